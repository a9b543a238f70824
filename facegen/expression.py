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
import re
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


# --------------------------------------------------------------------------------------------------
# spans in the transcript: "[happy:0.7] what a day [/happy]"

_MARKUP = re.compile(r"\[\s*(/)?\s*([A-Za-z]+)\s*(?::\s*([^\]]*?))?\s*\]")
RAMP_S = 0.3  # a span's emotion comes in over this much time around its first word, and goes likewise


@dataclass(frozen=True)
class EmotionSpan:
    """An emotion over part of a transcript: from character `first` (after the opening tag) to `last` (the
    closing tag's start)."""

    emotion: Emotion
    first: int
    last: int


def emotion_spans(text: str | None) -> list[EmotionSpan]:
    """The emotion spans marked in `text` (`[LABEL]` or `[LABEL:INTENSITY]` ... `[/LABEL]`, labels of
    EMOTIONS). Brackets holding anything else are stage directions (facegen.words.split_directions), as the
    markup is too: neither reaches the aligner. Unknown or unbalanced markup is a FacegenError naming the
    character where it is."""
    spans: list[EmotionSpan] = []
    open_: dict[str, tuple[Emotion, int, int]] = {}
    for m in _MARKUP.finditer(text or ""):
        closing, label, value = m.group(1), m.group(2).lower(), m.group(3)
        where = f"the transcript's markup {m.group(0)!r} at character {m.start() + 1}"
        if label not in EMOTIONS:
            if closing or value is not None:
                raise FacegenError(f"{where} names no emotion: use one of {', '.join(EMOTIONS)}, as "
                                   f"[happy:0.7] ... [/happy]", param="text")
            continue  # a stage direction such as [tone]
        if closing:
            if label not in open_:
                raise FacegenError(f"{where} closes a span that was never opened: open it with [{label}] "
                                   f"before", param="text")
            emotion, first, _ = open_.pop(label)
            spans.append(EmotionSpan(emotion, first, m.start()))
            continue
        if label in open_:
            raise FacegenError(f"{where} opens [{label}] again inside its own span: close the first with "
                               f"[/{label}]", param="text")
        try:
            emotion = parse_emotion(label if value is None else f"{label}:{value}")
        except FacegenError as exc:
            raise FacegenError(f"{where}: {exc}", param="text") from None
        open_[label] = (emotion, m.end(), m.start())
    if open_:
        label, (_, _, start) = min(open_.items(), key=lambda item: item[1][2])
        raise FacegenError(f"the transcript's markup [{label}] at character {start + 1} is never closed: end "
                           f"its span with [/{label}]", param="text")
    return sorted(spans, key=lambda s: s.first)


def is_markup(direction: str) -> bool:
    """Whether a stage direction (as facegen.words.split_directions gives it) is emotion markup."""
    m = _MARKUP.fullmatch(direction.strip())
    return m is not None and m.group(2).lower() in EMOTIONS


def span_times(text: str, spans: list[EmotionSpan], words: list) -> list[tuple[Emotion, float, float]]:
    """(emotion, start s, end s) of each span: from its first word's start to its last word's end, the words
    (`words`, aligned, with .start/.end) counted as facegen.words.normalize_transcript counts them."""
    from facegen.words import normalize_transcript

    total = len(normalize_transcript(text))
    out = []
    for span in spans:
        first = len(normalize_transcript(text[:span.first]))
        last = len(normalize_transcript(text[:span.last]))
        if not words or not total or last <= first:
            continue
        scale = len(words) / total  # the aligner's words, where they differ in number from the transcript's
        a = min(int(first * scale), len(words) - 1)
        b = min(max(round(last * scale), a + 1), len(words))
        out.append((span.emotion, float(words[a].start), float(words[b - 1].end)))
    return out


def span_curve(start: float, end: float, num_frames: int, fps: float) -> np.ndarray:
    """[num_frames] float32: 0 outside, 1 inside (`start`, `end`), smoothsteps of RAMP_S centred on them."""
    t = np.arange(num_frames) / fps

    def ramp(x: np.ndarray) -> np.ndarray:
        x = np.clip(x, 0, 1)
        return x * x * (3 - 2 * x)

    return (ramp((t - start + RAMP_S / 2) / RAMP_S) * (1 - ramp((t - end + RAMP_S / 2) / RAMP_S))).astype(
        np.float32)
