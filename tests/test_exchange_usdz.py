"""USDZ packages (facegen.exchange.usdz): the stage and its WAV inside one file, read back through USD's
package resolver, validated (including pxr's usdz validators), written atomically."""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest
import soundfile as sf
from helpers import FPS, SR, Boom, make_animation, max_distance, rich_animation, usdskel_points
from pxr import Ar, Sdf, Usd, UsdGeom, UsdMedia, UsdValidation

from facegen.errors import FacegenError
from facegen.exchange import extensions, read_animation, write_animation
from facegen.exchange.pca import DEFAULT_TOLERANCE
from facegen.exchange.usdz import contents
from facegen.validate import validate


def usdz_findings(path) -> list[str]:
    """Errors and warnings of pxr's usdz validators (keyword UsdzValidators) on the package."""
    registry = UsdValidation.ValidationRegistry()
    metadata = registry.GetValidatorMetadataForKeyword("UsdzValidators")
    validators = registry.GetOrLoadValidatorsByName([m.name for m in metadata])
    assert len(validators) >= 3  # root package, package encapsulation, file extensions, usdz package
    errors = UsdValidation.ValidationContext(validators).Validate(Usd.Stage.Open(str(path)))
    kinds = (UsdValidation.ValidationErrorType.Error, UsdValidation.ValidationErrorType.Warn)
    return [e.GetMessage() for e in errors if e.GetType() in kinds]


@pytest.mark.parametrize("mode", ["points", "blendshapes"])
def test_usdz_package(tmp_path, grid_mesh, mode):
    anim = rich_animation(grid_mesh)
    out = tmp_path / "clip.usdz"
    assert write_animation(anim, out, mode=mode) == [out]
    assert [p.name for p in tmp_path.iterdir()] == ["clip.usdz"]  # self-contained: no sidecar, no temp files

    # an uncompressed zip: the crate stage first, then its WAV, each 64-byte aligned (USDZ spec)
    assert contents(out) == ["clip.usdc", "clip.wav"]
    with zipfile.ZipFile(out) as package:
        assert [i.filename for i in package.infolist()] == ["clip.usdc", "clip.wav"]
        assert all(i.compress_type == zipfile.ZIP_STORED for i in package.infolist())
        assert package.read("clip.usdc")[:8] == b"PXR-USDC"
        wav = package.read("clip.wav")
    info = Sdf.ZipFile.Open(str(out)).GetFileInfo("clip.wav")
    assert info.dataOffset % 64 == 0
    samples, rate = sf.read(io.BytesIO(wav), dtype="float32")
    assert rate == SR and len(samples) == len(anim.audio)
    np.testing.assert_allclose(samples, anim.audio, atol=1.0 / 32767)

    # the audio path is relative and resolves inside the package, readable through USD's resolver
    stage = Usd.Stage.Open(str(out))
    sound = UsdMedia.SpatialAudio(stage.GetPrimAtPath("/Face/Audio"))
    asset = sound.GetFilePathAttr().Get()
    assert asset.path == "./clip.wav"
    assert Ar.IsPackageRelativePath(asset.resolvedPath)
    outer, inner = Ar.SplitPackageRelativePathOuter(asset.resolvedPath)
    assert (outer, inner) == (str(out), "clip.wav")
    assert bytes(Ar.GetResolver().OpenAsset(Ar.ResolvedPath(asset.resolvedPath)).GetBuffer()) == wav
    assert stage.GetTimeCodesPerSecond() == FPS and stage.GetEndTimeCode() == anim.num_frames - 1
    assert stage.GetRootLayer().customLayerData["facegen"]["mode"] == mode

    # reopens as the animation (exact for points, within the stated error for blendshapes)
    back = read_animation(out)
    assert back.fps == FPS and back.sample_rate == SR and back.metadata["speaker"] == "F2"
    np.testing.assert_allclose(back.audio, anim.audio, atol=1.0 / 32767)
    np.testing.assert_array_equal(back.faces, grid_mesh.faces)
    if mode == "points":
        np.testing.assert_array_equal(back.vertices, anim.vertices)
        points = UsdGeom.Mesh(stage.GetPrimAtPath("/Face/Mesh")).GetPointsAttr()
        assert points.GetNumTimeSamples() == anim.num_frames
    else:
        stated = stage.GetRootLayer().customLayerData["facegen"]["reconstruction"]["max_error"]
        assert stated <= DEFAULT_TOLERANCE * grid_mesh.size
        assert max_distance(back.vertices, anim.vertices) <= stated + 1e-6 * grid_mesh.size
        assert max_distance(usdskel_points(stage, 30.0), anim.vertices[30]) <= stated + 1e-6 * grid_mesh.size

    # validates: facegen's checks, the package check, every pxr validator (usdz ones included)
    report = validate(out, template=grid_mesh, fps=FPS)
    assert report.ok and report.warnings == [], report.to_text()
    assert report.check("package").detail == "holds clip.usdc, clip.wav"
    assert report.check("audio").ok and "2.400 s at 16000 Hz" in report.check("audio").detail
    assert report.check("usd validators").ok
    assert usdz_findings(out) == []


def test_usdz_options_and_registry(tmp_path, grid_mesh):
    anim = make_animation(grid_mesh, frames=10)
    assert ".usdz" in extensions()
    out = tmp_path / "k.usdz"
    write_animation(anim, out, mode="blendshapes", morph_targets=2, meters_per_unit=0.01)
    stage = Usd.Stage.Open(str(out))
    assert stage.GetRootLayer().customLayerData["facegen"]["reconstruction"]["targets"] == 3  # 2 + rest
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.01)
    with pytest.raises(FacegenError, match="blendshapes only"):
        write_animation(anim, tmp_path / "x.usdz", tolerance=1e-3)
    with pytest.raises(FacegenError, match="does not apply to .usdz"):
        write_animation(anim, tmp_path / "x.usdz", fps=30)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["k.usdz"]


def test_usdz_without_audio(tmp_path, grid_mesh):
    anim = make_animation(grid_mesh, frames=10)
    out = tmp_path / "mute.usdz"
    assert write_animation(anim, out, write_audio=False) == [out]
    assert contents(out) == ["mute.usdc"]
    assert read_animation(out).audio is None
    assert validate(out, require_audio=False).ok
    assert {c.name for c in validate(out).failures} == {"audio", "audio duration"}


def test_input_audio_beside_the_package_is_untouched(tmp_path, grid_mesh):
    source = tmp_path / "clip.wav"
    sf.write(str(source), np.zeros(4800, np.float32), 48000)
    before = source.read_bytes()
    anim = make_animation(grid_mesh, frames=10)
    assert write_animation(anim, tmp_path / "clip.usdz", audio_source=source) == [tmp_path / "clip.usdz"]
    assert source.read_bytes() == before
    assert contents(tmp_path / "clip.usdz") == ["clip.usdc", "clip.wav"]
    assert len(read_animation(tmp_path / "clip.usdz").audio) == len(anim.audio)  # the animation's audio


@pytest.mark.parametrize("exc", [RuntimeError("disk on fire"), KeyboardInterrupt()])
def test_failed_write_leaves_nothing(tmp_path, grid_mesh, exc):
    anim = make_animation(grid_mesh, frames=10)
    anim.metadata = {Boom(exc): 1}
    with pytest.raises(type(exc)):
        write_animation(anim, tmp_path / "out.usdz")
    assert list(tmp_path.iterdir()) == []  # no package, no staging folder
    write_animation(make_animation(grid_mesh, frames=12), tmp_path / "out.usdz")
    before = (tmp_path / "out.usdz").read_bytes()
    with pytest.raises(type(exc)):
        write_animation(anim, tmp_path / "out.usdz", mode="blendshapes")
    assert [p.name for p in tmp_path.iterdir()] == ["out.usdz"]
    assert (tmp_path / "out.usdz").read_bytes() == before


def test_rewrite_same_path_is_reread(tmp_path, grid_mesh):
    """pxr caches layers and zip files by path: a package rewritten in one process must be read anew."""
    out = tmp_path / "same.usdz"
    write_animation(make_animation(grid_mesh, frames=10), out)
    held = Usd.Stage.Open(str(out))
    assert len(read_animation(out).audio) == round(10 / FPS * SR)
    write_animation(make_animation(grid_mesh, frames=15), out, mode="blendshapes")
    back = read_animation(out)
    assert back.num_frames == 15 and len(back.audio) == round(15 / FPS * SR)
    assert validate(out).ok
    del held


def test_package_problems_are_reported(tmp_path, grid_mesh):
    # audio that resolves beside the package instead of inside it
    write_animation(make_animation(grid_mesh, frames=10), tmp_path / "loose.usdc")
    layer = Sdf.Layer.FindOrOpen(str(tmp_path / "loose.usdc"))
    layer.GetAttributeAtPath("/Face/Audio.filePath").default = Sdf.AssetPath(str(tmp_path / "loose.wav"))
    assert layer.Save()
    writer = Sdf.ZipFileWriter.CreateNew(str(tmp_path / "loose.usdz"))
    writer.AddFile(str(tmp_path / "loose.usdc"), "loose.usdc")
    writer.Save()
    report = validate(tmp_path / "loose.usdz")
    assert "package" in {c.name for c in report.failures}
    assert "does not resolve inside the package" in report.check("package").detail
    assert usdz_findings(tmp_path / "loose.usdz") != []  # pxr agrees: the package is not self-contained

    # not a zip at all
    (tmp_path / "junk.usdz").write_bytes(b"PK\x03\x04 not really" * 20)
    report = validate(tmp_path / "junk.usdz")
    assert not report.ok and report.failures[0].name == "file"


def test_biwi_usdz(tmp_path, biwi_template):
    anim = rich_animation(biwi_template, frames=40)
    for mode in ("points", "blendshapes"):
        out = tmp_path / f"biwi_{mode}.usdz"
        write_animation(anim, out, mode=mode)
        report = validate(out, template=biwi_template, fps=FPS)
        assert report.ok and report.warnings == [], report.to_text()
        assert report.check("vertex count").detail.startswith("23370 vertices per frame")
        assert usdz_findings(out) == []
        back = read_animation(out, template=biwi_template)
        assert back.vertices.shape == (40, 23370, 3)
        bound = 0.0 if mode == "points" else DEFAULT_TOLERANCE * biwi_template.size
        assert max_distance(back.vertices, anim.vertices) <= bound + 1e-6 * biwi_template.size
    sizes = {mode: (tmp_path / f"biwi_{mode}.usdz").stat().st_size for mode in ("points", "blendshapes")}
    assert sizes["blendshapes"] < sizes["points"]
