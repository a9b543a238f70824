"""Blinks timed by the speech (issue 24): when a face driven by facegen closes its eyes, and how.

The network cannot learn blinks: the training rig blinks at random times, which nothing in the audio
predicts, so it learned their average (eyeBlink never above 0.07). They are made here instead, as a layer over
the network's frames (inference.FrameStream.with_layers: the rig's blink offsets times a curve), so every
format carries them: the lids of the mesh close and the ARKit fit reads eyeBlinkLeft/Right from them.

When (after the literature on blinking in conversation: people blink 10-30 times a minute while speaking,
more at pauses and the ends of phrases, where a thought ends, than inside words; the intervals are far from
periodic; a few blinks come in pairs):

- a renewal process of gamma-distributed intervals (shape GAMMA_SHAPE, mean 60 / rate s) proposes times;
- a proposal near a pause (quiet audio of at least PAUSE_S) moves, with probability ANCHOR_P, to the pause's
  start (plus a short reaction), the end of the phrase; one inside speech not near a pause moves to the
  nearest quiet moment between words within WORD_GAP_S, if there is one;
- DOUBLE_P of the blinks are doubles (a second blink right after the first).

How: each blink lasts 100-400 ms (DURATION_S), closing fast (CLOSE_SHARE of it), held shut for at least one
output frame, opening slower. Both lids together. Random draws come from `seed`: the same audio, rate and seed
give the same blinks, bit for bit. A clip without speech (an idle clip) blinks at the same rate, without
anchors.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np

from facegen.errors import FacegenError

DEFAULT_RATE = 17.0  # blinks per minute (speakers: 10-30; at rest ~17)
MAX_RATE = 120.0
GAMMA_SHAPE = 3.0  # intervals' gamma shape: coefficient of variation 1/sqrt(3) = 0.58 before the anchors
PAUSE_S = 0.2  # quiet audio at least this long is a pause
ANCHOR_WINDOW = 0.5  # x the mean interval: how far a proposal looks for a pause
ANCHOR_P = 0.85  # a proposal near a pause moves to it with this probability
REACTION_S = (0.0, 0.25)  # after the pause starts (the end of the phrase) the blink begins within this
WORD_GAP_S = 0.4  # a proposal inside a word moves to a quiet moment this near
DOUBLE_P = 0.08  # share of double blinks
DOUBLE_GAP_S = (0.05, 0.15)  # between the two blinks of a double
DURATION_S = (0.12, 0.35)  # one blink, start to open
CLOSE_SHARE, SHUT_SHARE = 0.3, 0.15  # of a blink's duration: closing, held shut (the rest: opening)
MIN_GAP_S = 0.6  # two single blinks never closer than this


@dataclass(frozen=True)
class Blink:
    """One blink: starts closing at `start` (s) and is open again at start + duration."""

    start: float
    duration: float


def check_blink_rate(rate: float) -> float:
    """A blink rate: a finite number of blinks per minute in [0, MAX_RATE] (0: no blinks)."""
    number = isinstance(rate, int | float) and not isinstance(rate, bool)
    if not number or not math.isfinite(rate) or not 0 <= rate <= MAX_RATE:
        raise FacegenError(f"the blink rate must be a number of blinks per minute from 0 (none) to "
                           f"{MAX_RATE:g}, got {rate!r}: people blink 10-30 times a minute while speaking",
                           param="blink_rate")
    return float(rate)


def check_seed(seed: int) -> int:
    """A seed for the random layers: an integer in [0, 2^32)."""
    if not isinstance(seed, int | np.integer) or isinstance(seed, bool) or not 0 <= seed < 2**32:
        raise FacegenError(f"the seed must be a whole number from 0 to {2**32 - 1}, got {seed!r}",
                           param="seed")
    return int(seed)


def quiet_spans(samples: np.ndarray, sample_rate: int) -> list[tuple[float, float]]:
    """(start, end) in seconds of the pauses of a recording: quiet audio of at least PAUSE_S (the edges of
    the clip included)."""
    from facegen.align_pieces import loud_frames

    frames = len(samples) // (sample_rate // 100)
    if frames < 3 or not np.any(samples):
        return [(0.0, len(samples) / sample_rate)]
    loud = loud_frames(samples, frames, sample_rate)  # at the clip's own rate: no copy of a long clip
    edges = np.flatnonzero(np.diff(np.concatenate([[1], loud.astype(np.int8), [1]])))
    return [(a / 100, b / 100) for a, b in zip(edges[::2], edges[1::2], strict=True)
            if (b - a) / 100 >= PAUSE_S]


def blink_times(duration: float, pauses: list[tuple[float, float]], rate: float = DEFAULT_RATE,
                seed: int = 0) -> list[Blink]:
    """The blinks of a clip of `duration` s whose pauses are `pauses` (see the module docstring)."""
    rate = check_blink_rate(rate)
    if rate == 0 or duration <= 0:
        return []
    rng = np.random.default_rng([check_seed(seed), 0xB11E])
    mean = 60.0 / rate
    speech = not (len(pauses) == 1 and pauses[0][1] - pauses[0][0] >= duration - 1e-6)
    anchors = [a for a, b in pauses if 0 < a < duration] if speech else []
    quiet = sorted((a, b) for a, b in pauses) if speech else []
    starts = [a for a, _ in quiet]
    anchors = sorted(anchors)
    out: list[Blink] = []
    t = float(rng.uniform(0.1, 0.6)) * mean  # the first blink comes sooner than a full interval
    while t < duration:
        if anchors and rng.random() < ANCHOR_P:  # (bisect: a long clip has thousands of pauses)
            window = ANCHOR_WINDOW * mean
            near = anchors[bisect.bisect_left(anchors, t - window):bisect.bisect_right(anchors, t + window)]
            if near:
                t = min(near, key=lambda a: abs(a - t)) + float(rng.uniform(*REACTION_S))
        # the pauses that may hold t or lie within WORD_GAP_S of it: the last few starting before t + that
        around = quiet[max(0, bisect.bisect_right(starts, t + WORD_GAP_S) - 8):
                       bisect.bisect_right(starts, t + WORD_GAP_S)]
        if quiet and not any(a <= t <= b for a, b in around):
            gaps = [(a, b) for a, b in around if a - WORD_GAP_S <= t <= b + WORD_GAP_S]
            if gaps:  # inside a word: to the nearest quiet moment
                a, b = min(gaps, key=lambda g: min(abs(g[0] - t), abs(g[1] - t)))
                t = min(max(t, a), b)
        if out and t < out[-1].start + MIN_GAP_S:
            t = out[-1].start + MIN_GAP_S
        if t >= duration:
            break
        blink = Blink(round(float(t), 4), round(float(rng.uniform(*DURATION_S)), 4))
        out.append(blink)
        if rng.random() < DOUBLE_P:
            second = blink.start + blink.duration + float(rng.uniform(*DOUBLE_GAP_S))
            if second < duration:
                out.append(Blink(round(second, 4), round(float(rng.uniform(*DURATION_S)), 4)))
        t = out[-1].start + float(rng.gamma(GAMMA_SHAPE, mean / GAMMA_SHAPE))
    return out


def blink_curve(blinks: list[Blink], num_frames: int, fps: float) -> np.ndarray:
    """How shut the lids are at each frame, [num_frames] float32 in [0, 1] (1: shut): each blink closes over
    CLOSE_SHARE of its duration (smoothstep), stays shut for SHUT_SHARE of it but at least over one frame
    time, and opens over the rest (an ease-out)."""
    out = np.zeros(num_frames)
    for blink in blinks:
        close = CLOSE_SHARE * blink.duration
        shut_from = blink.start + close
        shut_to = max(shut_from + SHUT_SHARE * blink.duration, math.floor(shut_from * fps + 1.0) / fps + 1e-9)
        opened = shut_to + blink.duration - close - SHUT_SHARE * blink.duration
        first, end = max(0, math.floor(blink.start * fps)), min(num_frames, math.ceil(opened * fps) + 1)
        if first >= end:
            continue
        t = np.arange(first, end) / fps  # only the frames it spans: a long clip has thousands of blinks
        x = np.clip((t - blink.start) / close, 0, 1)
        closing = x * x * (3 - 2 * x)
        y = np.clip((t - shut_to) / (opened - shut_to), 0, 1)
        opening = (1 - y) ** 2  # fast at first, slow at the end
        value = np.where(t < shut_from, closing, np.where(t <= shut_to, 1.0, opening))
        value[(t < blink.start) | (t >= opened)] = 0.0
        out[first:end] = np.maximum(out[first:end], value)
    return out.astype(np.float32)


@dataclass(frozen=True)
class BlinkStats:
    """Measures of the blinks of an animation (docs/results.md): `per_minute`, the durations (s), the share
    of blinks that start within 0.4 s of a pause, the coefficient of variation of the intervals."""

    count: int
    per_minute: float
    durations: tuple[float, ...]
    near_pause: float | None
    interval_cv: float | None


def blink_stats(curve: np.ndarray, fps: float, pauses: list[tuple[float, float]],
                shut: float = 0.1) -> BlinkStats:
    """Blinks found in a lid curve (runs of frames above `shut`), measured against the clip's `pauses`."""
    closed = np.asarray(curve) > shut
    edges = np.flatnonzero(np.diff(np.concatenate([[0], closed.astype(np.int8), [0]])))
    starts, ends = edges[::2] / fps, edges[1::2] / fps
    near = [any(a - 0.4 <= s <= b + 0.4 for a, b in pauses) for s in starts]
    gaps = np.diff(starts)
    minutes = len(curve) / fps / 60
    return BlinkStats(len(starts), len(starts) / minutes if minutes else 0.0,
                      tuple(float(e - s) for s, e in zip(starts, ends, strict=True)),
                      float(np.mean(near)) if near else None,
                      float(gaps.std() / gaps.mean()) if len(gaps) > 2 else None)
