"""The batch workers' preload: the local batch engine's forkserver imports this module once (engines.PRELOAD,
processes.process_pool's `preload`) before it forks the workers, so that every worker starts with the forced
aligner's pocketsphinx decoders built (`sphinx.warm()`) instead of building its own. Importing it is its one
effect — a forkserver's preload can only import modules — and nothing else imports it."""

from facegen import align, sphinx  # noqa: F401  (align: the aligner's modules imported once too)

sphinx.warm()
