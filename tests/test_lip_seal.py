"""The lips shut on p, b and m (facegen.lip_seal): which frames, and the real pipeline's frames there."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from facegen.lip_seal import MIN_CLOSURE_S, SEALED_CM, seal_frames

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "excellent_room.wav"
FPS = 25.0


def test_frames_inside_a_long_bilabial_and_about_a_short_ones_middle():
    # a 120 ms m: the frames inside it (0.48, 0.52, 0.56)
    assert seal_frames([("M", 0.47, 0.59)], 100, FPS).tolist() == [12, 13, 14]
    # a 30 ms b between frames: held MIN_CLOSURE_S about its middle (0.545): the frames at 0.52 and 0.56
    assert MIN_CLOSURE_S == pytest.approx(0.08)
    assert seal_frames([("B", 0.53, 0.56)], 100, FPS).tolist() == [13, 14]
    # its middle on a frame: that frame and both neighbours, 40 ms away
    assert seal_frames([("P", 0.50, 0.54)], 100, FPS).tolist() == [12, 13, 14]


def test_only_p_b_m_and_only_frames_of_the_clip():
    phones = [("V", 0.2, 0.3), ("F", 0.4, 0.5), ("W", 0.6, 0.7), ("B", 0.8, 0.8), ("AA", 1.0, 1.2)]
    assert seal_frames(phones, 100, FPS).tolist() == []  # [β] reads as V: lips that near, not close
    assert seal_frames(None, 100, FPS).tolist() == []
    assert seal_frames([("P", -0.05, 0.01), ("M", 3.9, 4.2)], 100, FPS).tolist() == [0, 98, 99]


@pytest.fixture(scope="module")
def both():
    import facegen

    animator = facegen.Animator()
    text = (EXAMPLE.with_suffix(".txt")).read_text()
    kwargs = {"text": text, "blink_rate": 0, "head_motion": 0}
    return animator, animator.animate(EXAMPLE, **kwargs), animator.animate(EXAMPLE, lip_seal=False, **kwargs)


def test_the_aligned_bilabials_are_shut_and_nothing_else_moves(both):
    from facegen.lipsync import aperture

    animator, sealed, raw = both
    mesh = animator.mesh()
    assert sealed.metadata["lip_seal"]["on"] and not raw.metadata["lip_seal"]["on"]
    change = np.abs(np.asarray(sealed.vertices) - np.asarray(raw.vertices)).max(axis=(1, 2))
    moved = np.flatnonzero(change > 0)
    assert len(moved) == sealed.metadata["lip_seal"]["frames"] > 0
    gap_sealed, gap_raw = aperture(sealed.vertices, mesh), aperture(raw.vertices, mesh)
    # the frames it shut were open (the network left a gap there) and are closed to SEALED_CM now
    assert (gap_raw[moved] > SEALED_CM).all()
    assert np.allclose(gap_sealed[moved], SEALED_CM, atol=1e-4)
    assert gap_raw[moved].max() > 0.05  # at least one gap of half a millimetre or more was shut
    # every word with a p, b or m has its lips shut (by the network or the seal) at some frame; the seal
    # shut frames inside such words only
    words = {w["word"].lower().strip(".,!"): (w["start"], w["end"]) for w in sealed.metadata["words"]}
    bilabial = [span for word, span in words.items() if set(word) & set("pbm")]
    assert len(bilabial) == 2  # "room", "expensive"
    for start, end in bilabial:
        inside = np.arange(int(np.ceil(start * FPS)), int(end * FPS) + 1)
        assert gap_sealed[inside].min() <= SEALED_CM + 1e-4, (start, end)
    for k in moved:
        assert any(a * FPS - 2 <= k <= b * FPS + 2 for a, b in bilabial), k
    # the seal never crosses the lips (the network's own frames may, slightly, elsewhere)
    assert gap_sealed.min() >= min(gap_raw.min(), 0.0) - 1e-6


@pytest.mark.parametrize("flag", ["--lip-seal", "--no-lip-seal"])
def test_cli_flag(both, tmp_path, flag):
    """`facegen animate --no-lip-seal` writes the network's lips as they are; the default shuts them."""
    import subprocess
    import sys

    _, sealed, raw = both
    out = tmp_path / "lips.npy"
    args = [sys.executable, "-m", "facegen", "animate", str(EXAMPLE), "--text-file",
            str(EXAMPLE.with_suffix(".txt")), "-o", str(out), "--blink-rate", "0", "--head-motion", "0", "-q"]
    if flag == "--no-lip-seal":
        args.append(flag)
    subprocess.run(args, check=True, capture_output=True)
    frames = np.load(out).reshape(len(raw.vertices), -1, 3)
    want, other = (raw, sealed) if flag == "--no-lip-seal" else (sealed, raw)
    assert np.allclose(frames, want.vertices, atol=1e-6)
    assert not np.allclose(frames, other.vertices, atol=1e-6)


def test_batch_flag(both, tmp_path):
    """`facegen batch --no-lip-seal` writes the network's lips; a rerun with the seal is not skipped as
    unchanged (the option is in the items' content key) and writes the sealed frames."""
    import csv
    import subprocess
    import sys

    _, sealed, raw = both
    manifest = tmp_path / "lines.csv"
    with open(manifest, "w", newline="") as f:
        csv.writer(f).writerows([["audio", "text", "output"],
                                 [str(EXAMPLE), EXAMPLE.with_suffix(".txt").read_text(), "line.npy"]])
    command = [sys.executable, "-m", "facegen", "batch", str(manifest), "-o", str(tmp_path / "out"), "-q",
               "--jobs", "1", "--blink-rate", "0", "--head-motion", "0"]
    for extra, want in ((["--no-lip-seal"], raw), ([], sealed)):
        done = subprocess.run(command + extra, check=False, capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
        frames = np.load(tmp_path / "out" / "line.npy").reshape(len(want.vertices), -1, 3)
        assert np.allclose(frames, want.vertices, atol=1e-6), extra
