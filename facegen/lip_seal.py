"""The lips shut on p, b and m: where the clip's aligned phones have a bilabial stop or nasal, the frames that
show it get ARKit's mouthClose shape (the lips closed against the jaw, facegen.arkit.deformers) weighted to
shut whatever gap the network's frames leave there. A layer over the network's frames (facegen.layers).

Why: a bilabial is the one mouth shape viewers check — the lips must meet — and the network leaves a gap
where a p or b is short (25-45 ms, shorter than a frame at 25 fps: the phone stream, sampled at the frame
times, may not show it at all) or in a language it never heard (cross-language benchmark: 56-88 % closed in
some languages against 100 % for the rig it learned from). Only P, B and M close: a Spanish /b/ between vowels
([β]) reads as V (facegen.phonetics), lips that near and do not touch, and stays as the network has it.

Which frames: those whose time lies inside the phone, and at least MIN_CLOSURE_S about its middle. The lips of
a bilabial stay shut 60-120 ms in running speech (intervocalic /b/ the shortest), which is two frames or more
at 25 fps; the aligner's phones are shorter (pocketsphinx's 10 ms frames, three at least a phone, and its p,
b and m 10-30 ms before the synthesiser's in the cross-language benchmark), and a closure held on the one
frame nearest an early middle is open again on the frame that shows the sound. The weight is the
frame's own gap (the mean over the middle third of the mouth, as facegen.lipsync measures aperture) minus
SEALED_CM, over what a unit of mouthClose closes; frames already shut get nothing, and the weight never
exceeds MAX_WEIGHT (a gap wider than that is the network's wide-open mouth at a misaligned phone, which a
shape would tear rather than close).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

BILABIALS = ("P", "B", "M")
SEALED_CM = 0.005  # the gap left between the lips' margins (0.05 mm: touching, never crossing)
MAX_WEIGHT = 0.5  # mouthClose at most this (closes a gap of about 2 cm on facegen's face)
MIN_CLOSURE_S = 0.08  # a shorter aligned p, b or m is held closed this long about its middle


def seal_frames(phone_times: Sequence | None, num_frames: int, fps: float) -> np.ndarray:
    """Frame indices (int64, sorted, unique) showing a p, b or m of `phone_times` ((CMU phone, start s,
    end s)): the frames at times inside it, and those within MIN_CLOSURE_S / 2 of its middle."""
    out: set[int] = set()
    eps = 1e-6
    for name, start, end in phone_times or ():
        if name not in BILABIALS or not end > start:
            continue
        middle, half = (start + end) / 2, max(end - start, MIN_CLOSURE_S) / 2
        first = int(np.ceil((middle - half) * fps - eps))
        last = int(np.floor((middle + half) * fps + eps))
        out.update(range(max(first, 0), min(last, num_frames - 1) + 1))
    return np.asarray(sorted(out), np.int64)


def seal_curve(stream, mesh, phone_times: Sequence | None, fps: float,
               close: np.ndarray) -> np.ndarray | None:
    """[T] float32 weights of `close` ([V, 3], the mouthClose offsets) shutting the lips of `stream` (a
    FrameStream at `fps`, its layers included) at the frames of seal_frames; None when no frame needs it or
    the mouth's margins do not pair up. The mesh has ARKit's regions (facegen.layers asks for them first)."""
    from facegen.errors import FacegenError
    from facegen.face.regions import mouth_middle
    from facegen.face.rig import face_scale

    frames = seal_frames(phone_times, len(stream), fps)
    if not len(frames):
        return None
    try:
        upper, lower = mouth_middle(mesh.regions)
    except FacegenError:
        return None
    _, cm = face_scale(np.asarray(mesh.vertices, np.float64), mesh.regions)  # mesh units per cm
    per_unit = float(np.mean(close[upper, 1] - close[lower, 1])) / cm  # cm of gap, negative
    if not per_unit < 0:
        return None
    points = stream.points(np.concatenate([upper, lower]))  # [T, 2n, 3], layers included
    n = len(upper)
    gap = (points[frames, :n, 1] - points[frames, n:, 1]).mean(1) / cm
    weights = np.zeros(len(stream), np.float32)
    weights[frames] = np.clip((gap - SEALED_CM) / -per_unit, 0.0, MAX_WEIGHT)
    return weights if weights.any() else None
