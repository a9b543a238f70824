"""Expression control (issue 24): `--emotion LABEL[:INTENSITY]` moves the whole face — brows, lids, cheeks,
mouth corners — for a whole clip, on top of what the speech and the words already do.

Each emotion is a prototype of the facial action units people show it with (Ekman & Friesen's EMFACS
prototypes: happiness AU6+12, sadness AU1+4+15, anger AU4+5+7+23, surprise AU1+2+5, fear AU1+2+4+5+20,
disgust AU9+10+15), written as ARKit shapes built on facegen's face (facegen.arkit: AU1 browInnerUp, AU2
browOuterUp, AU4 browDown, AU5 eyeWide, AU6 cheekSquint, AU7 eyeSquint, AU9 noseSneer, AU10 mouthUpperUp,
AU12 mouthSmile, AU15 mouthFrown, AU20 mouthStretch, AU23 mouthPress). No jaw: the jaw belongs to the
speech. The prototype times the intensity (0-1) is a layer over the network's frames
(inference.FrameStream.with_layers), so every format carries it; intensity 0 (or "neutral") adds nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from facegen.errors import FacegenError


def _sides(**amounts: float) -> dict[str, float]:
    """ARKit amounts with the Left/Right pairs written once (name without the side)."""
    from facegen.arkit.names import ARKIT_NAMES

    out: dict[str, float] = {}
    for name, amount in amounts.items():
        for side in (("Left", "Right") if name + "Left" in ARKIT_NAMES else ("",)):
            out[name + side] = amount
    return out


EMOTIONS: dict[str, dict[str, float]] = {
    "neutral": {},
    "happy": _sides(mouthSmile=0.7, cheekSquint=0.6, eyeSquint=0.2),
    "sad": _sides(browInnerUp=0.7, browDown=0.3, mouthFrown=0.6),
    "angry": _sides(browDown=0.9, eyeWide=0.15, eyeSquint=0.35, mouthPress=0.35),
    "surprised": _sides(browInnerUp=0.8, browOuterUp=0.8, eyeWide=0.7),
    "afraid": _sides(browInnerUp=0.9, browOuterUp=0.5, browDown=0.3, eyeWide=0.8, mouthStretch=0.4),
    "disgusted": _sides(noseSneer=0.8, mouthUpperUp=0.4, browDown=0.4, mouthFrown=0.3),
}


@dataclass(frozen=True)
class Emotion:
    """An emotion for a whole clip: a label of EMOTIONS and its intensity in [0, 1]."""

    label: str
    intensity: float = 1.0

    def as_dict(self) -> dict:
        return {"label": self.label, "intensity": self.intensity}


def parse_emotion(value: str | Emotion | None) -> Emotion | None:
    """`LABEL[:INTENSITY]` (e.g. "happy", "angry:0.4") as an Emotion; None stays None."""
    if value is None or isinstance(value, Emotion):
        return value
    labels = ", ".join(EMOTIONS)
    if not isinstance(value, str):
        raise FacegenError(f"the emotion must be LABEL or LABEL:INTENSITY (labels: {labels}), got {value!r}",
                           param="emotion")
    label, _, amount = value.strip().partition(":")
    label = label.strip().lower()
    if label not in EMOTIONS:
        raise FacegenError(f"unknown emotion {label!r}: use one of {labels}, optionally with :INTENSITY "
                           f"from 0 to 1 (e.g. happy:0.7)", param="emotion")
    try:
        intensity = float(amount) if amount.strip() else 1.0
    except ValueError:
        intensity = math.nan
    if not 0 <= intensity <= 1:
        raise FacegenError(f"the intensity of emotion {label!r} must be a number from 0 to 1, got "
                           f"{amount.strip()!r}: e.g. {label}:0.7", param="emotion")
    return Emotion(label, intensity)


def emotion_offsets(emotion: Emotion | None, mesh) -> np.ndarray | None:
    """The offsets [3V] float32 of `emotion` at its intensity on `mesh`, or None when it moves nothing
    (none given, neutral, intensity 0) or the mesh lacks facegen's rig regions."""
    if emotion is None or not EMOTIONS[emotion.label] or emotion.intensity == 0:
        return None
    from facegen.arkit.shapes import arkit_shapes

    try:
        shapes = arkit_shapes(mesh)
    except FacegenError:
        return None
    total = sum(amount * shapes.offset(name).astype(np.float64)
                for name, amount in EMOTIONS[emotion.label].items())
    return (emotion.intensity * total).reshape(-1).astype(np.float32)
