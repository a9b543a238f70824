"""Head motion driven by prosody (issue 24): small, smooth rotations of the whole head that move with the
voice — nods on loudness peaks (pitch accents are louder), a tilt and settle at phrase ends, a slow drift —
written where each format can carry a transform (the points stay face-local).

After the visual-prosody literature (Graf et al. 2002; Munhall et al. 2004; Busso et al. 2007): heads nod
with accented syllables, slightly ahead of them; they settle or tilt as a phrase ends; they drift slowly at
rest, less and slower than during speech; the range is a few degrees.

- accents: peaks of the level (dB, 10 ms frames, smoothed over 80 ms) rising ACCENT_DB over the level of
  the second around them, at least ACCENT_GAP_S apart, inside speech and not just before or after a pause;
  each makes a nod (pitch down and back, a Gaussian bump of NOD_WIDTH_S, lowest NOD_LEAD_S before the
  peak), its size growing with the accent's prominence;
- phrase ends (a pause of PHRASE_PAUSE_S or more after speech): a roll tilt to a random side and a small
  pitch settle, moving in on the phrase's last syllable, held through the pause, released as speech resumes;
- drift: a slow random walk on each axis (Ornstein-Uhlenbeck), DRIFT_DEG and DRIFT_TAU_S in speech, 0.4
  times as large and three times as slow in silence;
- then smoothed (40 ms) and held within LIMIT_DEG. `amount` scales everything (0: no head motion at all);
  the random draws come from the seed.

Angles are (yaw, pitch, roll) in degrees: yaw about +y (+: the face turns to its left, +x), pitch about +x
(+: the chin goes down, a nod), roll about +z (+: the face's left side rises, counter-clockwise in a front
view), applied as R = Ry(yaw) Rx(pitch) Rz(roll) about `pivot` (the top of the neck: below and behind the jaw
hinge).
"""

from __future__ import annotations

import math

import numpy as np

from facegen.errors import FacegenError

DEFAULT_AMOUNT = 1.0
MAX_AMOUNT = 3.0
ACCENT_DB = 4.0
ACCENT_GAP_S = 0.35
NOD_DEG = (0.8, 2.5)  # a nod's size from the least to the most prominent accent (x amount)
NOD_WIDTH_S = 0.1  # a nod: down and back in about 0.4 s, its lowest point NOD_LEAD_S before the accent
NOD_LEAD_S = 0.08
NOD_CLEAR_S = 0.25  # no nod on an accent this close to a pause (a phrase's end tilts, its onset is loud)
PHRASE_PAUSE_S = 0.3
TILT_DEG = (0.5, 1.5)
TILT_LEAD_S = 0.3  # the tilt starts on the phrase's last syllable and peaks early in the pause
TILT_RELEASE_S = 0.5
SETTLE_DEG = 0.6
DRIFT_DEG = np.array([1.2, 0.8, 0.6])  # yaw, pitch, roll standard deviation in speech
DRIFT_TAU_S = 1.2
LIMIT_DEG = 8.0
SMOOTH_S = 0.04
PIVOT_BELOW_HINGE_CM, PIVOT_BEHIND_HINGE_CM = 3.0, 1.5
DEFAULT_AMOUNT = 1.0  # `--head-motion` when not given: as people move theirs


def check_amount(amount: float) -> float:
    number = isinstance(amount, int | float) and not isinstance(amount, bool)
    if not number or not math.isfinite(amount) or not 0 <= amount <= MAX_AMOUNT:
        raise FacegenError(f"the head motion amount must be a number from 0 (a still head) to {MAX_AMOUNT:g} "
                           f"(1: as people move theirs), got {amount!r}", param="head_motion")
    return float(amount)


def _frames(start: float, end: float, fps: float, num_frames: int) -> tuple[int, int]:
    """The frames from time `start` to `end` (s), within the clip: a long clip's events touch only these."""
    return max(0, math.floor(start * fps)), min(num_frames, math.ceil(end * fps) + 1)


def _ramp(t: np.ndarray, start: float, end: float) -> np.ndarray:
    """0 before `start`, 1 after `end`, a smoothstep between."""
    x = np.clip((t - start) / (end - start), 0, 1)
    return x * x * (3 - 2 * x)


def head_motion(samples: np.ndarray, sample_rate: int, pauses: list[tuple[float, float]], num_frames: int,
                fps: float, amount: float = DEFAULT_AMOUNT, seed: int = 0) -> np.ndarray:
    """(yaw, pitch, roll) in degrees at each frame, [num_frames, 3] float32 (see the module docstring)."""
    from facegen.align_pieces import frame_energy_db

    amount = check_amount(amount)
    out = np.zeros((num_frames, 3))
    if amount == 0 or num_frames == 0:
        return out.astype(np.float32)
    rng = np.random.default_rng([int(seed), 0x4EAD])
    duration = len(samples) / sample_rate
    t = np.arange(num_frames) / fps
    speaking = np.ones(num_frames, bool)
    clear = np.ones(len(samples) // (sample_rate // 100) + 1, bool)  # 10 ms steps where a nod may be
    for a, b in pauses:
        speaking[math.ceil(a * fps - 1e-9):max(0, math.ceil(b * fps - 1e-9))] = False  # frames in [a, b)
        clear[max(0, round((a - NOD_CLEAR_S) * 100)):round((b + NOD_CLEAR_S) * 100)] = False

    hop = sample_rate // 100
    n = len(samples) // hop
    if n > 10 and speaking.any():
        level = frame_energy_db(samples, n, sample_rate)
        smooth = np.convolve(level, np.ones(8) / 8, mode="same")
        local = np.convolve(smooth, np.ones(100) / 100, mode="same")
        edge = np.convolve(np.ones(n), np.ones(100) / 100, mode="same")
        prominence = smooth - local / edge
        is_peak = (smooth >= np.roll(smooth, 1)) & (smooth > np.roll(smooth, -1)) & (prominence >= ACCENT_DB)
        last = -1.0
        for k in np.flatnonzero(is_peak):
            when = k / 100
            if not clear[k] or when - last < ACCENT_GAP_S:  # nods in speech, clear of pauses
                continue
            last = when
            size = np.interp(prominence[k], [ACCENT_DB, 3 * ACCENT_DB], NOD_DEG)
            lo, hi = _frames(when - NOD_LEAD_S - 4 * NOD_WIDTH_S, when - NOD_LEAD_S + 4 * NOD_WIDTH_S, fps,
                             num_frames)
            out[lo:hi, 1] += size * np.exp(-0.5 * ((t[lo:hi] - (when - NOD_LEAD_S)) / NOD_WIDTH_S) ** 2)
    for a, b in pauses:  # phrase ends
        if b - a >= PHRASE_PAUSE_S and 0 < a < duration - 0.05:
            # into the tilt on the phrase's last syllable, held through the pause, out of it as speech resumes
            lo, hi = _frames(a - TILT_LEAD_S, b + TILT_RELEASE_S, fps, num_frames)
            fade = _ramp(t[lo:hi], a - TILT_LEAD_S, a) * (1 - _ramp(t[lo:hi], b, b + TILT_RELEASE_S))
            out[lo:hi, 2] += rng.choice([-1, 1]) * rng.uniform(*TILT_DEG) * fade
            out[lo:hi, 1] -= SETTLE_DEG * fade  # the chin comes up a little as the phrase closes
    drift = np.zeros(3)
    for i in range(num_frames):  # Ornstein-Uhlenbeck, slower and smaller in silence
        tau = DRIFT_TAU_S if speaking[i] else 3 * DRIFT_TAU_S
        sd = DRIFT_DEG if speaking[i] else 0.4 * DRIFT_DEG
        a = math.exp(-1 / (fps * tau))
        drift = a * drift + math.sqrt(1 - a * a) * sd * rng.standard_normal(3)
        out[i] += drift
    sigma = SMOOTH_S * fps
    if sigma > 0.3:
        k = np.arange(-math.ceil(3 * sigma), math.ceil(3 * sigma) + 1)
        kernel = np.exp(-0.5 * (k / sigma) ** 2)
        kernel /= kernel.sum()
        padded = np.pad(out, ((len(k) // 2, len(k) // 2), (0, 0)), mode="edge")
        out = np.stack([np.convolve(padded[:, j], kernel, mode="valid") for j in range(3)], 1)
    out = LIMIT_DEG * np.tanh(amount * out / LIMIT_DEG)
    return out.astype(np.float32)


def has_pivot(regions: dict) -> bool:
    """True when a face with these regions has the jaw hinge its head turns about (`pivot`): without it the
    head stays still."""
    return "jaw_hinge" in regions


def pivot(template: np.ndarray, regions: dict) -> np.ndarray:
    """The point the head turns about [3] (mesh units): the top of the neck, below and behind the jaw
    hinge."""
    from facegen.face.rig import face_scale

    t = np.asarray(template, np.float64)
    _, cm = face_scale(t, regions)
    hinge = t[np.asarray(regions["jaw_hinge"], np.int64)].mean(0)
    return hinge + np.array([0.0, -PIVOT_BELOW_HINGE_CM * cm, -PIVOT_BEHIND_HINGE_CM * cm])


def rotations(angles: np.ndarray) -> np.ndarray:
    """[T, 3, 3] rotation matrices of (yaw, pitch, roll) degrees: Ry(yaw) Rx(pitch) Rz(roll)."""
    yaw, pitch, roll = np.radians(np.asarray(angles, np.float64)).T
    T = len(yaw)

    def axis(c, s, i, j):
        m = np.zeros((T, 3, 3))
        m[:, :, :] = np.eye(3)
        m[:, i, i], m[:, j, j], m[:, i, j], m[:, j, i] = c, c, -s, s
        return m

    ry = axis(np.cos(yaw), -np.sin(yaw), 0, 2)  # about +y: +yaw turns +z toward +x
    rx = axis(np.cos(pitch), np.sin(pitch), 1, 2)  # about +x: +pitch turns +z toward -y (chin down)
    rz = axis(np.cos(roll), np.sin(roll), 0, 1)
    return ry @ rx @ rz


def angles_of(turns: np.ndarray) -> np.ndarray:
    """[T, 3] (yaw, pitch, roll) degrees of rotation matrices [T, 3, 3] (the inverse of `rotations`, pitch
    within +-90 degrees), float32; e.g. a glTF Head node's rotation keys read back."""
    m = np.asarray(turns, np.float64)
    pitch = np.arcsin(np.clip(-m[:, 1, 2], -1.0, 1.0))  # Ry Rx Rz's row y: cos p sin r, cos p cos r, -sin p
    yaw = np.arctan2(m[:, 0, 2], m[:, 2, 2])
    roll = np.arctan2(m[:, 1, 0], m[:, 1, 1])
    return np.degrees(np.stack([yaw, pitch, roll], 1)).astype(np.float32)


def quaternions(angles: np.ndarray) -> np.ndarray:
    """[T, 4] unit quaternions (x, y, z, w; glTF's order) of `rotations(angles)`."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(rotations(angles)).as_quat().astype(np.float32)
