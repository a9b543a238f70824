"""The tongue's motion from the clip's phones: its tip rises to the ridge behind the upper teeth for t, d, n
and l, and comes forward between the teeth for th (the "tipUp" and "tipForward" targets of the tongue in
facegen.face.parts; tipForward x arkit.solve.TONGUE_OUT is ARKit's tongueOut in every ARKit output). Each
phone's weight ramps in and out over about COARTICULATION_S (a raised-cosine window), as the tongue moves
before and after the sound it makes."""

from __future__ import annotations

import numpy as np

from facegen.phonetics import INDEX

RAISED = ("T", "D", "N", "L")
FORWARD = ("TH", "DH")
COARTICULATION_S = 0.12


def tongue_curves(phones: np.ndarray | None, frames: int, fps: float) -> np.ndarray:
    """[frames, 2] float32 (tipUp, tipForward) in [0, 1] from the per-frame phones [Tn, P] one-hot of the
    network's phone stream (spread over `frames` output frames at `fps`); zeros without phones."""
    out = np.zeros((frames, 2), np.float32)
    if phones is None or len(phones) == 0 or frames == 0:
        return out
    phones = np.asarray(phones)
    at = np.minimum((np.arange(frames) * len(phones)) // frames, len(phones) - 1)
    half = max(1, round(COARTICULATION_S * fps / 2))
    window = np.hanning(2 * half + 3)[1:-1]
    window /= window.max()
    for k, group in enumerate((RAISED, FORWARD)):
        on = phones[at][:, [INDEX[p] for p in group]].sum(1) > 0
        spread = np.convolve(on.astype(np.float64), window, mode="same")
        out[:, k] = np.clip(spread, 0.0, 1.0)
    return out
