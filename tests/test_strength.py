"""--strength (issue 24): the network's motion scaled by region — the lips by their scale, the brows held at
rest at 0, smooth across the borders, the same in the ARKit fit (a stream's projection) as in the frames,
recorded in the metadata, per line in batch manifests, and one-line refusals of bad values."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import facegen
from facegen import inference
from facegen.errors import FacegenError
from facegen.strength import as_text, parse_strength, region_scales

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "excellent_room.wav"
TEXT = (EXAMPLE.with_suffix(".txt")).read_text().strip()
STILL = {"blink_rate": 0, "head_motion": 0}  # no blinks; the gaze's lids are not scaled (their own layer)


def test_parse_and_bad_values():
    assert parse_strength("lips=1.2, upper=0") == {"lips": 1.2, "jaw": 1.0, "upper": 0.0}
    assert parse_strength({"jaw": 2}) == {"lips": 1.0, "jaw": 2.0, "upper": 1.0}
    assert parse_strength(None) is None and parse_strength("lips=1,jaw=1") is None
    assert as_text(parse_strength("upper=1.5")) == "lips=1,jaw=1,upper=1.5"
    for bad, said in [("lips", "not REGION=SCALE"), ("lips=x", "not a number"),
                      ("nose=1", "unknown strength"), ("lips=-0.1", "from 0"), ("lips=3.5", "from 0"),
                      ("lips=nan", "from 0"),
                      ("lips=1,lips=2", "twice"), (3, "must be a string")]:
        with pytest.raises(FacegenError, match=said):
            parse_strength(bad)


def test_scales_are_smooth_across_region_borders():
    from facegen.face.template import load_template

    mesh = load_template()
    scales = region_scales(mesh, parse_strength("lips=2,jaw=1,upper=0"))
    assert scales.shape == (len(mesh.vertices),) and scales.min() >= 0 and scales.max() <= 2 + 1e-6
    assert np.median(scales[mesh.regions["lips"]]) > 1.9
    assert np.median(scales[mesh.regions["brows"]]) < 0.05
    faces = np.asarray(mesh.faces)
    jumps = np.abs(scales[faces] - scales[np.roll(faces, 1, axis=1)]).max()
    assert jumps < 0.35, jumps  # no edge jumps from one region's scale to the next


def test_a_scaled_streams_projection_is_its_frames_projection():
    rng = np.random.default_rng(8)
    states = rng.standard_normal((300, 12)).astype(np.float32)
    weight = (0.01 * rng.standard_normal((60, 12))).astype(np.float32)
    origin = rng.standard_normal((20, 3)).astype(np.float32)
    base = origin.reshape(-1) + 0.01 * rng.standard_normal(60).astype(np.float32)
    scales = rng.uniform(0, 3, 20).astype(np.float32)
    plain = inference.FrameStream(states, weight, base, block_frames=64)
    stream = plain.with_scale(scales, origin)
    frames = np.asarray(stream).astype(np.float64)
    expected = origin + scales[None, :, None] * (np.asarray(plain).astype(np.float64) - origin)
    np.testing.assert_allclose(frames, expected, rtol=1e-5, atol=1e-5)
    basis = rng.standard_normal((4, 60)).astype(np.float32)
    at = rng.standard_normal(60).astype(np.float32)
    np.testing.assert_allclose(stream.project(basis, at), (frames.reshape(300, -1) - at) @ basis.T,
                               rtol=1e-5, atol=1e-4)
    layered = stream.with_layers(np.ones((300, 1)), np.full((1, 60), 0.5))  # layers: added unscaled
    np.testing.assert_allclose(np.asarray(layered), frames + 0.5, atol=1e-5)


@pytest.fixture(scope="module")
def pair():
    plain = facegen.animate(EXAMPLE, text=TEXT, **STILL)
    scaled = facegen.animate(EXAMPLE, text=TEXT, strength="lips=2,jaw=1,upper=0", **STILL)
    return plain, scaled


def test_the_lips_move_twice_as_far_and_the_brows_not_at_all(pair):
    plain, scaled = pair
    t = plain.template

    def moved(anim, region):
        idx = anim.regions[region]
        return float(np.linalg.norm(anim.vertices[:, idx] - t[idx], axis=2).mean())

    for region in ("mouth_lower_margin", "mouth_upper_margin"):
        assert moved(scaled, region) / moved(plain, region) == pytest.approx(2.0, rel=0.02)
    # the brows move (3.0e-3 on average over the clip with the default model), and not at all at upper=0
    assert moved(plain, "brows") > 1e-4 and moved(scaled, "brows") < 1e-3 * moved(plain, "brows")
    assert scaled.metadata["strength"] == {"lips": 2.0, "jaw": 1.0, "upper": 0.0}
    assert "strength" not in plain.metadata


def test_the_arkit_fit_sees_the_scaled_motion(tmp_path):
    plain, scaled = tmp_path / "plain.json", tmp_path / "scaled.json"
    for out, extra in ((plain, []), (scaled, ["--strength", "lips=1.8,jaw=1.8,upper=0"])):
        subprocess.run([sys.executable, "-m", "facegen", "animate", str(EXAMPLE), "--text", TEXT, "-o",
                        str(out), "--blink-rate", "0", "--head-motion", "0", "-q", *extra], check=True)
    a, b = (json.loads(p.read_text()) for p in (plain, scaled))
    names = a["facsNames"]
    wa, wb = np.array(a["weightMat"]), np.array(b["weightMat"])
    jaw = names.index("jawOpen")
    brows = [names.index(n) for n in names if n.startswith("brow")]
    assert wb[:, jaw].max() > 1.4 * wa[:, jaw].max()
    assert wb[:, brows].max() < 0.005 and wa[:, brows].max() > 0.01  # upper=0: the fit's crosstalk alone


def test_bad_strength_is_one_line_and_writes_nothing(tmp_path):
    out = tmp_path / "x.usdc"
    done = subprocess.run([sys.executable, "-m", "facegen", "animate", str(EXAMPLE), "--text", TEXT, "-o",
                           str(out), "--strength", "lips=9"], capture_output=True, text=True, check=False)
    assert done.returncode == 2 and not out.exists()
    assert done.stderr.count("\n") == 1 and "lips strength must be a number from 0" in done.stderr


def test_batch_takes_a_strength_column(tmp_path):
    import csv

    manifest = tmp_path / "lines.csv"

    def rows(*strengths):
        with manifest.open("w", newline="") as f:
            out = csv.writer(f)
            out.writerow(["audio", "text", "output", "strength"])
            out.writerows([EXAMPLE, TEXT, f"{name}.json", s] for name, s in zip("abc", strengths))

    command = [sys.executable, "-m", "facegen", "batch", str(manifest), "-o", str(tmp_path / "out"), "-q",
               "--strength", "lips=1.5", "--jobs", "1"]
    rows("lips=1,upper=0", "", "nose=2")
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    assert done.returncode == 2 and "unknown strength region 'nose'" in done.stderr  # the plan: before work
    assert not (tmp_path / "out").exists()
    rows("lips=1,upper=0", "")
    subprocess.run(command, check=True)
    a, b = (json.loads((tmp_path / "out" / n).read_text())["facegen"] for n in ("a.json", "b.json"))
    assert a["strength"] == {"lips": 1.0, "jaw": 1.0, "upper": 0.0}  # the row's own
    assert b["strength"] == {"lips": 1.5, "jaw": 1.0, "upper": 1.0}  # the run's
