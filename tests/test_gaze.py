"""Gaze (issue 24): fixations and saccades on the main sequence, aversion as speech starts after a planning
pause, the eyeballs turned in the frames (never a lip vertex), the lids following the pitch, the Live Link
CSV's eye columns, reproducible by seed."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest
from helpers import phrase_pauses

from facegen.gaze import Saccade, gaze_curve, saccade_duration, saccades


def test_saccades_follow_the_main_sequence_and_the_speech():
    pauses = phrase_pauses(120.0, first=0.6, gap=(0.25, 1.0))
    found = saccades(120.0, pauses, seed=1)
    assert found == saccades(120.0, pauses, seed=1) and found != saccades(120.0, pauses, seed=2)
    assert len(found) >= 120 / 4  # at least one per 4 s
    starts = [s.start for s in found]
    assert starts == sorted(starts) and all(0 <= t < 120 for t in starts)
    here = np.zeros(2)
    amplitudes = []
    for s in found:
        amplitude = math.hypot(s.yaw - here[0], s.pitch - here[1])
        amplitudes.append(amplitude)
        assert s.duration == pytest.approx(saccade_duration(amplitude), abs=1e-3)
        assert abs(s.yaw) <= 15 and abs(s.pitch) <= 15
        here = np.array([s.yaw, s.pitch])
    assert min(amplitudes) >= 0.5 and max(amplitudes) <= 15 + 1e-3 and 1.5 <= np.median(amplitudes) <= 10
    gaps = np.diff(starts)
    assert np.median(gaps) >= 0.3 and gaps.max() <= 2.5  # fixations of 0.3-2 s (aversions held ~1-2 s)
    onsets = [b for a, b in pauses if b - a >= 0.5 and 0 < b < 119.7]
    averted = [o for o in onsets if any(o - 0.3 <= s.start <= o and abs(s.yaw) >= 5.9 for s in found)]
    assert len(averted) >= 0.6 * len(onsets)  # most planning pauses end in a look away


def test_gaze_curve_holds_between_saccades():
    found = [Saccade(0.5, saccade_duration(10), 10.0, 0.0), Saccade(1.5, saccade_duration(10), 10.0, -10.0)]
    curve = gaze_curve(found, 75, 25.0)
    assert curve.shape == (75, 2) and curve.dtype == np.float32
    assert np.all(curve[:12] == 0) and np.allclose(curve[15:37], [10, 0])
    assert np.allclose(curve[40:], [10, -10])
    assert np.all(np.diff(curve[:20, 0]) >= 0)  # monotone: minimum jerk, no overshoot


@pytest.fixture(scope="module")
def animated(tmp_path_factory):
    import soundfile as sf

    import facegen
    from facegen.espeak import synthesize

    parts = []
    for i, text in enumerate(["Where did you put the keys?", "I looked everywhere in the kitchen.",
                              "Maybe they are still in the car.", "Let me check again tomorrow."]):
        parts += [synthesize(text, variant="m1", sample_rate=16000).audio, np.full(12000, 1e-4, np.float32)]
    wav = tmp_path_factory.mktemp("gaze") / "speech.wav"
    sf.write(wav, np.concatenate(parts), 16000)
    return (wav, facegen.animate(wav, no_text=True, seed=0, head_motion=0),
            facegen.animate(wav, no_text=True, seed=9, head_motion=0))


def test_the_eyeballs_turn_and_the_lips_do_not(animated):
    _, anim, other = animated
    assert len(anim.metadata["saccades"]) >= 2 and anim.metadata["saccades"] != other.metadata["saccades"]
    eyes = np.concatenate([anim.regions["left_eyeball"], anim.regions["right_eyeball"]])
    moved = np.linalg.norm(anim.vertices[:, eyes] - anim.template[eyes], axis=-1).max()
    assert moved > 0.5 * anim.mesh.size / 200  # more than ~0.5 mm
    lips = anim.regions["lips"]
    assert np.array_equal(anim.vertices[:, lips], other.vertices[:, lips])  # seeds change eyes, not lips


def test_arkit_fit_and_live_link_eye_columns(animated, tmp_path):
    from facegen.arkit.solve import fit_arkit
    from facegen.exchange import arkit_csv

    _, anim, _ = animated
    fit = fit_arkit(anim)
    looks = [fit.weights[:, fit.names.index(f"eyeLook{d}Left")].max() for d in ("In", "Out", "Up", "Down")]
    assert max(looks) > 0.1
    path = tmp_path / "take.csv"
    arkit_csv.write(anim, path, write_audio=False)
    rows = list(csv.DictReader(path.open()))
    yaw = np.array([float(r["LeftEyeYaw"]) for r in rows])
    assert len(rows) == anim.num_frames and np.radians(1) < np.abs(yaw).max() <= np.radians(16)
    assert np.array_equal(yaw, [float(r["RightEyeYaw"]) for r in rows])
    assert all(float(r["HeadYaw"]) == 0 for r in rows)  # a still head (--head-motion 0)
