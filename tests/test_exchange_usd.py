"""facegen.exchange: USD and .npy writers/readers, the WAV sidecar, atomic writes, a minute-long clip."""

from __future__ import annotations

import importlib
import inspect
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from helpers import FPS, SR, Boom, make_animation
from pxr import Sdf, Usd, UsdGeom, UsdMedia

from facegen import __version__
from facegen.animation import Animation
from facegen.errors import FacegenError
from facegen.exchange import extensions, format_of, read_animation, write_animation
from facegen.exchange.formats import COMMON_OPTIONS, FORMATS
from facegen.exchange.usd import DEFAULT_METERS_PER_UNIT
from facegen.face.mesh import Mesh


def stage_points(path: Path) -> tuple[Usd.Stage, UsdGeom.Mesh, list[float], np.ndarray]:
    stage = Usd.Stage.Open(str(path))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Face/Mesh"))
    attr = mesh.GetPointsAttr()
    times = list(attr.GetTimeSamples())
    return stage, mesh, times, np.stack([np.asarray(attr.Get(t)) for t in times])


@pytest.mark.parametrize("ext", [".usda", ".usdc", ".usd"])
def test_usd_file_contents(tmp_path, grid_mesh, ext):
    anim = make_animation(grid_mesh)
    out = tmp_path / f"clip{ext}"
    written = write_animation(anim, out)
    assert written == [out, tmp_path / "clip.wav"]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["clip.wav", f"clip{ext}"])  # no temp files
    head = out.read_bytes()[:8]
    assert head == (b"#usda 1." if ext == ".usda" else b"PXR-USDC")

    stage, mesh, times, points = stage_points(out)
    layer = stage.GetRootLayer()
    assert stage.GetTimeCodesPerSecond() == FPS and stage.GetFramesPerSecond() == FPS
    assert layer.HasTimeCodesPerSecond() and layer.HasFramesPerSecond()
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0.0, 49.0)
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(DEFAULT_METERS_PER_UNIT)
    assert stage.GetDefaultPrim().GetPath() == Sdf.Path("/Face")
    assert Usd.ModelAPI(stage.GetDefaultPrim()).GetKind() == "component"

    # topology: triangles, the template's face list, no subdivision
    assert list(mesh.GetFaceVertexCountsAttr().Get()) == [3] * len(grid_mesh.faces)
    np.testing.assert_array_equal(np.asarray(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3),
                                  grid_mesh.faces)
    assert mesh.GetSubdivisionSchemeAttr().Get() == UsdGeom.Tokens.none
    assert mesh.GetOrientationAttr().Get() == UsdGeom.Tokens.rightHanded

    # one sample per frame at 0..T-1, values exactly the float32 input; rest pose as the default value
    assert times == [float(i) for i in range(50)]
    assert points.dtype == np.float32 and points.shape == (50, grid_mesh.num_vertices, 3)
    np.testing.assert_array_equal(points, anim.vertices)
    np.testing.assert_array_equal(np.asarray(mesh.GetPointsAttr().Get(Usd.TimeCode.Default())),
                                  grid_mesh.vertices)
    extent = mesh.GetExtentAttr()
    assert list(extent.GetTimeSamples()) == times
    for i in (0, 17, 49):
        np.testing.assert_array_equal(
            np.asarray(extent.Get(i)), np.stack([anim.vertices[i].min(0), anim.vertices[i].max(0)])
        )

    # audio: a relative asset path that resolves to the sidecar, played once from 0, not spatialised
    sound = UsdMedia.SpatialAudio(stage.GetPrimAtPath("/Face/Audio"))
    asset = sound.GetFilePathAttr().Get()
    assert asset.path == "./clip.wav"
    assert Path(asset.resolvedPath) == (tmp_path / "clip.wav").resolve()
    assert sound.GetAuralModeAttr().Get() == UsdMedia.Tokens.nonSpatial
    assert sound.GetPlaybackModeAttr().Get() == UsdMedia.Tokens.onceFromStart
    assert sound.GetStartTimeAttr().Get() == 0
    info = sf.info(str(tmp_path / "clip.wav"))
    assert (info.channels, info.samplerate, info.subtype, info.frames) == (1, SR, "PCM_16", len(anim.audio))
    assert info.duration == pytest.approx(50 / FPS)
    wav, _ = sf.read(str(tmp_path / "clip.wav"), dtype="float32")
    np.testing.assert_allclose(wav, anim.audio, atol=1.0 / 32767)

    data = layer.customLayerData["facegen"]
    assert data["version"] == __version__ and data["fps"] == FPS and data["frames"] == 50
    meta = data["metadata"]
    assert (meta["model"] == "unit-test.safetensors" and meta["frames"] == 50
            and list(meta["tags"]) == ["a", "b"])
    assert "gone" not in meta and '"word": "hi"' in meta["words"]


@pytest.mark.parametrize(("name", "mode"), [("p.usda", "points"), ("b.usdc", "blendshapes"),
                                            ("z.usdz", "points"),
                                           ("zb.usdz", "blendshapes")])
def test_uvs_display_colour_and_skin_material(tmp_path, grid_mesh, name, mode):
    from pxr import UsdShade

    from facegen.exchange.surface import SKIN_COLOR, face_uvs
    from facegen.validate import validate

    anim = make_animation(grid_mesh)
    out = tmp_path / name
    write_animation(anim, out, mode=mode)
    stage = Usd.Stage.Open(str(out))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Face/Mesh"))
    st = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("st")
    assert (st.GetTypeName() == Sdf.ValueTypeNames.TexCoord2fArray
            and st.GetInterpolation() == UsdGeom.Tokens.vertex)
    uv = np.asarray(st.Get(), np.float32)
    assert uv.shape == (grid_mesh.num_vertices, 2) and uv.min() == 0.0 and uv.max() == 1.0
    assert np.array_equal(uv, face_uvs(grid_mesh.vertices))
    top, left = np.argmax(grid_mesh.vertices[:, 1]), np.argmin(grid_mesh.vertices[:, 0])
    assert uv[top, 1] == 1.0 and uv[left, 0] < 0.5  # USD's v runs up
    colour = mesh.GetDisplayColorPrimvar()
    assert colour.GetInterpolation() == UsdGeom.Tokens.constant
    assert np.allclose(np.asarray(colour.Get()), [SKIN_COLOR])
    assert mesh.GetPrim().HasAPI(UsdShade.MaterialBindingAPI)
    material, _ = UsdShade.MaterialBindingAPI(mesh.GetPrim()).ComputeBoundMaterial()
    assert material and material.GetPath() == Sdf.Path("/Face/Looks/Skin")
    shader = material.ComputeSurfaceSource()[0]
    assert shader.GetIdAttr().Get() == "UsdPreviewSurface"
    assert np.allclose(shader.GetInput("diffuseColor").Get(), SKIN_COLOR)
    assert (shader.GetInput("metallic").Get() == 0.0
            and shader.GetInput("roughness").Get() == pytest.approx(0.6))
    report = validate(out)
    assert report.ok and "no findings" in report.check("usd validators").detail, report.to_text()


def test_usd_round_trip(tmp_path, grid_mesh):
    anim = make_animation(grid_mesh, frames=30, fps=30.0)
    write_animation(anim, tmp_path / "a.usdc", meters_per_unit=0.01)
    back = read_animation(tmp_path / "a.usdc")
    np.testing.assert_array_equal(back.vertices, anim.vertices)
    np.testing.assert_array_equal(back.faces, grid_mesh.faces)
    np.testing.assert_array_equal(back.template, grid_mesh.vertices)
    assert back.fps == 30.0 and back.sample_rate == SR
    np.testing.assert_allclose(back.audio, anim.audio, atol=1.0 / 32767)
    assert back.metadata["speaker"] == "F2" and back.metadata["tags"] == ["a", "b"]
    assert UsdGeom.GetStageMetersPerUnit(Usd.Stage.Open(str(tmp_path / "a.usdc"))) == pytest.approx(0.01)
    # with a template: topology is checked; a contradicting fps is refused
    assert read_animation(tmp_path / "a.usdc", template=grid_mesh, fps=30.0).num_frames == 30
    with pytest.raises(FacegenError, match="30 fps but 25 fps"):
        read_animation(tmp_path / "a.usdc", fps=25.0)
    other = Mesh(grid_mesh.vertices[:-1], grid_mesh.faces[:-20])
    with pytest.raises(FacegenError, match="vertices"):
        read_animation(tmp_path / "a.usdc", template=other)


def test_npy_layout_and_round_trip(tmp_path, grid_mesh):
    anim = make_animation(grid_mesh, frames=40)
    written = write_animation(anim, tmp_path / "b.npy")
    assert written == [tmp_path / "b.npy", tmp_path / "b.wav"]
    data = np.load(tmp_path / "b.npy")
    assert data.dtype == np.float32 and data.shape == (40, 3 * grid_mesh.num_vertices)
    np.testing.assert_array_equal(data[7, 3:6], anim.vertices[7, 1])  # x y z of vertex 1, frame 7
    np.testing.assert_array_equal(data.reshape(40, -1, 3), anim.vertices)
    assert sf.info(str(tmp_path / "b.wav")).frames == len(anim.audio)

    back = read_animation(tmp_path / "b.npy", template=grid_mesh)
    np.testing.assert_array_equal(back.vertices, anim.vertices)
    np.testing.assert_array_equal(back.faces, grid_mesh.faces)
    assert back.fps == 25.0 and back.audio is not None and len(back.audio) == len(anim.audio)
    assert read_animation(tmp_path / "b.npy", template=grid_mesh, fps=30).fps == 30.0
    with pytest.raises(FacegenError, match="template"):
        read_animation(tmp_path / "b.npy")
    small = Mesh(grid_mesh.vertices[:10], grid_mesh.faces[:2])
    with pytest.raises(FacegenError, match="has 10"):
        read_animation(tmp_path / "b.npy", template=small)


class Blocks:
    """A stand-in for inference.FrameStream: frames only through blocks(n), never as one array."""

    def __init__(self, frames: np.ndarray) -> None:
        self.frames, self.shape, self.calls = frames, frames.shape, []

    def blocks(self, block_frames=None, ahead=False):
        self.calls.append((block_frames, ahead))
        for start in range(0, len(self.frames), block_frames or 7):
            yield start, self.frames[start : start + (block_frames or 7)].copy()


@pytest.mark.parametrize("ext", [".npy", ".usdc"])
def test_streamed_frames_are_written_block_by_block(tmp_path, grid_mesh, ext):
    anim = make_animation(grid_mesh, frames=30)
    stream = Blocks(anim.vertices)
    streamed = Animation(stream, anim.faces, anim.fps, anim.template, anim.audio, anim.sample_rate)
    assert streamed.streamed and not anim.streamed and format_of(tmp_path / f"a{ext}").streams_with({})
    write_animation(anim, tmp_path / f"a{ext}", write_audio=False)
    write_animation(streamed, tmp_path / f"b{ext}", write_audio=False)
    assert stream.calls == ([(None, False)] if ext == ".npy" else [(256, True)])  # .usdc: next block ahead
    if ext == ".npy":  # the header np.save writes, then the blocks: the same bytes
        assert (tmp_path / "a.npy").read_bytes() == (tmp_path / "b.npy").read_bytes()
        buffer = tmp_path / "c.npy"
        np.save(buffer, anim.vertices.reshape(30, -1), allow_pickle=False)
        assert buffer.read_bytes() == (tmp_path / "a.npy").read_bytes()
    else:
        np.testing.assert_array_equal(read_animation(tmp_path / "b.usdc").vertices, anim.vertices)
    assert [s for s, _ in streamed.frame_blocks(8)] == [s for s, _ in anim.frame_blocks(8)] == [0, 8, 16, 24]


def test_format_table():
    assert extensions() == [ext for f in FORMATS for ext in f.extensions]
    assert len(set(extensions())) == len(extensions())
    for fmt in FORMATS:
        module = importlib.import_module(fmt.module)
        params = inspect.signature(module.write).parameters
        keywords = [n for n, p in params.items() if p.kind is p.KEYWORD_ONLY]
        if any(p.kind is p.VAR_KEYWORD for p in params.values()):  # usdz: the USD writer's options, passed on
            keywords += list(format_of("x.usdc").options)
        assert sorted(keywords) == sorted(fmt.options + COMMON_OPTIONS), fmt.name
        assert callable(importlib.import_module(fmt.validator).check)
    assert format_of("x.usdc").streams_with({"mode": "points"})
    assert not format_of("x.usdc").streams_with({"mode": "blendshapes"})
    assert not format_of("x.GLB").streams_with({}) and not format_of("x.usdz").streams_with({})


def test_the_table_imports_no_format_module():
    code = ("import sys, facegen.cli, facegen.exchange\n"
            "print(sorted(m for m in ('numpy', 'pxr', 'pygltflib') if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"


def test_no_audio_no_sidecar(tmp_path, grid_mesh):
    anim = make_animation(grid_mesh, frames=5)
    assert write_animation(anim, tmp_path / "c.usda", write_audio=False) == [tmp_path / "c.usda"]
    anim.audio = None
    assert write_animation(anim, tmp_path / "d.npy") == [tmp_path / "d.npy"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.usda", "d.npy"]
    stage = Usd.Stage.Open(str(tmp_path / "c.usda"))
    assert not stage.GetPrimAtPath("/Face/Audio")
    assert read_animation(tmp_path / "c.usda").audio is None


def test_input_audio_beside_the_output_is_kept(tmp_path, grid_mesh):
    """`facegen animate clip.wav -o clip.usda`: the sidecar is the input itself; it must not be rewritten."""
    source = tmp_path / "clip.wav"
    stereo = np.stack([np.linspace(-0.5, 0.5, 96000)] * 2, axis=1)
    sf.write(str(source), stereo, 48000, subtype="FLOAT")
    before = source.read_bytes()
    anim = make_animation(grid_mesh, frames=50)
    written = write_animation(anim, tmp_path / "clip.usda", audio_source=source)
    assert written == [tmp_path / "clip.usda", source]
    assert source.read_bytes() == before
    back = read_animation(tmp_path / "clip.usda")
    assert back.sample_rate == 48000 and len(back.audio) == 96000


def test_unknown_extension_and_option(tmp_path, grid_mesh):
    anim = make_animation(grid_mesh, frames=3)
    with pytest.raises(FacegenError) as err:
        write_animation(anim, tmp_path / "x.fbx")
    message = str(err.value)
    assert "'.fbx'" in message and all(ext in message for ext in (".usda", ".usdc", ".usd", ".npy"))
    assert extensions()[:4] == [".usda", ".usdc", ".usd", ".npy"]
    with pytest.raises(FacegenError, match="meters_per_unit"):
        write_animation(anim, tmp_path / "x.npy", meters_per_unit=1.0)
    with pytest.raises(FacegenError, match="positive"):
        write_animation(anim, tmp_path / "x.usda", meters_per_unit=0)
    assert list(tmp_path.iterdir()) == []


def test_bad_animations_are_refused(tmp_path, grid_mesh):
    anim = make_animation(grid_mesh, frames=3)
    bad_faces = Animation(anim.vertices, anim.faces + 1000, FPS, anim.template)
    with pytest.raises(FacegenError, match="outside"):
        write_animation(bad_faces, tmp_path / "x.usda")
    with pytest.raises(FacegenError, match="fps"):
        write_animation(Animation(anim.vertices, anim.faces, 0.0, anim.template), tmp_path / "x.usda")
    with pytest.raises(FacegenError, match=r"\[T, V, 3\]"):
        write_animation(Animation(anim.vertices[:0], anim.faces, FPS, anim.template), tmp_path / "x.npy")
    assert list(tmp_path.iterdir()) == []




@pytest.mark.parametrize("exc", [RuntimeError("disk on fire"), KeyboardInterrupt()])
@pytest.mark.parametrize("ext", [".usda", ".usdc"])
def test_failed_write_leaves_nothing(tmp_path, grid_mesh, exc, ext):
    anim = make_animation(grid_mesh, frames=10)
    anim.metadata = {Boom(exc): 1}
    with pytest.raises(type(exc)):
        write_animation(anim, tmp_path / f"out{ext}")
    assert list(tmp_path.iterdir()) == []  # neither the asset, nor the sidecar, nor temp files


def test_failed_write_keeps_previous_files(tmp_path, grid_mesh):
    good = make_animation(grid_mesh, frames=10)
    write_animation(good, tmp_path / "out.usdc")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    bad = make_animation(grid_mesh, frames=20)
    bad.metadata = {Boom(RuntimeError("no")): 1}
    with pytest.raises(RuntimeError):
        write_animation(bad, tmp_path / "out.usdc")
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    assert read_animation(tmp_path / "out.usdc").num_frames == 10


def test_rewrite_same_path_is_reread(tmp_path, grid_mesh):
    """pxr caches open layers by path: reading after rewriting in one process must see the new file."""
    out = tmp_path / "same.usda"
    write_animation(make_animation(grid_mesh, frames=10), out)
    held = Usd.Stage.Open(str(out))  # keeps the old layer alive in pxr's registry
    write_animation(make_animation(grid_mesh, frames=12), out)
    assert read_animation(out).num_frames == 12
    del held


def test_biwi_template_usd(tmp_path, biwi_template):
    anim = make_animation(biwi_template, frames=50)
    write_animation(anim, tmp_path / "biwi.usdc")
    _, mesh, times, points = stage_points(tmp_path / "biwi.usdc")
    assert points.shape == (50, 23370, 3) and times == [float(i) for i in range(50)]
    np.testing.assert_array_equal(points, anim.vertices)
    faces = np.asarray(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
    assert faces.shape == (46068, 3)
    np.testing.assert_array_equal(faces, biwi_template.faces)
    # rightHanded winding: the area-weighted normals of the face point out of it (+Z, toward the viewer)
    v = points[0].astype(np.float64)
    normals = np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])
    total = normals.sum(0)
    assert total[2] > 0.9 * np.linalg.norm(total)
    back = read_animation(tmp_path / "biwi.usdc", template=biwi_template)
    np.testing.assert_array_equal(back.vertices, anim.vertices)


def test_usdc_writes_a_minute(tmp_path, request):
    """1500 frames x 23,370 vertices (a minute at 25 fps): every frame is a time sample with its values (the
    write speed is measured by benchmarks/bench_export.py --usdc-throughput)."""
    try:
        mesh = request.getfixturevalue("biwi_template")
    except pytest.skip.Exception:
        rng = np.random.default_rng(0)
        mesh = Mesh(rng.standard_normal((23370, 3)).astype(np.float32),
                    rng.integers(0, 23370, (46068, 3)).astype(np.int32))
    frames = 1500
    rng = np.random.default_rng(1)
    noise = (0.002 * rng.standard_normal((frames, 1, 3))).astype(np.float32)
    anim = Animation(mesh.vertices[None] + noise + 0.001 * np.arange(frames, dtype=np.float32)[:, None, None],
                     mesh.faces, FPS, mesh.vertices, np.zeros(frames * SR // 25, np.float32), SR)
    out = tmp_path / "long.usdc"
    write_animation(anim, out)
    stage = Usd.Stage.Open(str(out))
    points = UsdGeom.Mesh(stage.GetPrimAtPath("/Face/Mesh")).GetPointsAttr()
    assert points.GetNumTimeSamples() == frames
    for frame in (0, 1234, frames - 1):
        np.testing.assert_array_equal(np.asarray(points.Get(frame)), anim.vertices[frame])


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_vec3f_array_holds_the_points_as_from_numpy_does(dtype):
    from pxr import Vt

    from facegen.exchange.usd_values import vec3f_array

    points = np.random.default_rng(3).normal(size=(23370, 3)).astype(dtype)
    fast = vec3f_array(points[::-1])  # not contiguous: copied first
    assert isinstance(fast, Vt.Vec3fArray) and len(fast) == 23370
    np.testing.assert_array_equal(np.asarray(fast), np.asarray(Vt.Vec3fArray.FromNumpy(
        np.ascontiguousarray(points[::-1], np.float32))))
    assert tuple(fast[0]) == tuple(points[-1].astype(np.float32).tolist())
    again = vec3f_array(points[:2] + 1)  # a new array each time: the first keeps its values
    assert len(again) == 2 and tuple(fast[0]) == tuple(points[-1].astype(np.float32).tolist())
    assert len(vec3f_array(np.zeros((0, 3)))) == 0
