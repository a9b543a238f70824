"""ARKit weight files: Audio2Face JSON and Live Link Face CSV, reopened with json/csv, validated, and the
CLI."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import grid_face, make_animation, make_bundle, rig_clip

from facegen.arkit.names import ARKIT_NAMES, LIVE_LINK_COLUMNS, arkit_name
from facegen.arkit.solve import fit_arkit
from facegen.errors import FacegenError
from facegen.exchange import write_animation
from facegen.exchange.arkit_csv import parse_timecode, timecode
from facegen.validate import validate

REPO = Path(__file__).resolve().parents[1]
FRAMES = 60


@pytest.fixture(scope="module")
def clip():
    anim = rig_clip(FRAMES)
    return anim, fit_arkit(anim)


def failed(report) -> list[str]:
    return [c.name for c in report.failures]


def test_json_is_audio2face_layout(tmp_path, clip):
    anim, fit = clip
    files = write_animation(anim, tmp_path / "line.json")
    assert files == [tmp_path / "line.json", tmp_path / "line.wav"]
    doc = json.loads(files[0].read_text())
    assert list(doc)[:6] == ["exportFps", "trackPath", "numPoses", "numFrames", "facsNames", "weightMat"]
    assert doc["exportFps"] == 25 and doc["numPoses"] == 52 and doc["numFrames"] == FRAMES
    assert doc["facsNames"] == list(ARKIT_NAMES) and doc["trackPath"] == "line.wav"
    weights = np.asarray(doc["weightMat"])
    assert weights.shape == (FRAMES, 52) and weights.min() >= 0 and weights.max() <= 1
    assert np.abs(weights - fit.weights).max() <= 1e-5  # rounded to 5 decimals
    assert doc["facegen"]["lip_error_mm"] == pytest.approx(fit.lip_error_mm, abs=1e-4)
    report = validate(files[0])
    assert report.ok, report.to_text()
    assert report.check("fit").ok and "mm" in report.check("fit").detail
    assert report.check("audio duration").ok


def test_csv_is_live_link_face_layout(tmp_path, clip):
    anim, fit = clip
    files = write_animation(anim, tmp_path / "take.csv")
    assert files == [tmp_path / "take.csv", tmp_path / "take.wav"]
    with open(files[0], newline="") as f:
        header, *rows = list(csv.reader(f))
    assert tuple(header) == LIVE_LINK_COLUMNS and len(rows) == FRAMES
    assert [r[0] for r in rows[:2]] == ["00:00:00:00.000", "00:00:00:01.000"]
    assert rows[26][0] == "00:00:01:01.000"  # frame 26 at 25 fps: second 1, frame 1
    assert {r[1] for r in rows} == {"61"}
    values = np.asarray([[float(v) for v in r[2:]] for r in rows])
    by_name = {arkit_name(c): values[:, i] for i, c in enumerate(header[2:54])}
    weights = np.stack([by_name[n] for n in ARKIT_NAMES], 1)
    assert np.abs(weights - fit.weights).max() <= 1e-5 and weights.min() >= 0 and weights.max() <= 1
    assert not values[:, 52:].any()  # head and eye rotations: none
    report = validate(files[0], fps=25)
    assert report.ok, report.to_text()


def test_timecodes():
    assert timecode(0, 25) == "00:00:00:00.000"
    assert timecode(3600 * 25 + 61, 25) == "01:00:02:11.000"
    assert [timecode(i, 29.97)[-6:] for i in (29, 30)] == ["29.000", "00.000"]
    assert parse_timecode("14:03:52:28.207") == (14 * 3600 + 3 * 60 + 52, 28, pytest.approx(0.207))
    assert parse_timecode("1:2:3") is None


def _json(tmp_path: Path, name: str, edit) -> Path:
    doc = {"exportFps": 30, "trackPath": "", "numPoses": 52, "numFrames": 3, "facsNames": list(ARKIT_NAMES),
           "weightMat": [[0.1] * 52 for _ in range(3)]}
    edit(doc)
    path = tmp_path / name
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize("edit, problem", [
    (lambda d: d.pop("numPoses"), "keys"),
    (lambda d: d["facsNames"].__setitem__(3, "eyeLookSideways"), "names"),
    (lambda d: d["weightMat"][1].__setitem__(5, float("nan")), "finite"),
    (lambda d: d["weightMat"][2].__setitem__(0, 1.5), "range"),
    (lambda d: d.update(numFrames=4), "frame count"),
    (lambda d: d.update(exportFps=0), "fps"),
    (lambda d: d["weightMat"][0].pop(), "pose count"),
])
def test_validate_finds_each_json_problem_once(tmp_path, edit, problem):
    assert validate(_json(tmp_path, "good.json", lambda d: None), require_audio=False).ok
    report = validate(_json(tmp_path, "bad.json", edit), require_audio=False)
    assert failed(report) == [problem], report.to_text()


def test_validate_json_order_and_garbage(tmp_path):
    report = validate(_json(tmp_path, "order.json", lambda d: d["facsNames"].reverse()), require_audio=False)
    assert report.ok and not report.check("name order").ok  # another order: a warning only
    (tmp_path / "list.json").write_text("[1, 2]")
    assert failed(validate(tmp_path / "list.json")) == ["file"]


def _csv(tmp_path: Path, name: str, edit) -> Path:
    rows = [[timecode(i, 30), "61"] + ["0.2"] * 52 + ["0"] * 9 for i in range(40)]
    header = list(LIVE_LINK_COLUMNS)
    edit(header, rows)
    path = tmp_path / name
    path.write_text("\n".join(",".join(r) for r in [header, *rows]) + "\n")
    return path


@pytest.mark.parametrize("edit, problem", [
    (lambda h, r: r[5].__setitem__(1, "51"), "BlendShapeCount"),
    (lambda h, r: r[7].__setitem__(0, r[3][0]), "timecode"),
    (lambda h, r: r[7].__setitem__(0, "7 o'clock"), "timecode"),
    (lambda h, r: r[2].__setitem__(20, "abc"), "finite"),
    (lambda h, r: r[2].__setitem__(20, "-0.5"), "range"),
    (lambda h, r: h.__setitem__(10, "EyeLookSideways"), "names"),
    (lambda h, r: r[9].pop(), "row length"),
])
def test_validate_finds_each_csv_problem_once(tmp_path, edit, problem):
    assert validate(_csv(tmp_path, "good.csv", lambda h, r: None), require_audio=False).ok
    report = validate(_csv(tmp_path, "bad.csv", edit), require_audio=False)
    assert failed(report) == [problem], report.to_text()


def test_no_rig_regions_writes_nothing(tmp_path):
    anim = make_animation(grid_face(), frames=5)
    for name in ("x.json", "x.csv"):
        with pytest.raises(FacegenError, match="regions"):
            write_animation(anim, tmp_path / name)
    assert list(tmp_path.iterdir()) == []


def run(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "facegen", *map(str, args)], capture_output=True, text=True,
                          timeout=600, check=False, cwd=REPO)


def test_cli_animate_json_with_the_default_model(tmp_path):
    out = tmp_path / "room.json"
    p = run("animate", "examples/excellent_room.wav", "--text-file", "examples/excellent_room.txt", "-o", out,
            "-q")
    assert p.returncode == 0, p.stderr
    doc = json.loads(out.read_text())
    assert doc["facsNames"] == list(ARKIT_NAMES) and doc["numFrames"] == len(doc["weightMat"]) > 50
    assert doc["facegen"]["lip_error_mm"] < 0.5
    jaw = np.asarray(doc["weightMat"])[:, ARKIT_NAMES.index("jawOpen")]
    assert jaw.max() > 0.1  # the mouth opens while speaking
    val = run("validate", out, "--json")
    assert val.returncode == 0 and json.loads(val.stdout)["ok"], val.stdout


def test_cli_model_without_the_rig_is_one_line_exit_2(tmp_path):
    make_bundle(grid_face(), tmp_path / "grid.safetensors")
    p = run("animate", "examples/excellent_room.wav", "--no-text", "--model", tmp_path / "grid.safetensors",
            "-q",
            "--device", "cpu", "-o", tmp_path / "out.csv")
    assert p.returncode == 2, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in p.stderr and "regions" in lines[0]
    assert sorted(f.name for f in tmp_path.iterdir()) == ["grid.safetensors"]
