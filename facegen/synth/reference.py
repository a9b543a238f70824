"""The reference animation for any recording: facegen's rig driven by the recording's phone and word
timings, as the synthetic corpus animates its speech (the lip-sync metrics of facegen.lipsync compare an
animation with it)."""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np

from facegen.face.mesh import Mesh
from facegen.face.rig import CHANNELS, Rig
from facegen.face.template import load_template
from facegen.synth.curves import SpeakerStyle, motion_curves


def rig_reference(phones: Sequence, words: Sequence, num_frames: int, fps: float,
                  mesh: Mesh | Rig | None = None, *, alphabet: str = "espeak",
                  loudness: np.ndarray | None = None, f1: np.ndarray | None = None,
                  style: SpeakerStyle | None = None) -> np.ndarray:
    """The reference animation [num_frames, V, 3] (float32) for a recording with these phone and word
    timings (e.g. from forced alignment): facegen's rig with the neutral speaker style (or `style`, one
    speaker's motion: SpeakerStyle.for_speaker) and no blinks.

    `mesh`: the face (a Mesh, or a facegen.face.rig.Rig built on it to reuse across calls; default: the
    committed neutral face, rigged once). `alphabet` ("espeak" mnemonics or "cmu" phones), `loudness` (the
    recording's facegen.synth.curves.loudness_envelope: prosody) and `f1` (its formant_track: how open each
    vowel is said) go to the rig's motion_curves; emotional words move the upper face as in the synthetic
    corpus."""
    rig = _template_rig() if mesh is None else mesh if isinstance(mesh, Rig) else Rig(mesh)
    curves = motion_curves(phones, words, int(num_frames), fps, style, rng=np.random.default_rng(0),
                           alphabet=alphabet, loudness=loudness, f1=f1)
    curves[:, CHANNELS.index("blink")] = 0.0
    return rig.pose(curves)


@functools.cache
def _template_rig() -> Rig:
    """The rig on the committed neutral face (facegen/face/templates/face.ply), built once."""
    return Rig(load_template())
