"""facegen.validate: passes on files facegen writes, fails on each kind of broken file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from helpers import FPS, SR, make_animation
from pxr import Sdf, Vt

from facegen.exchange import write_animation
from facegen.face.mesh import Mesh
from facegen.validate import validate

FRAMES = 50


def failed(report) -> set[str]:
    return {c.name for c in report.failures}


def edit_layer(path: Path, edit) -> None:
    layer = Sdf.Layer.FindOrOpen(str(path))
    edit(layer)
    assert layer.Save()


POINTS = Sdf.Path("/Face/Mesh.points")
EXTENT = Sdf.Path("/Face/Mesh.extent")


@pytest.fixture
def good_usda(tmp_path, grid_mesh) -> Path:
    out = tmp_path / "good.usda"
    write_animation(make_animation(grid_mesh), out)
    return out


@pytest.mark.parametrize("ext", [".usda", ".usdc", ".usd"])
def test_good_usd_passes(tmp_path, grid_mesh, ext):
    out = tmp_path / f"ok{ext}"
    write_animation(make_animation(grid_mesh), out)
    for report in (validate(out, template=grid_mesh, fps=FPS), validate(out)):
        assert report.ok, report.to_text()
        names = [c.name for c in report.checks]
        for name in ("file", "mesh", "vertex count", "faces", "frame rate", "time samples", "finite",
                     "displacement", "audio", "audio duration", "usd validators"):
            assert name in names
        assert report.warnings == [] and report.failures == []
    report = validate(out, template=grid_mesh, fps=FPS)
    assert "120 vertices per frame (the template)" in report.check("vertex count").detail
    assert "identical to the template's" in report.check("faces").detail
    assert report.check("time samples").detail == "50 frames, one at each of 0..49"
    assert "2.000 s at 16000 Hz" in report.check("audio").detail


def test_good_npy_passes(tmp_path, grid_mesh):
    out = tmp_path / "ok.npy"
    write_animation(make_animation(grid_mesh), out)
    report = validate(out, template=grid_mesh)
    assert report.ok, report.to_text()
    assert {c.name for c in report.checks} == {"file", "vertex count", "finite", "displacement", "audio",
                                              "audio duration"}
    # the community's float64 files are read too
    np.save(tmp_path / "f64.npy", np.load(out).astype(np.float64))
    (tmp_path / "f64.wav").write_bytes((tmp_path / "ok.wav").read_bytes())
    assert validate(tmp_path / "f64.npy", template=grid_mesh).ok
    # without a template there is nothing to check against
    report = validate(out)
    assert not report.ok and failed(report) == {"template"}


def test_biwi_usd_passes(tmp_path, biwi_template):
    out = tmp_path / "biwi.usdc"
    write_animation(make_animation(biwi_template), out)
    report = validate(out, template=biwi_template, fps=FPS)
    assert report.ok, report.to_text()
    assert report.check("vertex count").detail.startswith("23370 vertices per frame")
    assert report.check("faces").detail.startswith("46068 triangles")


def test_wrong_fps(tmp_path, grid_mesh, good_usda):
    report = validate(good_usda, fps=30.0)
    assert failed(report) == {"frame rate"} and "expected 30 fps" in report.check("frame rate").detail
    # a file written at 30 fps for 50 frames of 25-fps audio: the duration no longer matches
    out = tmp_path / "fast.usda"
    anim = make_animation(grid_mesh, fps=30.0, audio_frames=FRAMES * 30 / 25)  # 2 s of audio, 50 frames
    write_animation(anim, out)
    assert failed(validate(out, fps=30.0)) == {"audio duration"}
    # framesPerSecond contradicting timeCodesPerSecond
    edit_layer(good_usda, lambda layer: setattr(layer, "framesPerSecond", 24.0))
    assert failed(validate(good_usda)) == {"frame rate"}


def test_missing_audio(tmp_path, grid_mesh, good_usda):
    (good_usda.parent / "good.wav").unlink()
    report = validate(good_usda)
    assert {"audio", "audio duration", "usd:usdUtilsValidators:MissingReferenceValidator"} == failed(report)
    assert "does not resolve" in report.check("audio").detail
    # written without audio: fails unless audio is not required
    out = tmp_path / "mute.usdc"
    write_animation(make_animation(grid_mesh), out, write_audio=False)
    assert failed(validate(out)) == {"audio", "audio duration"}
    assert validate(out, require_audio=False).ok
    # an explicit audio file is used for the duration check
    sf.write(str(tmp_path / "speech.wav"), np.zeros(2 * SR, np.float32), SR)
    assert validate(out, audio_path=tmp_path / "speech.wav", require_audio=False).ok
    npy = tmp_path / "mute.npy"
    write_animation(make_animation(grid_mesh), npy, write_audio=False)
    assert failed(validate(npy, template=grid_mesh)) == {"audio", "audio duration"}


def test_unreadable_audio(tmp_path, good_usda):
    (good_usda.parent / "good.wav").write_bytes(b"RIFF not really a wav")
    report = validate(good_usda)
    assert {"audio", "audio duration"} <= failed(report)
    assert "good.wav as audio" in report.check("audio").detail  # audio.load_audio's one-line error


def test_nan(tmp_path, grid_mesh):
    anim = make_animation(grid_mesh)
    anim.vertices[10, 5, 1] = np.nan
    anim.vertices[30, 7, 0] = np.inf
    for ext in (".usdc", ".npy"):
        write_animation(anim, tmp_path / f"nan{ext}")
        report = validate(tmp_path / f"nan{ext}", template=grid_mesh)
        assert failed(report) == {"finite", "displacement"}, report.to_text()  # NaN frames cannot be measured
        assert "2 frames" in report.check("finite").detail and "frame 10" in report.check("finite").detail
        assert ("2 frames with NaN/inf coordinates could not be measured"
                in report.check("displacement").detail)


def test_wrong_vertex_count(tmp_path, grid_mesh, good_usda):
    bigger = Mesh(np.concatenate([grid_mesh.vertices, grid_mesh.vertices[:5] + 1]), grid_mesh.faces)
    report = validate(good_usda, template=bigger)
    assert "vertex count" in failed(report) and "has 125" in report.check("vertex count").detail
    # one frame with fewer points inside the file itself
    short = Vt.Vec3fArray.FromNumpy(np.zeros((100, 3), np.float32))
    edit_layer(good_usda, lambda layer: layer.SetTimeSample(POINTS, 3.0, short))
    report = validate(good_usda)
    assert "vertex count" in failed(report) and "1 of 50 frames" in report.check("vertex count").detail
    npy = tmp_path / "v.npy"
    write_animation(make_animation(grid_mesh), npy)
    assert failed(validate(npy, template=bigger)) == {"vertex count", "finite"}


def test_different_faces(good_usda, grid_mesh):
    flipped = Mesh(grid_mesh.vertices, grid_mesh.faces[:, ::-1].copy())
    report = validate(good_usda, template=flipped)
    assert failed(report) == {"faces"} and "from triangle 0 on" in report.check("faces").detail
    fewer = Mesh(grid_mesh.vertices, grid_mesh.faces[:-2])
    report = validate(good_usda, template=fewer)
    assert failed(report) == {"faces"} and "the template has 196" in report.check("faces").detail


def test_exploded_vertex(tmp_path, grid_mesh):
    anim = make_animation(grid_mesh)
    anim.vertices[20, 7] += np.array([0.0, 0.0, 0.5 * grid_mesh.size], np.float32)
    write_animation(anim, tmp_path / "boom.usda")
    report = validate(tmp_path / "boom.usda")
    assert failed(report) == {"displacement"} and "(frame 20)" in report.check("displacement").detail
    assert validate(tmp_path / "boom.usda", max_displacement=0.6).ok
    write_animation(anim, tmp_path / "boom.npy")
    assert failed(validate(tmp_path / "boom.npy", template=grid_mesh)) == {"displacement"}


def test_sample_count_mismatch(tmp_path, grid_mesh, good_usda):
    anim = make_animation(grid_mesh, audio_frames=FRAMES + 3)
    write_animation(anim, tmp_path / "long_audio.usdc")
    report = validate(tmp_path / "long_audio.usdc")
    assert failed(report) == {"audio duration"} and "53.0 frames" in report.check("audio duration").detail
    assert validate(good_usda).ok
    write_animation(make_animation(grid_mesh, audio_frames=FRAMES + 0.9), tmp_path / "close.usdc")
    assert validate(tmp_path / "close.usdc").ok
    write_animation(anim, tmp_path / "long_audio.npy")
    assert failed(validate(tmp_path / "long_audio.npy", template=grid_mesh)) == {"audio duration"}


def test_time_samples_off_the_frame_grid(good_usda):
    value = Vt.Vec3fArray.FromNumpy(np.zeros((120, 3), np.float32))
    edit_layer(good_usda, lambda layer: layer.SetTimeSample(POINTS, 2.5, value))
    report = validate(good_usda)
    assert "time samples" in failed(report) and "instead of 0, 1, ..., 50" in report.check("time "
                                                                                           "samples").detail


def test_stale_extent(good_usda):
    wrong = Vt.Vec3fArray.FromNumpy(np.zeros((2, 3), np.float32))
    edit_layer(good_usda, lambda layer: layer.SetTimeSample(EXTENT, 4.0, wrong))
    report = validate(good_usda)
    assert failed(report) == {"time samples"} and "extent at time 4" in report.check("time samples").detail


def test_pxr_validators_fail_the_report(good_usda):
    def strip(layer):
        layer.ClearDefaultPrim()
        layer.pseudoRoot.ClearInfo("metersPerUnit")

    edit_layer(good_usda, strip)
    report = validate(good_usda)
    assert failed(report) == {"usd:usdValidation:StageMetadataChecker",
                              "usd:usdGeomValidators:StageMetadataChecker"}
    assert "metersPerUnit" in report.check("usd:usdGeomValidators:StageMetadataChecker").detail


def test_unreadable_files_are_reported_not_raised(tmp_path):
    (tmp_path / "junk.usdc").write_bytes(b"\x00garbage" * 10)
    (tmp_path / "junk.npy").write_bytes(b"\x00garbage" * 10)
    for name in ("junk.usdc", "junk.npy", "missing.usda", "x.fbx"):
        report = validate(tmp_path / name)
        assert not report.ok and failed(report) == {"file"}, name
    assert ".usda" in validate(tmp_path / "x.fbx").check("file").detail


def test_report_text_and_json(good_usda):
    (good_usda.parent / "good.wav").unlink()
    report = validate(good_usda, fps=24)
    text = report.to_text()
    assert text.splitlines()[0].startswith(f"{good_usda}: FAILED (")
    assert any(line.strip().startswith("FAIL  frame rate") for line in text.splitlines())
    assert any(line.strip().startswith("PASS  faces") for line in text.splitlines())
    data = json.loads(report.to_json())
    assert data["ok"] is False and data["path"] == str(good_usda)
    by_name = {c["name"]: c for c in data["checks"]}
    assert by_name["frame rate"]["ok"] is False and by_name["frame rate"]["severity"] == "error"
    assert by_name["finite"]["ok"] is True
