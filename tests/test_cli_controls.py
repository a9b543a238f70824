"""A control asked for that the output format cannot carry: one warning line naming the control and the
format (facegen.exchange.controls), the file still written, exit 0; none where the format carries it. The
table of what each format carries is the one docs/dcc.md shows."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from helpers import grid_face, make_bundle

from facegen.exchange.controls import CONTROLS, dropped, markdown_table
from facegen.exchange.formats import FORMATS

REPO = Path(__file__).resolve().parents[1]
SECONDS = 1.6


def run(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "facegen", *map(str, args)], capture_output=True, text=True,
                          cwd=REPO, timeout=300, check=False)


def warnings(proc: subprocess.CompletedProcess) -> list[str]:
    return [line for line in proc.stderr.splitlines() if "warning" in line]


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """Speech, a small audio-only model on facegen's face (its head turns) and one on a grid face (no head
    pivot: the head stays still)."""
    from facegen.espeak import synthesize
    from facegen.face.template import load_template

    d = tmp_path_factory.mktemp("controls")
    speech = synthesize("Bring the blue book to my office.", sample_rate=16000)
    sf.write(d / "line.wav", speech.audio[: int(SECONDS * 16000)], 16000)
    make_bundle(load_template(), d / "face.safetensors", modalities="audio", speakers=("F2", "M3"))
    make_bundle(grid_face(12, 10, height=0.8, bend=2.0), d / "grid.safetensors", modalities="audio",
                speakers=("F2", "M3"))
    return d


def animate(work: Path, out: str, *options, model: str = "face") -> subprocess.CompletedProcess:
    return run("animate", work / "line.wav", "--no-text", "--model", work / f"{model}.safetensors",
               "-o", work / out, *options)


def test_npy_warns_of_the_frame_rate_and_the_head(work):
    proc = animate(work, "npy/line.npy", "--fps", "30", "--head-motion", "2")
    assert proc.returncode == 0, proc.stderr
    head = ("facegen: warning: .npy holds vertex positions only: --head-motion 2 is written beside it, to "
            "line.head.npy ([T, 3] yaw, pitch, roll degrees); .usd*, .glb, .json and .csv carry the head in "
            "the file")
    fps = ("facegen: warning: .npy holds no frame rate: --fps 30 is not stored in line.npy, which facegen "
           "reads at 25 fps; read it with --fps 30 (render, validate) or write .usd*, .glb or .json, which "
           "store it")
    assert warnings(proc) == [head, fps]
    frames = np.load(work / "npy" / "line.npy").shape[0]
    assert frames == round(SECONDS * 30)
    head = np.load(work / "npy" / "line.head.npy")  # where the warning says
    assert head.shape == (frames, 3) and np.abs(head).max() > 0


@pytest.mark.parametrize("ext", ["usdc", "glb", "json"])
def test_formats_that_carry_them_say_nothing(work, ext):
    proc = animate(work, f"{ext}/line.{ext}", "--fps", "30", "--head-motion", "2")
    assert proc.returncode == 0, proc.stderr
    assert warnings(proc) == [] and (work / ext / f"line.{ext}").is_file()


@pytest.mark.parametrize(("fps", "said"), [("29.97", 1), ("30", 0)])
def test_csv_loses_a_fractional_frame_rate(work, fps, said):
    proc = animate(work, f"csv{fps}/line.csv", "--fps", fps)
    assert proc.returncode == 0, proc.stderr
    lost = ("facegen: warning: .csv holds no frame rate and its timecodes count whole frames: readers that "
            "take the rate from them get 30 fps from line.csv, not --fps 29.97; set 29.97 fps where you "
            "import it, or write .json (exportFps)")
    assert warnings(proc) == [lost][:said] and (work / f"csv{fps}" / "line.csv").is_file()


def test_defaults_and_a_face_without_head_warn_nothing(work):
    proc = animate(work, "plain/line.npy")
    assert proc.returncode == 0 and warnings(proc) == [], proc.stderr
    still = animate(work, "grid/line.npy", "--head-motion", "2", model="grid")  # no head pivot: no head
    assert still.returncode == 0 and warnings(still) == [], still.stderr
    assert (work / "grid" / "line.npy").is_file() and not (work / "grid" / "line.head.npy").exists()


def test_batch_warns_once_per_run(work):
    manifest = work / "lines.csv"
    manifest.write_text("audio,output,emotion\n" + "".join(f"{work / 'line.wav'},b{i}.npy,happy\n"
                                                            for i in range(3)))
    out = work / "batch"
    proc = run("batch", manifest, "-o", out, "--model", work / "face.safetensors", "--formats", "npy,json",
               "--fps", "30", "--head-motion", "2", "-j", "1", "--quiet")
    assert proc.returncode == 0, proc.stderr
    one = animate(work, "again/line.npy", "--fps", "30", "--head-motion", "2")  # animate's, of line.npy
    assert len(warnings(one)) == 2
    assert warnings(proc) == [line.replace("line.", "NAME.") for line in warnings(one)]  # once each
    assert all((out / f"b{i}.{ext}").is_file() for i in range(3) for ext in ("npy", "json"))


def test_the_table():
    assert all(set(c.carried) == {f.name for f in FORMATS} and all(c.carried.values()) for c in CONTROLS)
    assert markdown_table() in (REPO / "docs" / "dcc.md").read_text()
    assert dropped("x.usda", {"fps": 29.97, "head_motion": 3.0}) == []
    assert dropped("x.npy", {"fps": 25.0, "head_motion": 1.0, "emotion": None}) == []  # as not asked
    assert dropped("x.npy", {"head_motion": 0.0}) == []  # a still head: nothing to carry
    assert [line.split(":")[0] for line in dropped("x.npy", {"fps": 24.0, "head_motion": 0.5})] == [
        ".npy holds vertex positions only", ".npy holds no frame rate"]
