"""The optional phone stream: per-frame phone identity (one-hot over pocketsphinx's CMU phones + silence), an
extra input of the audio encoder for models trained with it (facegen.model: `n_phones`).

At inference the phones come from pocketsphinx's phone alignment of the transcript (facegen.align.align_phones)
or from an alignment file that lists them; in training from the corpus's phone timings (the synthesiser's own,
espeak mnemonics or CMU phones, mapped to CMU here).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from facegen.errors import FacegenError
from facegen.espeak import CMU_CONSONANTS, CMU_VOWELS, espeak_to_cmu

PHONES = ("SIL", *CMU_VOWELS, *CMU_CONSONANTS)  # class 0: silence / no phone
INDEX = {p: i for i, p in enumerate(PHONES)}


def to_cmu(phones: Sequence, alphabet: str = "cmu") -> list[tuple[str, float, float]]:
    """(CMU phone, start, end) from phones as (name, start, end) tuples or objects with .text/.start/.end;
    espeak mnemonics (`alphabet="espeak"`) that map to several CMU phones share their span evenly."""
    if alphabet not in ("cmu", "espeak"):
        raise FacegenError(f"unknown phone alphabet {alphabet!r}: use cmu or espeak")
    out = []
    for ph in phones:
        name, start, end = (ph.text, ph.start, ph.end) if hasattr(ph, "text") else ph[:3]
        parts = espeak_to_cmu([str(name)]) if alphabet == "espeak" else [str(name).upper().rstrip("012")]
        parts = [p for p in parts if p in INDEX]
        step = (float(end) - float(start)) / max(1, len(parts))
        out += [(p, float(start) + k * step, float(start) + (k + 1) * step) for k, p in enumerate(parts)]
    return out


def phone_frames(phones: Sequence, num_frames: int, fps: float, alphabet: str = "cmu") -> np.ndarray:
    """One-hot [num_frames, len(PHONES)] float32: the phone sounding at each frame's time k / fps (SIL where
    none is)."""
    ids = np.zeros(num_frames, np.int64)
    t = np.arange(num_frames) / fps
    for name, start, end in to_cmu(phones, alphabet):
        ids[(t >= start) & (t < end)] = INDEX[name]
    out = np.zeros((num_frames, len(PHONES)), np.float32)
    out[np.arange(num_frames), ids] = 1.0
    return out


def silence(num_frames: int) -> np.ndarray:
    """Phone frames [num_frames, len(PHONES)] of silence only (class 0)."""
    out = np.zeros((num_frames, len(PHONES)), np.float32)
    out[:, 0] = 1.0
    return out
