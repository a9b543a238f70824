"""Gaze (issue 24): eyes that fixate, make saccades and look away while planning speech, turning the
eyeballs of every mesh format.

When and where (after the conversational-gaze literature: speakers look away from the listener at the start
of an utterance and in planning pauses and back at its end; between, fixations of 0.3-2 s joined by small
saccades; saccade duration and amplitude follow the main sequence):

- fixations last a gamma-distributed FIXATION_S on average (0.3-2 s);
- a speech onset after a pause of at least AVERT_PAUSE_S (planning) starts a gaze aversion: a saccade to the
  side and up or down (AVERT_DEG) held AVERT_HOLD_S, then back to the listener;
- otherwise each fixation ends in a small saccade around the listener (amplitude 1-15°, mostly 2-6°), drawn
  back toward the listener;
- a saccade of A degrees lasts 21 + 2.2 A ms (the main sequence) on a minimum-jerk profile.

How: both eyes turn together (yaw: + toward the character's left, +x; pitch: + up) about their fitted
centres, as facegen.arkit.deformers turns them for eyeLook*: each point of the eyeball's front cap slides over
the eyeball's ellipsoid, fading to none at the cap's rim so no gap opens (`EyeTurns`, applied to the frames
by inference.FrameStream). The upper lid follows the pitch (the eyeLookUp/Down lids, a layer). Random draws
come from the seed, as the blinks'.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np

FIXATION_S = 0.9  # mean fixation (gamma, shape 3), clipped to 0.3-2 s
AVERT_PAUSE_S = 0.5  # a pause at least this long before speech: planning, the gaze turns away
AVERT_DEG = (6.0, 12.0)  # yaw of an aversion (either side); its pitch 2-7 degrees up or down
AVERT_HOLD_S = (0.8, 1.8)
SMALL_DEG = 3.0  # scale of the small saccades around the listener (amplitude clipped to 1-15 degrees)
LIMIT_DEG = 15.0
MIN_FIXATION_S = 0.1  # between the end of a saccade and the next


@dataclass(frozen=True)
class Saccade:
    """A saccade starting at `start` (s) to (`yaw`, `pitch`) degrees, lasting `duration` s."""

    start: float
    duration: float
    yaw: float
    pitch: float


def saccade_duration(amplitude: float) -> float:
    """The main sequence: seconds for a saccade of `amplitude` degrees."""
    return 0.021 + 0.0022 * amplitude


def saccades(duration: float, pauses: list[tuple[float, float]], seed: int = 0) -> list[Saccade]:
    """The saccades of a clip of `duration` s whose pauses are `pauses` (see the module docstring)."""
    rng = np.random.default_rng([int(seed), 0x6A2E])
    onsets = [b for a, b in pauses if b - a >= AVERT_PAUSE_S and 0 < b < duration - 0.3]
    out: list[Saccade] = []
    t, yaw, pitch = 0.0, 0.0, 0.0
    hold_until = -1.0

    def move(start: float, to_yaw: float, to_pitch: float) -> float:
        """Add a saccade at `start` (after the last one's end and a short fixation); its start."""
        nonlocal yaw, pitch
        if out:
            start = max(start, out[-1].start + out[-1].duration + MIN_FIXATION_S)
        amplitude = math.hypot(to_yaw - yaw, to_pitch - pitch)
        if amplitude > LIMIT_DEG:  # a longer way in one saccade is not made: shortened
            to_yaw, to_pitch = (yaw + (to_yaw - yaw) * LIMIT_DEG / amplitude,
                                pitch + (to_pitch - pitch) * LIMIT_DEG / amplitude)
            amplitude = LIMIT_DEG
        out.append(Saccade(round(start, 4), round(saccade_duration(amplitude), 4), round(to_yaw, 3),
                           round(to_pitch, 3)))
        yaw, pitch = to_yaw, to_pitch
        return start

    while True:
        fixation = float(np.clip(rng.gamma(3.0, FIXATION_S / 3.0), 0.3, 2.0))
        nxt = t + fixation
        i = bisect.bisect_right(onsets, t + 0.1)  # the first onset with t < onset - 0.1
        onset = onsets[i] if i < len(onsets) and onsets[i] - 0.1 <= nxt else None
        if onset is not None and onset - 0.1 > hold_until:  # planning: look away as speech starts
            start = onset - float(rng.uniform(0.05, 0.2))
            if start >= duration:
                break
            start = move(start, float(rng.choice([-1, 1]) * rng.uniform(*AVERT_DEG)),
                         float(rng.choice([-1, 1]) * rng.uniform(2.0, 7.0)))
            hold_until = start + float(rng.uniform(*AVERT_HOLD_S))
            t = hold_until
            if t < duration:
                t = move(t, float(rng.normal(0, 1.0)), float(rng.normal(0, 0.7)))  # back to the listener
            continue
        if nxt >= duration:
            break
        for _ in range(20):  # a small saccade, drawn back toward the listener
            to = np.array([yaw, pitch]) * 0.4 + rng.normal(0, SMALL_DEG, 2) * np.array([1.0, 0.6])
            amplitude = math.hypot(to[0] - yaw, to[1] - pitch)
            if 1.0 <= amplitude <= LIMIT_DEG and np.all(np.abs(to) <= LIMIT_DEG):
                break
        else:
            to = np.array([0.0, 0.0])
        t = move(nxt, float(to[0]), float(to[1]))
    return out


def gaze_curve(found: list[Saccade], num_frames: int, fps: float) -> np.ndarray:
    """(yaw, pitch) in degrees at each frame, [num_frames, 2] float32: held between saccades, each on a
    minimum-jerk profile."""
    out = np.zeros((num_frames, 2))
    here = np.zeros(2)
    for k, s in enumerate(found):  # its frames only, up to the next saccade (a long clip has thousands)
        first = min(num_frames, max(0, math.ceil(s.start * fps - 1e-9)))
        end = num_frames if k + 1 == len(found) else min(num_frames, max(first, math.ceil(
            found[k + 1].start * fps - 1e-9)))
        t = np.arange(first, end) / fps
        u = np.clip((t - s.start) / s.duration, 0, 1)
        shape = u ** 3 * (10 - 15 * u + 6 * u * u)
        target = np.array([s.yaw, s.pitch])
        out[first:end] = here + shape[:, None] * (target - here)
        here = target
    return out.astype(np.float32)


class EyeTurns:
    """The eyeballs of a face turned by a gaze curve: `apply(first frame, positions)` turns the eyeball
    points (`indices`) of consecutive frames in place, as facegen.arkit.deformers turns them for eyeLook*."""

    def __init__(self, template: np.ndarray, regions: dict, gaze: np.ndarray) -> None:
        from facegen.arkit.deformers import EYE_FIXED_DEG, EYE_ROTATED_DEG
        from facegen.face.rig import eyeballs

        self.gaze = np.radians(np.asarray(gaze, np.float64))
        template = np.asarray(template, np.float64)
        centres, semi_axes = eyeballs(template, regions)
        sides = []
        for side, name in enumerate(("left_eyeball", "right_eyeball")):
            idx = np.asarray(regions[name], np.int64)
            c, axes = centres[side], semi_axes[side]
            u = (template[idx] - c) / axes
            polar = np.degrees(np.arccos(np.clip(u[:, 2] / np.linalg.norm(u, axis=1), -1, 1)))
            x = np.clip((polar - EYE_ROTATED_DEG) / (EYE_FIXED_DEG - EYE_ROTATED_DEG), 0, 1)
            sides.append((idx, c, axes, 1 - x * x * (3 - 2 * x)))
        self.sides = sides
        self.indices = np.concatenate([s[0] for s in sides])

    def every(self, step: int) -> EyeTurns:
        other = object.__new__(EyeTurns)
        other.gaze, other.sides, other.indices = self.gaze[::step], self.sides, self.indices
        return other

    def rotations(self, start: int, stop: int) -> np.ndarray:
        """[n, 3, 3]: yaw about +y, then pitch about x (+ up)."""
        from facegen.face.parts import gaze_rotations  # the parts' eyeballs turn by the same rotation

        return gaze_rotations(self.gaze[start:stop, 0], self.gaze[start:stop, 1])

    def turn(self, start: int, points: np.ndarray) -> np.ndarray:
        """The eyeball points `points` [n, len(indices), 3] of frames start.. turned (a new array)."""
        out = np.array(points, np.float64)
        rot = self.rotations(start, start + len(points))
        at = 0
        for idx, c, axes, g in self.sides:
            p = out[:, at:at + len(idx)]
            u = (p - c) / axes
            turned = np.matmul(u, rot.transpose(0, 2, 1))  # each frame's points by its rotation
            mixed = u + g[None, :, None] * (turned - u)
            mixed *= np.sqrt(_squares(u) / np.maximum(_squares(mixed), 1e-24))[..., None]
            out[:, at:at + len(idx)] = c + mixed * axes
            at += len(idx)
        return out

    def apply(self, start: int, frames: np.ndarray) -> None:
        """Turn the eyeballs of `frames` [n, V, 3] (frames start..) in place."""
        frames[:, self.indices] = self.turn(start, frames[:, self.indices])


def _squares(points: np.ndarray) -> np.ndarray:
    """The squared lengths of `points` [..., 3] (einsum: a third of np.linalg.norm's time)."""
    return np.einsum("...i,...i->...", points, points)


def lid_curves(gaze: np.ndarray) -> np.ndarray:
    """How far the upper lids follow the pitch, [T, 2] (eyeLookUp, eyeLookDown amounts in [0, 1]): the
    lid parts of those shapes, so a look down lowers the lids."""
    from facegen.arkit.deformers import LOOK_DOWN, LOOK_UP

    pitch = np.radians(np.asarray(gaze, np.float64)[:, 1])
    return np.stack([np.clip(pitch / LOOK_UP, 0, 1), np.clip(-pitch / LOOK_DOWN, 0, 1)], 1).astype(np.float32)
