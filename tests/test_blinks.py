"""Blinks timed by the speech (issue 24): when (rate, pauses, not periodic, doubles), how (durations, shut
at a frame), where (the lids only: never a lip vertex), in every format (the ARKit fit reads eyeBlink from the
lids), reproducible by seed, and the bad values."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from helpers import phrase_pauses

from facegen import blinks
from facegen.blinks import Blink, blink_curve, blink_stats, blink_times
from facegen.errors import FacegenError


def test_blinks_during_speech_follow_its_pauses_at_the_rate_asked():
    rates, near, cvs = [], [], []
    for seed in range(8):
        pauses = phrase_pauses(60.0, seed)
        found = blink_times(60.0, pauses, seed=seed)
        curve = blink_curve(found, 1500, 25.0)
        stats = blink_stats(curve, 25.0, pauses)
        rates.append(stats.per_minute)
        near.append(stats.near_pause)
        cvs.append(stats.interval_cv)
        assert all(0.1 <= b.duration <= 0.4 for b in found)
        assert all(0.04 <= d <= 0.4 for d in stats.durations)  # what a viewer sees of each (lids > 10 % shut)
    assert 10 <= np.median(rates) <= 30 and min(rates) >= 8, rates
    assert np.median(near) >= 0.6, near  # most blinks at pauses and phrase ends
    assert np.median(cvs) >= 0.3, cvs  # not periodic


def test_rate_seed_and_doubles():
    pauses = phrase_pauses(600.0)
    assert blink_times(600.0, pauses, rate=0) == []
    assert blink_times(600.0, pauses, seed=3) == blink_times(600.0, pauses, seed=3)
    assert blink_times(600.0, pauses, seed=3) != blink_times(600.0, pauses, seed=4)
    few, many = (len(blink_times(600.0, pauses, rate=r)) for r in (8, 30))
    assert 50 <= few <= 110 and 220 <= many <= 360, (few, many)
    found = blink_times(600.0, pauses, rate=20)
    gaps = np.diff([b.start for b in found])
    doubles = np.sum(gaps < 0.6)  # a second blink right after the first
    assert 0.02 * len(found) <= doubles <= 0.2 * len(found)
    idle = blink_times(60.0, [(0.0, 60.0)], rate=17)  # no speech: blinks all the same
    assert 8 <= len(idle) <= 30


@pytest.mark.parametrize("fps", [24.0, 25.0, 30.0, 60.0])
def test_every_blink_is_shut_at_a_frame(fps):
    found = [Blink(1.0 + 1.37 * k + 0.013 * k, 0.12 + 0.02 * k) for k in range(12)]
    curve = blink_curve(found, int(20 * fps), fps)
    assert curve.dtype == np.float32 and 0 <= curve.min() and curve.max() <= 1
    t = np.arange(len(curve)) / fps
    for b in found:
        inside = (t >= b.start) & (t < b.start + b.duration)
        assert curve[inside].max() == 1.0  # fully shut for at least one frame, however short the blink
    outside = ~np.any([(t >= b.start) & (t < b.start + b.duration + 1e-6) for b in found], axis=0)
    assert np.all(curve[outside] == 0)
    b = found[5]  # closing faster than opening
    k = np.flatnonzero((t >= b.start) & (t < b.start + b.duration))
    shut = k[curve[k] == 1.0]
    assert shut[0] - k[0] <= k[-1] - shut[-1] + 1


def test_bad_values_are_one_line_errors():
    for rate in (-1, float("nan"), float("inf"), 500, "10", True):
        with pytest.raises(FacegenError, match="blink rate"):
            blinks.check_blink_rate(rate)
    for seed in (-1, 2**32, 1.5, "3", True):
        with pytest.raises(FacegenError, match="seed"):
            blinks.check_seed(seed)


@pytest.fixture(scope="module")
def spoken(tmp_path_factory):
    """20 s of espeak speech in phrases with pauses, and its transcript."""
    import soundfile as sf

    from facegen.espeak import synthesize

    sentences = ["The quick brown fox jumps over the lazy dog.", "We walked along the river until evening.",
                 "Please bring the blue book to my office.", "Nobody knew where the money had gone.",
                 "She sells sea shells by the sea shore.", "It was the best of times."]
    parts = []
    for i, text in enumerate(sentences):
        parts += [synthesize(text, variant=("m1", "f3")[i % 2], sample_rate=16000).audio,
                  np.full(int(0.6 * 16000), 1e-4, np.float32)]
    path = tmp_path_factory.mktemp("blinks") / "speech.wav"
    sf.write(path, np.concatenate(parts), 16000)
    return path, " ".join(sentences)


def test_animate_blinks_in_the_lids_only(spoken):
    import facegen
    from facegen.arkit.solve import fit_arkit

    wav, text = spoken
    anim = facegen.animate(wav, text=text)
    still = facegen.animate(wav, text=text, blink_rate=0)
    again = facegen.animate(wav, text=text)
    assert np.array_equal(anim.vertices, again.vertices)  # the same seed: the same frames
    times = anim.metadata["blinks"]["times"]
    assert len(times) >= 3 and anim.metadata["blinks"]["seed"] == 0
    assert still.metadata["blinks"]["times"] == []
    moved = np.abs(anim.vertices - still.vertices).max(axis=(0, 2))
    lids = np.concatenate([anim.regions[f"{side}_upper_lid_margin"] for side in ("left", "right")])
    assert moved[anim.regions["lips"]].max() == 0.0  # a blink never moves a lip vertex
    assert moved[lids].min() > 0
    fit = fit_arkit(anim)
    for side in ("Left", "Right"):
        blink = fit.weights[:, fit.names.index(f"eyeBlink{side}")]
        for start, duration in times:
            frames = blink[int(start * 25):int(np.ceil((start + duration) * 25)) + 1]
            assert frames.max() >= 0.8, (side, start)  # shut at the closed frame
    other = facegen.animate(wav, text=text, seed=7)
    assert other.metadata["blinks"]["times"] != times


def test_cli_blink_options(spoken, tmp_path):
    import json

    wav, text = spoken
    out = tmp_path / "a.json"
    command = [sys.executable, "-m", "facegen", "animate", str(wav), "--text", text, "-o", str(out)]
    bad = subprocess.run([*command, "--blink-rate", "-2"], check=False, capture_output=True, text=True)
    assert bad.returncode == 2 and "blink-rate" in bad.stderr and not out.exists()
    assert len(bad.stderr.strip().splitlines()) == 1
    done = subprocess.run([*command, "--blink-rate", "25", "--seed", "5", "-q"], check=False,
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    meta = json.loads(out.read_text())["facegen"]["blinks"]
    assert meta["rate_per_minute"] == 25 and meta["seed"] == 5 and meta["times"]


def test_layers_join_the_stream_as_states():
    from facegen.inference import FrameStream

    rng = np.random.default_rng(1)
    states, weight, base = rng.normal(size=(70, 8)), rng.normal(size=(30, 8)), rng.normal(size=30)
    stream = FrameStream(states, weight, base, block_frames=16)
    curves, offsets = rng.uniform(size=(70, 2)), rng.normal(size=(2, 30))
    layered = stream.with_layers(curves, offsets)
    expected = np.asarray(stream).reshape(70, -1) + curves @ offsets
    assert np.allclose(np.asarray(layered).reshape(70, -1), expected, atol=1e-5)
    basis, origin = rng.normal(size=(4, 30)), rng.normal(size=30)
    assert np.allclose(layered.project(basis, origin), (expected - origin) @ basis.T, atol=1e-4)
    assert np.allclose(np.asarray(layered.every(3)).reshape(-1, 30), expected[::3], atol=1e-5)


def test_the_same_seed_writes_the_same_files(tmp_path):
    """Blinks, saccades and the head's drift are drawn from --seed: the same inputs and seed give
    bit-identical files, another seed other ones."""
    outputs = {}
    for folder, seed in (("a", "3"), ("b", "3"), ("c", "4")):
        (tmp_path / folder).mkdir()
        for ext in (".glb", ".json"):
            done = subprocess.run([sys.executable, "-m", "facegen", "animate", "examples/excellent_room.wav",
                                   "--text-file", "examples/excellent_room.txt", "-o",
                                   str(tmp_path / folder / f"line{ext}"), "--seed", seed, "-q"],
                                  check=False, capture_output=True, text=True)
            assert done.returncode == 0, done.stderr
            outputs[folder, ext] = (tmp_path / folder / f"line{ext}").read_bytes()
    for ext in (".glb", ".json"):
        assert outputs["a", ext] == outputs["b", ext] and outputs["a", ext] != outputs["c", ext], ext
