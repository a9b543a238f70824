"""USD blendshapes mode (facegen.exchange.usd_skel): UsdSkel layout, UsdSkel's own evaluation vs the source,
the stated reconstruction error, read-back, validation, atomic writes."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import (
    FPS,
    Boom,
    make_animation,
    max_distance,
    rich_animation,
    static_vertices,
    usdskel_points,
)
from pxr import Gf, Sdf, Usd, UsdGeom, UsdMedia, UsdSkel, Vt

from facegen import __version__
from facegen.errors import FacegenError
from facegen.exchange import read_animation, write_animation
from facegen.exchange.pca import DEFAULT_TOLERANCE, MAX_FRAME_TARGETS
from facegen.exchange.usd import DEFAULT_METERS_PER_UNIT
from facegen.validate import validate

FRAMES = 60
WEIGHTS = Sdf.Path("/Face/Skeleton/Animation.blendShapeWeights")


def test_blendshapes_layout(tmp_path, grid_mesh):
    anim = rich_animation(grid_mesh)
    out = tmp_path / "clip.usda"
    assert write_animation(anim, out, mode="blendshapes") == [out, tmp_path / "clip.wav"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clip.usda", "clip.wav"]  # no temp files
    stage = Usd.Stage.Open(str(out))
    layer = stage.GetRootLayer()

    # stage metadata as points mode
    assert stage.GetTimeCodesPerSecond() == FPS and stage.GetFramesPerSecond() == FPS
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0.0, FRAMES - 1.0)
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(DEFAULT_METERS_PER_UNIT)
    root = stage.GetDefaultPrim()
    assert root.GetPath() == Sdf.Path("/Face") and root.IsA(UsdSkel.Root)
    assert Usd.ModelAPI(root).GetKind() == "component"

    # the skeleton: one root joint, identity bind/rest, its animation source
    skeleton = UsdSkel.Skeleton(stage.GetPrimAtPath("/Face/Skeleton"))
    assert list(skeleton.GetJointsAttr().Get()) == ["root"]
    assert list(skeleton.GetBindTransformsAttr().Get()) == [Gf.Matrix4d(1)]
    assert list(skeleton.GetRestTransformsAttr().Get()) == [Gf.Matrix4d(1)]
    assert skeleton.GetPrim().HasAPI(UsdSkel.BindingAPI)
    source = UsdSkel.BindingAPI(skeleton.GetPrim()).GetAnimationSourceRel().GetTargets()
    assert source == [Sdf.Path("/Face/Skeleton/Animation")]

    # the mesh: template points (no samples), bound to the skeleton and its blend shapes
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Face/Mesh"))
    assert mesh.GetPointsAttr().GetNumTimeSamples() == 0
    np.testing.assert_array_equal(np.asarray(mesh.GetPointsAttr().Get()), grid_mesh.vertices)
    faces = np.asarray(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
    np.testing.assert_array_equal(faces, grid_mesh.faces)
    binding = UsdSkel.BindingAPI(mesh.GetPrim())
    assert mesh.GetPrim().HasAPI(UsdSkel.BindingAPI)
    assert binding.GetSkeletonRel().GetTargets() == [Sdf.Path("/Face/Skeleton")]
    names = list(binding.GetBlendShapesAttr().Get())
    assert binding.GetBlendShapeTargetsRel().GetTargets() == [Sdf.Path(f"/Face/Mesh/{n}") for n in names]
    indices, weights = binding.GetJointIndicesPrimvar(), binding.GetJointWeightsPrimvar()
    assert list(indices.Get()) == [0] and list(weights.Get()) == [1.0]
    assert indices.GetInterpolation() == weights.GetInterpolation() == UsdGeom.Tokens.constant
    assert indices.GetElementSize() == weights.GetElementSize() == 1
    assert binding.GetGeomBindTransformAttr().Get() == Gf.Matrix4d(1)

    # PCA targets plus the constant `rest` target; the static rows are left out of every target
    assert names[-1] == "rest" and all(n.startswith("pca_") for n in names[:-1]) and len(names) >= 4
    static = static_vertices(grid_mesh)
    assert len(static) == 36  # the top three rows of the grid
    for name in names:
        shape = UsdSkel.BlendShape(stage.GetPrimAtPath(f"/Face/Mesh/{name}"))
        point_indices = np.asarray(shape.GetPointIndicesAttr().Get())
        assert 0 < len(point_indices) <= grid_mesh.num_vertices - len(static)
        assert not np.isin(static, point_indices).any()
        assert (np.diff(point_indices) > 0).all()
        offsets = np.asarray(shape.GetOffsetsAttr().Get())
        assert len(offsets) == len(point_indices) and (np.abs(offsets).max(1) > 0).all()

    # the animation: the same names, one weight sample per frame at 0..T-1, weights in [0, 1], rest = 1
    animation = UsdSkel.Animation(stage.GetPrimAtPath("/Face/Skeleton/Animation"))
    assert list(animation.GetBlendShapesAttr().Get()) == names
    attr = animation.GetBlendShapeWeightsAttr()
    assert list(attr.GetTimeSamples()) == [float(i) for i in range(FRAMES)]
    samples = np.stack([np.asarray(attr.Get(t)) for t in attr.GetTimeSamples()])
    assert samples.shape == (FRAMES, len(names)) and samples.dtype == np.float32
    assert samples.min() >= 0.0 and samples.max() <= 1.0
    np.testing.assert_array_equal(samples[:, -1], 1.0)
    assert (samples[:, :-1].min(0) == 0).all() and (samples[:, :-1].max(0) == 1).all()  # each spans 0..1

    # audio as in points mode
    sound = UsdMedia.SpatialAudio(stage.GetPrimAtPath("/Face/Audio"))
    assert sound.GetFilePathAttr().Get().path == "./clip.wav"
    assert sound.GetPlaybackModeAttr().Get() == UsdMedia.Tokens.onceFromStart

    # the stated reconstruction error: within the default tolerance of the face size
    data = layer.customLayerData["facegen"]
    assert data["mode"] == "blendshapes" and data["version"] == __version__ and data["frames"] == FRAMES
    info = data["reconstruction"]
    assert info["targets"] == len(names) and info["tolerance"] == DEFAULT_TOLERANCE
    assert info["size"] == pytest.approx(grid_mesh.size)
    assert 0 < info["max_error"] <= DEFAULT_TOLERANCE * grid_mesh.size
    assert info["relative_error"] == pytest.approx(info["max_error"] / grid_mesh.size)


def test_extents_bound_every_frame(tmp_path, grid_mesh):
    """The mesh's and the SkelRoot's extent: a sample per frame bounding UsdSkel's evaluation of that frame
    (tightly), and a default value bounding every frame (the jaw leaves the template's box)."""
    anim = rich_animation(grid_mesh)
    out = tmp_path / "box.usdc"
    write_animation(anim, out, mode="blendshapes", write_audio=False)
    stage = Usd.Stage.Open(str(out))
    mesh, root = UsdGeom.Mesh(stage.GetPrimAtPath("/Face/Mesh")), UsdSkel.Root(stage.GetPrimAtPath("/Face"))
    template_box = np.stack([anim.template.min(0), anim.template.max(0)])
    default = np.asarray(mesh.GetExtentAttr().Get(Usd.TimeCode.Default()), np.float64)
    assert np.array_equal(default, np.asarray(root.GetExtentAttr().Get(Usd.TimeCode.Default())))
    outside = 0
    for t in range(FRAMES):
        points = usdskel_points(stage, float(t)).astype(np.float64)
        for boundable in (mesh, root):
            box = np.asarray(boundable.GetExtentAttr().Get(float(t)), np.float64)
            assert box.shape == (2, 3) and (box[0] <= box[1]).all()
            slack = 1e-6 * anim.size
            assert (points >= box[0] - slack).all() and (points <= box[1] + slack).all(), t
            assert np.allclose(box, [points.min(0), points.max(0)], atol=1e-5 * anim.size)  # tight
        assert (points >= default[0] - 1e-6).all() and (points <= default[1] + 1e-6).all()
        outside += int(((points < template_box[0]) | (points > template_box[1])).any())
    assert outside > 0  # the frames do leave the template's box: its extent alone would not bound them
    assert list(mesh.GetExtentAttr().GetTimeSamples()) == list(root.GetExtentAttr().GetTimeSamples())
    assert validate(out, require_audio=False).check("time samples").ok
    # an extent of the template only (what the writer stated before) fails validate's time samples check
    mesh.GetExtentAttr().Clear()  # its default and every time sample
    mesh.GetExtentAttr().Set(Vt.Vec3fArray.FromNumpy(template_box.astype(np.float32)))
    stage.GetRootLayer().Save()
    check = validate(out, require_audio=False).check("time samples")
    assert not check.ok and "does not bound the blended points" in check.detail


@pytest.mark.parametrize("ext", [".usda", ".usdc"])
def test_usdskel_evaluation_equals_the_source(tmp_path, grid_mesh, ext):
    anim = rich_animation(grid_mesh)
    out = tmp_path / f"clip{ext}"
    write_animation(anim, out, mode="blendshapes")
    stage = Usd.Stage.Open(str(out))
    stated = stage.GetRootLayer().customLayerData["facegen"]["reconstruction"]["max_error"]
    bound = DEFAULT_TOLERANCE * grid_mesh.size
    rounding = 1e-6 * grid_mesh.size  # float32 sums in a different order than the writer's measurement
    errors = []
    for frame in (0, FRAMES // 2, FRAMES - 1):
        points = usdskel_points(stage, float(frame))
        errors.append(max_distance(points, anim.vertices[frame]))
    assert max(errors) <= stated + rounding and max(errors) <= bound + rounding
    assert max(errors) > 0  # a real approximation: K < T

    # facegen's reader blends the same shapes: equal to UsdSkel's evaluation and to the source
    back = read_animation(out)
    assert back.vertices.shape == anim.vertices.shape and back.fps == FPS
    assert max_distance(back.vertices[FRAMES // 2], usdskel_points(stage, FRAMES // 2)) <= rounding
    assert max_distance(back.vertices, anim.vertices) <= stated + rounding
    np.testing.assert_array_equal(back.template, grid_mesh.vertices)
    np.testing.assert_array_equal(back.faces, grid_mesh.faces)
    assert back.metadata["speaker"] == "F2"
    np.testing.assert_allclose(back.audio, anim.audio, atol=1.0 / 32767)


def test_tolerance_sets_the_number_of_targets(tmp_path, grid_mesh):
    anim = rich_animation(grid_mesh)
    counts = []
    for tolerance in (3e-2, 3e-3, 1e-4):
        out = tmp_path / f"t{tolerance:g}.usdc"
        write_animation(anim, out, mode="blendshapes", tolerance=tolerance)
        stage = Usd.Stage.Open(str(out))
        info = stage.GetRootLayer().customLayerData["facegen"]["reconstruction"]
        assert info["tolerance"] == tolerance and info["relative_error"] <= tolerance
        evaluated = usdskel_points(stage, 31.0)
        assert max_distance(evaluated, anim.vertices[31]) <= (tolerance + 1e-6) * grid_mesh.size
        counts.append(info["targets"])
    assert counts[0] < counts[1] < counts[2], counts


def test_fixed_and_per_frame_targets(tmp_path, grid_mesh):
    anim = rich_animation(grid_mesh, frames=20)
    write_animation(anim, tmp_path / "k3.usdc", mode="blendshapes", morph_targets="3")  # as the CLI passes it
    stage = Usd.Stage.Open(str(tmp_path / "k3.usdc"))
    info = stage.GetRootLayer().customLayerData["facegen"]["reconstruction"]
    assert "tolerance" not in info and info["targets"] == 4  # 3 PCA targets + rest
    animation = UsdSkel.Animation(stage.GetPrimAtPath("/Face/Skeleton/Animation"))
    assert list(animation.GetBlendShapesAttr().Get()) == ["pca_000", "pca_001", "pca_002", "rest"]
    error = max_distance(usdskel_points(stage, 10.0), anim.vertices[10])
    assert error <= info["max_error"] + 1e-6 * grid_mesh.size

    # "all": one target per frame, one-hot weights, no rest target, exact
    write_animation(anim, tmp_path / "all.usdc", mode="blendshapes", morph_targets="all")
    stage = Usd.Stage.Open(str(tmp_path / "all.usdc"))
    attr = UsdSkel.Animation(stage.GetPrimAtPath("/Face/Skeleton/Animation")).GetBlendShapeWeightsAttr()
    np.testing.assert_array_equal(np.stack([np.asarray(attr.Get(t)) for t in range(20)]), np.eye(20))
    assert stage.GetRootLayer().customLayerData["facegen"]["reconstruction"]["targets"] == 20
    assert max_distance(usdskel_points(stage, 7.0), anim.vertices[7]) <= 1e-6 * grid_mesh.size

    long = rich_animation(grid_mesh, frames=MAX_FRAME_TARGETS + 1)
    with pytest.raises(FacegenError, match="morph targets") as err:
        write_animation(long, tmp_path / "long.usdc", mode="blendshapes", morph_targets="all")
    assert err.value.param == "morph_targets"
    assert not (tmp_path / "long.usdc").exists() and not (tmp_path / "long.wav").exists()


def test_options_are_checked(tmp_path, grid_mesh):
    anim = make_animation(grid_mesh, frames=5)
    with pytest.raises(FacegenError, match="blendshapes only"):
        write_animation(anim, tmp_path / "x.usdc", morph_targets=4)
    with pytest.raises(FacegenError, match="tolerance apply to USD blendshapes only"):
        write_animation(anim, tmp_path / "x.usdc", mode="points", tolerance=1e-3)
    with pytest.raises(FacegenError, match="points, blendshapes"):
        write_animation(anim, tmp_path / "x.usdc", mode="skinned")
    with pytest.raises(FacegenError, match="mode"):
        write_animation(anim, tmp_path / "x.npy", mode="blendshapes")
    with pytest.raises(FacegenError, match="positive"):
        write_animation(anim, tmp_path / "x.usdc", mode="blendshapes", tolerance=0)
    with pytest.raises(FacegenError, match="whole number"):
        write_animation(anim, tmp_path / "x.usdc", mode="blendshapes", morph_targets=0)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("exc", [RuntimeError("disk on fire"), KeyboardInterrupt()])
def test_failed_write_leaves_nothing(tmp_path, grid_mesh, exc):
    anim = rich_animation(grid_mesh, frames=10)
    anim.metadata = {Boom(exc): 1}
    with pytest.raises(type(exc)):
        write_animation(anim, tmp_path / "out.usdc", mode="blendshapes")
    assert list(tmp_path.iterdir()) == []
    # a previous file at the same path is kept as it was
    write_animation(rich_animation(grid_mesh, frames=10), tmp_path / "out.usdc", mode="blendshapes")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    with pytest.raises(type(exc)):
        write_animation(anim, tmp_path / "out.usdc", mode="blendshapes")
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_validate_blendshapes(tmp_path, grid_mesh):
    out = tmp_path / "ok.usda"
    write_animation(rich_animation(grid_mesh), out, mode="blendshapes")
    report = validate(out, template=grid_mesh, fps=FPS)
    assert report.ok and report.warnings == [], report.to_text()
    for name in ("blendshapes", "reconstruction", "rig", "vertex count", "faces", "frame rate",
                 "time samples",
                 "finite", "displacement", "audio", "audio duration", "usd validators"):
        assert report.check(name) is not None and report.check(name).ok, name
    assert report.check("time samples").detail == f"{FRAMES} frames, one at each of 0..{FRAMES - 1}"
    assert "blend shapes + 'rest'" in report.check("blendshapes").detail
    assert "none named as ARKit shapes (pca_000, " in report.check("rig").detail
    assert "120 vertices per frame" in report.check("vertex count").detail

    def broken(name: str, edit) -> set[str]:
        copy = tmp_path / f"{name}.usda"
        copy.write_bytes(out.read_bytes())
        (tmp_path / f"{name}.wav").write_bytes((tmp_path / "ok.wav").read_bytes())
        stage = Usd.Stage.Open(str(copy))
        edit(stage)
        stage.GetRootLayer().Save()
        report = validate(copy, template=grid_mesh)
        return {c.name for c in report.failures}

    first = Sdf.Path("/Face/Mesh/pca_000.offsets")

    def nan_offset(stage):
        offsets = np.asarray(stage.GetAttributeAtPath(first).Get()).copy()
        offsets[3, 1] = np.nan
        stage.GetAttributeAtPath(first).Set(Vt.Vec3fArray.FromNumpy(offsets))

    def huge_offset(stage):
        offsets = np.asarray(stage.GetAttributeAtPath(first).Get()).copy()
        offsets[3] = [0.0, 0.0, 2.0 * grid_mesh.size]
        stage.GetAttributeAtPath(first).Set(Vt.Vec3fArray.FromNumpy(offsets))

    def drop_sample(stage):
        stage.GetAttributeAtPath(WEIGHTS).ClearAtTime(17.0)

    def short_sample(stage):
        stage.GetAttributeAtPath(WEIGHTS).Set(Vt.FloatArray([0.5]), 4.0)

    def short_offsets(stage):
        shape = UsdSkel.BlendShape(stage.GetPrimAtPath("/Face/Mesh/pca_001"))
        shape.GetPointIndicesAttr().Clear()
        shape.GetOffsetsAttr().Set(Vt.Vec3fArray.FromNumpy(np.zeros((7, 3), np.float32)))

    def over_tolerance(stage):
        data = stage.GetRootLayer().customLayerData
        data["facegen"]["reconstruction"]["relative_error"] = 0.5
        stage.GetRootLayer().customLayerData = data

    assert broken("nan", nan_offset) == {"finite", "displacement"}  # NaN frames cannot be measured
    assert broken("huge", huge_offset) == {"displacement", "time samples"}  # and it leaves the extent
    assert broken("gap", drop_sample) == {"time samples"}  # 59 frames: still within a frame of the audio
    cascade = {"blendshapes", "vertex count", "finite", "audio duration"}  # no frames to check at all
    assert broken("short", short_sample) == cascade
    assert "time 4 has a different count" in validate(tmp_path / "short.usda").check("blendshapes").detail
    assert broken("offsets", short_offsets) == cascade
    detail = validate(tmp_path / "offsets.usda").check("blendshapes").detail
    assert "7 offsets for a mesh of 120 points" in detail
    assert broken("over", over_tolerance) == {"reconstruction"}
    detail = validate(tmp_path / "gap.usda").check("time samples").detail
    assert "blendShapeWeights sampled at 0, 1, 2, 3, ..." in detail


def test_biwi_blendshapes(tmp_path, biwi_template):
    anim = rich_animation(biwi_template, frames=50)
    write_animation(anim, tmp_path / "biwi.usdc")
    written = write_animation(anim, tmp_path / "biwi_bs.usdc", mode="blendshapes")
    assert written == [tmp_path / "biwi_bs.usdc", tmp_path / "biwi_bs.wav"]
    stage = Usd.Stage.Open(str(tmp_path / "biwi_bs.usdc"))
    info = stage.GetRootLayer().customLayerData["facegen"]["reconstruction"]
    bound = DEFAULT_TOLERANCE * biwi_template.size
    assert info["max_error"] <= bound and info["size"] == pytest.approx(biwi_template.size)
    evaluated = usdskel_points(stage, 25.0)
    assert evaluated.shape == (23370, 3)
    assert max_distance(evaluated, anim.vertices[25]) <= info["max_error"] + 1e-6 * biwi_template.size
    # much smaller than one points sample per frame
    assert (tmp_path / "biwi_bs.usdc").stat().st_size < 0.5 * (tmp_path / "biwi.usdc").stat().st_size
    report = validate(tmp_path / "biwi_bs.usdc", template=biwi_template, fps=FPS)
    assert report.ok and report.warnings == [], report.to_text()
    assert report.check("vertex count").detail.startswith("23370 vertices per frame")
    back = read_animation(tmp_path / "biwi_bs.usdc", template=biwi_template)
    assert max_distance(back.vertices, anim.vertices) <= info["max_error"] + 1e-6 * biwi_template.size


@pytest.mark.parametrize("name", ["arkit.usdc", "arkit.usdz"])
def test_arkit_rig_blend_shapes(tmp_path, name):
    """`rig="arkit"`: blendshapes by default, one BlendShape per ARKit shape named by ARKit's name, the
    solver's weights; UsdSkel's own evaluation is the template plus the weighted ARKit shapes."""
    from helpers import rig_clip

    from facegen.arkit.names import ARKIT_NAMES
    from facegen.arkit.solve import fit_arkit

    anim = rig_clip(30)
    out = tmp_path / name
    write_animation(anim, out, rig="arkit")
    stage = Usd.Stage.Open(str(out))
    mesh = stage.GetPrimAtPath("/Face/Mesh")
    assert list(UsdSkel.BindingAPI(mesh).GetBlendShapesAttr().Get()) == list(ARKIT_NAMES)
    assert [p.name
            for p in UsdSkel.BindingAPI(mesh).GetBlendShapeTargetsRel().GetTargets()] == list(ARKIT_NAMES)
    animation = UsdSkel.Animation(stage.GetPrimAtPath("/Face/Skeleton/Animation"))
    assert list(animation.GetBlendShapesAttr().Get()) == list(ARKIT_NAMES)
    fit = fit_arkit(anim)
    t = 12
    assert np.allclose(np.asarray(animation.GetBlendShapeWeightsAttr().Get(t)), fit.weights[t])
    expected = anim.template + np.einsum("k,kvc->vc", fit.weights[t], fit.shapes.offsets)
    assert max_distance(usdskel_points(stage, float(t)), expected) <= 1e-5 * anim.size
    info = stage.GetRootLayer().customLayerData["facegen"]["reconstruction"]
    assert info["rig"] == "arkit" and info["targets"] == 52 and "tolerance" not in info
    assert info["lip_error_mm"] == pytest.approx(fit.lip_error_mm)
    report = validate(out)
    assert report.ok and report.warnings == [], report.to_text()
    assert report.check("rig").detail.startswith("ARKit: 52 of 52 shapes (eyeBlinkLeft, ")


def test_extents_equal_the_frames_min_and_max():
    """frame_extents (blending on x, y, z planes) and point_extents (planes copied a block at a time) give
    exactly each frame's min and max, for clips longer than a block."""
    from facegen.exchange.usd_skel import frame_extents, point_extents

    rng = np.random.default_rng(3)
    template = rng.standard_normal((500, 3)).astype(np.float32)
    offsets = rng.standard_normal((7, 500, 3)).astype(np.float32)
    weights = rng.random((150, 7)).astype(np.float32)
    frames = (weights @ offsets.reshape(7, -1)).reshape(150, 500, 3) + template
    naive = np.stack([frames.min(1), frames.max(1)], axis=1)
    assert np.array_equal(point_extents(frames), naive)
    assert np.allclose(frame_extents(template, offsets, weights, block=64), naive, atol=1e-6, rtol=0)
    assert frame_extents(template, offsets, weights).shape == (150, 2, 3)
