"""Long points clips as USD value clips (facegen/exchange/usd_clips.py): the files, what usd-core composes
from them, read back, validate, usdz, atomic writes, the auto threshold, and Blender's import of them.

Short clips are forced into clips with `clips=N` (N frames per clip layer) or a lowered threshold, so every
test runs in a second; the 10-minute memory case is benchmarks/bench_export.py --usd-long 10.
"""

from __future__ import annotations

import itertools
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import FPS, make_animation, rig_clip
from pxr import Sdf, Usd, UsdGeom

from facegen.animation import Animation
from facegen.errors import FacegenError
from facegen.exchange import read_animation, usd_clips, write_animation
from facegen.exchange.usdz import contents
from facegen.validate import validate

TESTS = Path(__file__).resolve().parent
BLENDER_PYTHON = TESTS.parent / ".venv-blender" / "bin" / "python"
TOLERANCE = 1e-4  # of the face's size, as in test_blender.py
FRAMES, PER_CLIP = 50, 16  # 4 clip layers: frames 0-15, 16-31, 32-47, 48-49
BOUNDARIES = (0, 15, 16, 31, 32, 47, 48, 49)


class Blocks:
    """A stand-in for inference.FrameStream: frames only through blocks(n), in blocks of 7 (which straddle
    the clip boundaries); counts the frames it hands out."""

    def __init__(self, frames: np.ndarray, fail_after: int | None = None) -> None:
        self.frames, self.shape, self.given, self.fail_after = frames, frames.shape, 0, fail_after

    def blocks(self, block_frames=None, ahead=False):
        for start in range(0, len(self.frames), 7):
            if self.fail_after is not None and start >= self.fail_after:
                raise RuntimeError("inference failed")
            block = self.frames[start : start + 7].copy()
            self.given += len(block)
            yield start, block


def streamed(anim: Animation, fail_after: int | None = None) -> Animation:
    return Animation(Blocks(anim.vertices, fail_after), anim.faces, anim.fps, anim.template, anim.audio,
                     anim.sample_rate, metadata=anim.metadata)


def listing(folder) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


CLIP_FILES = ["clip.clips/clip.rest.usdc", "clip.clips/clip.manifest.usda", "clip.clips/clip.0000.usdc",
              "clip.clips/clip.0001.usdc", "clip.clips/clip.0002.usdc", "clip.clips/clip.0003.usdc"]


@pytest.mark.parametrize("ext", [".usdc", ".usda", ".usd"])
def test_value_clip_files_and_what_usd_composes(tmp_path, grid_mesh, ext):
    anim = make_animation(grid_mesh, frames=FRAMES)
    stream = streamed(anim)
    out = tmp_path / f"clip{ext}"
    written = write_animation(stream, out, clips=PER_CLIP)
    assert written == [out, tmp_path / "clip.wav", *(tmp_path / f for f in CLIP_FILES)]
    # no temporaries
    assert listing(tmp_path) == sorted([f"clip{ext}", "clip.wav", "clip.clips", *CLIP_FILES])
    assert stream.vertices.given == FRAMES  # each frame computed once

    # each clip layer holds exactly its frames' points and extents, at the stage's own time codes
    for k in range(4):
        layer = Sdf.Layer.FindOrOpen(str(tmp_path / f"clip.clips/clip.{k:04d}.usdc"))
        times = list(layer.ListTimeSamplesForPath("/Face/Mesh.points"))
        assert times == [float(t) for t in range(k * PER_CLIP, min((k + 1) * PER_CLIP, FRAMES))]
        assert list(layer.ListTimeSamplesForPath("/Face/Mesh.extent")) == times
        assert layer.timeCodesPerSecond == FPS
        np.testing.assert_array_equal(np.asarray(layer.QueryTimeSample("/Face/Mesh.points", times[-1])),
                                      anim.vertices[int(times[-1])])
    manifest = Sdf.Layer.FindOrOpen(str(tmp_path / "clip.clips/clip.manifest.usda"))
    assert sorted(manifest.GetPrimAtPath("/Face/Mesh").attributes.keys()) == ["extent", "points"]

    # the main layer: the clip set, the rest pose in its sublayer, no samples of its own
    root = Sdf.Layer.FindOrOpen(str(out))
    assert list(root.subLayerPaths) == ["./clip.clips/clip.rest.usdc"]
    assert not root.ListTimeSamplesForPath("/Face/Mesh.points")
    stage = Usd.Stage.Open(str(out))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Face/Mesh"))
    clips = Usd.ClipsAPI(mesh.GetPrim()).GetClips()["default"]
    assert [a.path for a in clips["assetPaths"]] == [f"./clip.clips/clip.{k:04d}.usdc" for k in range(4)]
    assert [tuple(a) for a in clips["active"]] == [(0, 0), (16, 1), (32, 2), (48, 3)]
    assert [tuple(t) for t in clips["times"]] == [(0, 0), (49, 49)]
    assert (clips["primPath"] == "/Face/Mesh"
            and clips["manifestAssetPath"].path == "./clip.clips/clip.manifest.usda")

    # composed: one animation, one sample per frame, exact values across the clip boundaries
    points, extent = mesh.GetPointsAttr(), mesh.GetExtentAttr()
    assert list(points.GetTimeSamples()) == [float(t) for t in range(FRAMES)]
    assert list(extent.GetTimeSamples()) == [float(t) for t in range(FRAMES)]
    for t in BOUNDARIES:
        np.testing.assert_array_equal(np.asarray(points.Get(t)), anim.vertices[t])
        np.testing.assert_array_equal(np.asarray(extent.Get(t)),
                                      np.stack([anim.vertices[t].min(0), anim.vertices[t].max(0)]))
    np.testing.assert_array_equal(np.asarray(points.Get(Usd.TimeCode.Default())), grid_mesh.vertices)
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode(), stage.GetTimeCodesPerSecond()) == (0, 49, FPS)

    back = read_animation(out)
    np.testing.assert_array_equal(back.vertices, anim.vertices)
    np.testing.assert_array_equal(back.template, grid_mesh.vertices)
    np.testing.assert_array_equal(back.audio, read_animation(out).audio)
    assert back.metadata["frames"] == FRAMES
    report = validate(out, fps=FPS)
    assert report.ok, report.to_text()
    assert "4 clip layers" in report.check("clips").detail
    assert report.check("time samples").detail == "50 frames, one at each of 0..49"


def test_auto_threshold_and_never(tmp_path, grid_mesh, monkeypatch):
    monkeypatch.setattr(usd_clips, "CLIP_THRESHOLD", 20)
    monkeypatch.setattr(usd_clips, "CLIP_FRAMES", 8)
    short, long = make_animation(grid_mesh, frames=20), make_animation(grid_mesh, frames=21)
    assert write_animation(short, tmp_path / "short.usdc") == [tmp_path / "short.usdc",
                                                               tmp_path / "short.wav"]
    written = write_animation(long, tmp_path / "long.usdc")
    assert [p.name for p in written[2:]] == ["long.rest.usdc", "long.manifest.usda", "long.0000.usdc",
                                             "long.0001.usdc", "long.0002.usdc"]
    assert write_animation(long, tmp_path / "one.usdc", clips="never") == [tmp_path / "one.usdc",
                                                                           tmp_path / "one.wav"]
    # blend shapes hold a few weights per frame: "auto" keeps them in one file
    assert len(write_animation(long, tmp_path / "bs.usdc", mode="blendshapes")) == 2
    for name in ("long", "one"):
        np.testing.assert_array_equal(read_animation(tmp_path / f"{name}.usdc").vertices, long.vertices)
    bs = read_animation(tmp_path / "bs.usdc").vertices  # a PCA within its tolerance (1e-3 of the face size)
    assert np.linalg.norm(bs - long.vertices, axis=2).max() <= 1e-3 * long.size
    assert not (tmp_path / "one.clips").exists() and not (tmp_path / "short.clips").exists()


def test_short_clips_keep_their_bytes(tmp_path, grid_mesh):
    """A clip under the threshold is the same one file as before value clips existed, byte for byte."""
    anim = make_animation(grid_mesh, frames=30)
    for ext in (".usda", ".usdc"):
        for folder, options in (("auto", {}), ("never", {"clips": "never"}), ("stream", {"clips": "never"})):
            (tmp_path / folder).mkdir(exist_ok=True)
            write_animation(streamed(anim) if folder == "stream" else anim, tmp_path / folder / f"a{ext}",
                            **options)
        assert len({(tmp_path / folder / f"a{ext}").read_bytes() for folder in ("auto", "never",
                                                                                "stream")}) == 1
    text = (tmp_path / "auto" / "a.usda").read_text()
    assert "clips" not in text and "subLayers" not in text


def test_rewrites_replace_the_clip_folder(tmp_path, grid_mesh):
    out = tmp_path / "clip.usdc"
    write_animation(make_animation(grid_mesh, frames=FRAMES), out, clips=PER_CLIP)
    fewer = make_animation(grid_mesh, frames=20)
    write_animation(fewer, out, clips=PER_CLIP)  # 2 clip layers now: the old 3rd and 4th are gone
    assert listing(tmp_path / "clip.clips") == ["clip.0000.usdc", "clip.0001.usdc", "clip.manifest.usda",
                                                "clip.rest.usdc"]
    np.testing.assert_array_equal(read_animation(out).vertices, fewer.vertices)
    write_animation(fewer, out, clips="never")  # one file again: its old clips are removed
    assert listing(tmp_path) == ["clip.usdc", "clip.wav"]
    np.testing.assert_array_equal(read_animation(out).vertices, fewer.vertices)


@pytest.mark.parametrize("exc", ["inference", "interrupt"])
def test_failed_long_write_leaves_nothing_and_keeps_the_old_asset(tmp_path, grid_mesh, exc, monkeypatch):
    anim = make_animation(grid_mesh, frames=FRAMES)
    out = tmp_path / "clip.usdc"
    if exc == "inference":  # the frames fail after two clip layers were written
        with pytest.raises(RuntimeError, match="inference"):
            write_animation(streamed(anim, fail_after=35), out, clips=PER_CLIP)
    else:
        finish = usd_clips._finish

        def interrupted(layer, path, *args):  # Ctrl-C once the third clip layer is saved
            finish(layer, path, *args)
            if path.name == "clip.0002.usdc":
                raise KeyboardInterrupt
        with monkeypatch.context() as patch:
            patch.setattr(usd_clips, "_finish", interrupted)
            with pytest.raises(KeyboardInterrupt):
                write_animation(anim, out, clips=PER_CLIP)
    assert listing(tmp_path) == []
    write_animation(anim, out, clips=PER_CLIP)
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    with pytest.raises(RuntimeError):
        write_animation(streamed(make_animation(grid_mesh, frames=40), fail_after=20), out, clips=PER_CLIP)
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == before
    np.testing.assert_array_equal(read_animation(out).vertices, anim.vertices)


@pytest.mark.parametrize(("options", "message"), [
    ({"clips": 0}, "auto, never or a positive number"),
    ({"clips": "sometimes"}, "auto, never or a positive number"),
    ({"clips": True}, "auto, never or a positive number"),
    ({"clips": 8, "mode": "blendshapes"}, "use the points mode"),
])
def test_bad_clip_options(tmp_path, grid_mesh, options, message):
    with pytest.raises(FacegenError, match=message):
        write_animation(make_animation(grid_mesh, frames=10), tmp_path / "x.usdc", **options)
    with pytest.raises(FacegenError, match="clips does not apply"):
        write_animation(make_animation(grid_mesh, frames=10), tmp_path / "x.glb", clips=8)
    assert listing(tmp_path) == []


def test_usdz_packs_the_clips(tmp_path, grid_mesh):
    anim = make_animation(grid_mesh, frames=FRAMES)
    out = tmp_path / "clip.usdz"
    assert write_animation(anim, out, clips=PER_CLIP) == [out]
    assert listing(tmp_path) == ["clip.usdz"]
    assert contents(out) == ["clip.usdc", *(f for f in sorted(CLIP_FILES[2:])),
                             "clip.clips/clip.manifest.usda",
                             "clip.clips/clip.rest.usdc", "clip.wav"]
    back = read_animation(out)
    np.testing.assert_array_equal(back.vertices, anim.vertices)
    np.testing.assert_array_equal(back.template, grid_mesh.vertices)
    report = validate(out)
    assert report.ok and report.check("clips").ok, report.to_text()


def test_validate_finds_broken_clips(tmp_path, grid_mesh):
    anim = make_animation(grid_mesh, frames=FRAMES)
    anim.vertices[20, 3, 1] = np.nan  # in the second clip
    out = tmp_path / "clip.usdc"
    write_animation(anim, out, clips=PER_CLIP)
    report = validate(out)
    assert not report.check("finite").ok and "first: frame 20" in report.check("finite").detail
    assert report.check("clips").ok and report.check("time samples").ok

    (tmp_path / "clip.clips/clip.0002.usdc").unlink()
    report = validate(out)
    assert not report.ok
    assert "clip layer ./clip.clips/clip.0002.usdc does not resolve" in report.check("clips").detail
    assert not report.check("time samples").ok  # frames 32..47 are missing from the composed animation
    assert not report.check("audio duration").ok


def test_validate_reads_one_frame_at_a_time(tmp_path, grid_mesh, monkeypatch):
    """The validator never asks the stage for a list of every frame: it reads the samples through lazy
    frames (PointsFrames), each once (its vertex count, extent, values), so a long clip is never held
    whole."""
    from facegen.exchange import usd

    out = tmp_path / "clip.usdc"
    write_animation(make_animation(grid_mesh, frames=FRAMES), out, clips=PER_CLIP)
    seen = []
    original = usd.PointsFrames.value
    monkeypatch.setattr(usd.PointsFrames, "value", lambda self, i: seen.append(i) or original(self, i))
    assert validate(out).ok
    assert sorted(seen) == list(range(FRAMES))


def test_cli_usd_clips_and_validate(tmp_path, grid_mesh):
    """`--usd-clips` is checked before any work; `facegen validate` follows the clips."""
    done = subprocess.run([sys.executable, "-m", "facegen", "animate", str(tmp_path / "none.wav"),
                           "--no-text",
                           "-o", str(tmp_path / "x.usdc"), "--usd-clips", "0"], capture_output=True,
                          text=True,
                          check=False)
    assert done.returncode == 2 and "auto, never or a positive number" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
    write_animation(make_animation(grid_mesh, frames=FRAMES), tmp_path / "clip.usdc", clips=PER_CLIP)
    done = subprocess.run([sys.executable, "-m", "facegen", "validate", str(tmp_path / "clip.usdc"),
                           "--json"],
                          capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stdout + done.stderr
    checks = {c["name"]: c for c in json.loads(done.stdout)["checks"]}
    assert checks["clips"]["ok"] and checks["time samples"]["detail"].startswith("50 frames")


# ---- Blender ---------------------------------------------------------------------------------------------

def test_blender_plays_value_clips(tmp_path):
    """Blender's USD importer composes the value clips through usd-core: the mesh-sequence cache shows each
    frame, across the clip boundaries, as written (the same checks as tests/test_blender.py's formats)."""
    if not BLENDER_PYTHON.is_file():
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(f"{BLENDER_PYTHON} is missing in CI: `make test` runs `make blender-venv` first")
        pytest.skip(f"{BLENDER_PYTHON} is missing: run `make blender-venv` to test the Blender import")
    frames = 60
    clip = rig_clip(frames, seed=6)  # adjacent frames across each boundary differ by > 10x the tolerance
    path = tmp_path / "clip.usdc"
    written = write_animation(clip, path, clips=16)
    assert len(written) == 2 + 2 + 4
    checked = (0, 15, 16, 31, 32, 47, 48, frames - 1)
    steps = [np.abs(clip.vertices[a] - clip.vertices[b]).max() for a, b in itertools.pairwise(checked)]
    assert min(steps) > 10 * TOLERANCE * clip.size  # Blender showing one frame of them everywhere would fail
    positions = {}
    for frame in checked:
        positions[str(frame)] = str(tmp_path / f"frame{frame}.npy")
        np.save(positions[str(frame)], clip.vertices[frame].astype(np.float64))
    expect = {"vertices": clip.num_vertices, "frames": frames, "fps": clip.fps, "meters_per_unit": 0.2,
              "tolerance": TOLERANCE * clip.size, "positions": positions, "sound_frames": frames,
              "packed": False}
    (tmp_path / "expect.json").write_text(json.dumps(expect))
    temp = tmp_path / "tmp"
    temp.mkdir()
    done = subprocess.run([str(BLENDER_PYTHON), str(TESTS / "blender_check.py"), str(path), "--expect-json",
                           str(tmp_path / "expect.json")], capture_output=True, text=True, timeout=300,
                          cwd=tmp_path,
                          check=False, env={**os.environ, "TMPDIR": str(temp)})
    lines = [line for line in done.stdout.splitlines() if line.startswith("blender_check: ")]
    assert lines, (f"blender_check printed no result (exit {done.returncode}):\n{done.stdout[-3000:]}\n"
                   f"{done.stderr[-3000:]}")
    result = json.loads(lines[-1].removeprefix("blender_check: "))
    assert done.returncode == 0
    failed = {name: c["detail"] for name, c in result["checks"].items() if not c["ok"]}
    assert not failed, failed
    assert result["import"]["warnings"] == [] and list(temp.iterdir()) == []
    errors = result["checks"]["positions"]["detail"]["max_abs_error"]
    assert set(errors) == set(positions) and max(errors.values()) <= TOLERANCE * clip.size
    sys.stdout.write(f"Blender, value clips: {result['checks']['positions']['detail']}\n")
