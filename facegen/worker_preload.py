"""Importing this module creates the forced aligner's pocketsphinx decoders (`align.warm`). The local batch
engine's forkserver imports it (engines.PRELOAD), so that every worker is forked with them instead of building
its own: a module, because a forkserver's preload can only import."""

from facegen import align

align.warm()
