"""The real-face benchmark's measures (benchmarks/real_faces*.py) on synthetic landmark tracks with known
answers; the MediaPipe tracker itself only where its venv is (`make faces-venv`), else skipped."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCH))

import real_faces  # the benchmark's folder, put on the path above
import real_faces_measures as m

FPS = 25.0


def landmarks(aperture_px: np.ndarray, iris_px: float = 63.0, width_px: float = 450.0) -> np.ndarray:
    """Landmarks [T, 478, 3] of a still face, its inner lips `aperture_px` apart (iris 63 px: 0.1 cm/px)."""
    lm = np.zeros((len(aperture_px), 478, 3), np.float32)
    lm[:, m.IRIS[0], :2] = (200 - iris_px / 2, 100)
    lm[:, m.IRIS[1], :2] = (200 + iris_px / 2, 100)
    lm[:, m.LIP_INNER[0], :2] = (200, 300)
    lm[:, m.LIP_INNER[1], 0] = 200
    lm[:, m.LIP_INNER[1], 1] = 300 + np.asarray(aperture_px)
    lm[:, m.CORNERS[0], :2] = (200 - width_px / 2, 300)
    lm[:, m.CORNERS[1], :2] = (200 + width_px / 2, 300)
    lm[:, m.NOSE_CHIN[0], :2] = (200, 200)
    lm[:, m.NOSE_CHIN[1], 0] = 200
    lm[:, m.NOSE_CHIN[1], 1] = 400 + np.asarray(aperture_px) / 2  # the jaw takes half the opening
    return lm


def test_tracks_in_cm_on_the_iris_scale_and_gaps_filled():
    ap = np.array([0, 0, 10, 20, 10, 0], float)  # px
    lm = landmarks(ap)
    lm[3] = np.nan  # the tracker lost the face here: filled from frames 2 and 4
    tr = m.tracks_of(lm)
    assert tr.found == 5 and tr.iris_px == pytest.approx(63.0)
    assert np.allclose(tr.aperture, [0, 0, 1.0, 1.0, 1.0, 0], atol=1e-5)
    assert np.allclose(tr.width, 45.0, atol=1e-4)
    assert tr.jaw.min() == pytest.approx(0, abs=1e-5) and tr.jaw[2] == pytest.approx(0.5, abs=1e-5)
    with pytest.raises(ValueError):
        m.tracks_of(np.full((3, 478, 3), np.nan))


def test_best_lag_finds_a_late_prediction_and_the_ratio_its_scale():
    rng = np.random.default_rng(0)
    ref = np.convolve(rng.random(120), np.ones(4) / 4, "same")
    pred = 0.5 * np.roll(ref, 2)  # half as wide, two frames (80 ms) late
    r, lag = m.best_lag(pred, ref, FPS)
    assert lag == 2 and r == pytest.approx(1.0, abs=1e-6)
    assert m.lag_curve(pred, ref, FPS)[0] < 0.9
    assert set(m.lag_curve(pred, ref, FPS)) == set(range(-5, 6))  # +-200 ms at 25 fps
    assert m.median_ratio(pred, ref, ref > 0) == pytest.approx(0.5, rel=0.05)
    assert m.median_ratio(pred, ref, np.zeros(len(ref), bool)) is None
    # the pooled best lag is where the mean curve peaks
    assert m.pooled_best([{-1: 0.2, 0: 0.5, 1: 0.6}, {-1: 0.1, 0: 0.7, 1: 0.3}]) == (pytest.approx(0.6), 0)


def test_closure_rate_and_closure_timing_against_the_phones():
    ap = np.full(40, 1.0)
    ap[10:13] = 0.0  # closed at frames 10-12: the aperture crosses 0.1 cm at frames 9.9 and 12.1
    phones = [("AH", 0.2, 0.38), ("B", 0.38, 0.5), ("AH", 0.5, 0.7), ("M", 1.0, 1.1), ("AH", 1.1, 1.3)]
    assert m.closure_rate(ap, [11, 26]) == 0.5  # frame 26 (M's midpoint) is open
    assert m.closure_rate(ap, [13], reach=1) == 1.0 and m.closure_rate(ap, []) is None
    rows = m.closures(ap, phones, FPS)
    assert [r["phone"] for r in rows] == ["B", "M"] and [r["closed"] for r in rows] == [True, False]
    b = rows[0]
    assert b["close_s"] == pytest.approx(9.9 / FPS) and b["release_s"] == pytest.approx(12.1 / FPS)
    assert b["duration_s"] == pytest.approx(2.2 / FPS)
    assert b["close_offset_s"] == pytest.approx(9.9 / FPS - 0.38)
    assert b["release_offset_s"] == pytest.approx(12.1 / FPS - 0.5)
    assert not b["edge"] and rows[1]["edge"]  # M follows a 0.3 s pause


def test_vowels_per_viseme_and_class():
    tr = m.Tracks(np.linspace(0, 2, 50), np.full(50, 5.0), np.linspace(0, 1, 50), 50, 60.0)
    rows = m.vowel_values(tr, [("AA", 0.4, 0.6), ("AY", 1.0, 1.4), ("T", 1.4, 1.5)], FPS, 4.5)
    assert [(r["viseme"], r["phone"]) for r in rows] == [("AA", "AA"), ("AA", "AY"), ("IH", "AY")]
    assert rows[0]["aperture"] == pytest.approx(2 * 0.5 * FPS / 49)  # the track at 0.5 s
    assert rows[2]["t"] == pytest.approx(1.3) and rows[0]["width_change"] == pytest.approx(0.5)
    summary = m.summarize_vowels(rows)
    assert summary["AA"]["n"] == 2 and summary["class:open"]["n"] == 2 and summary["class:spread"]["n"] == 1


def test_jaw_at_consonants_over_vowels():
    jaw = np.zeros(50)
    jaw[10:15] = 1.0  # AA at 0.4-0.6 s: middle 0.5 s, frame 12.5
    jaw[20:25] = 0.5  # B at 0.8-1.0 s
    jaw[30:35] = 0.2  # F at 1.2-1.4 s
    phones = [("AA1", 0.4, 0.6), ("B", 0.8, 1.0), ("F", 1.2, 1.4), ("ZZ", 1.5, 1.6)]
    out = m.jaw_at_consonants([(jaw, phones), (jaw * 2, [("IY", 0.4, 0.6)])], FPS)
    assert out["vowels"] == {"n": 2, "jaw": pytest.approx(1.5)}
    assert out["p/b/m"] == {"n": 1, "ratio": pytest.approx(0.5 / 1.5)}
    assert out["f/v"]["ratio"] == pytest.approx(0.2 / 1.5)
    assert out["k/g"] == {"n": 0, "ratio": None}  # no k/g; an unknown phone is in no class


def test_leads_of_the_lips_over_the_sound():
    t = np.arange(0, 3, 0.01)
    loud = np.where((t > 0.8) & (t < 2.0), -10.0, -60.0) + 5 * np.sin(2 * np.pi * 4 * (t - 0.8))
    lips = np.interp(np.arange(75) / FPS + 0.08, t, np.clip(loud + 60, 0, None) / 50)  # the lips 80 ms early
    lead, r = m.envelope_lead(lips, FPS, loud)
    assert lead == pytest.approx(0.08, abs=0.021) and r > 0.9
    ap = np.zeros(75)
    ap[18:] = 1.0  # lips part between frames 17 and 18 (0.68-0.72 s): crossing 0.1 at 17.1 frames
    words, phones = [("lay", 0.8, 1.0)], [("L", 0.8, 0.85), ("EY", 0.85, 1.0)]
    assert m.onset_lead(ap, words, phones, FPS) == pytest.approx(0.8 - 17.1 / FPS)
    assert m.onset_lead(ap, [("bin", 0.8, 1.0)], [("B", 0.8, 0.85)], FPS) is None  # parts at the release
    assert m.onset_lead(np.ones(75), words, phones, FPS) is None  # never closed before the word


def test_grid_names_and_alignments():
    assert real_faces.grid_transcript("bbaf2n.mpg") == "bin blue at f two now"
    assert real_faces.grid_transcript("id2_vcd_swwp2s") == "set white with p two soon"
    assert real_faces.grid_transcript("lwbsza") == "lay white by s zero again"
    words = real_faces.read_grid_align(real_faces.DATA / "swwp2s.align")
    assert [w[0] for w in words] == ["set", "white", "with", "p", "two", "soon"]
    assert words[0][1:] == (0.49, 0.77) and words[-1][2] == 2.21
    shifted = [(w, a + 0.02, b - 0.02) for w, a, b in words]
    assert real_faces.alignment_error(shifted, words) == pytest.approx(0.02)
    assert real_faces.alignment_error(shifted[:-1], words) is None


def _faces_python() -> Path | None:
    path = Path(os.environ.get("FACEGEN_FACES_PYTHON", real_faces.FACES_VENV / "bin" / "python"))
    if not path.exists():
        return None
    found = subprocess.run([str(path), "-c", "import mediapipe"], capture_output=True, check=False)
    return path if found.returncode == 0 else None


@pytest.mark.skipif(_faces_python() is None, reason="no MediaPipe venv (make faces-venv)")
def test_tracker_sees_a_real_grid_speaker_close_for_the_b(tmp_path):
    """bbaf2n ('bin blue ...'): the speaker's lips part before speaking (frames 14-20) and close for the b
    of 'bin' (frame 23), as read off the clip's frames."""
    [lm] = real_faces.track([real_faces.DATA / "bbaf2n.mpg"], tmp_path / "lm.npz")
    tr = m.tracks_of(lm)
    assert len(tr) == 75 and tr.found == 75
    assert 40 < tr.iris_px < 55  # GRID's 360 x 288 frames
    assert tr.aperture[16:21].min() > 0.3 and tr.aperture[23] < m.CLOSED_CM
    assert 3.5 < np.median(tr.width) < 6.5
