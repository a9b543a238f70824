"""UsdSkel blendshapes: the animation as a few BlendShape targets and one weight curve per target.

`facegen.exchange.usd.write(..., mode="blendshapes")` calls this module. The targets are the writers'
basis (morph_targets.py, the same code path as glTF morph targets): by rig, the PCA basis with weights
rescaled into [0, 1] (Blender clamps a shape key's value to its 0..1 slider range), or the 52 ARKit shapes
named by their ARKit names with the solver's weights, so a frame is

    points(t) = template + sum_k weights[t, k] * offsets[k]

Layout (added to the points-mode layout of usd.py; /Face is a SkelRoot instead of an Xform, and the
mesh's `points` hold the template only, with no time samples; the mesh's and the SkelRoot's `extent`
have one time sample per frame, the blended frame's bounds, and a default value that bounds every frame):

    /Face/Skeleton            Skeleton: one joint "root", bind and rest transforms identity;
                              UsdSkelBindingAPI with skel:animationSource -> /Face/Skeleton/Animation
    /Face/Skeleton/Animation  SkelAnimation: blendShapes (the target names) and blendShapeWeights, one
                              float[K] time sample per frame at time codes 0..T-1
    /Face/Mesh                UsdSkelBindingAPI: skel:skeleton -> /Face/Skeleton, skel:blendShapes and
                              skel:blendShapeTargets (the BlendShape prims below, same order),
                              primvars:skel:jointIndices [0] / jointWeights [1] (constant, one influence),
                              primvars:skel:geomBindTransform identity
    /Face/Mesh/<name>         BlendShape: offsets [V]; or, when a quarter or more of the target's offsets
                              are zero, pointIndices (the vertices it moves) and their offsets only
                              (4 + 12 bytes per moved vertex < 12 per vertex). `rest` is a target whose
                              weight is 1 in every frame: the constant part the [0, 1] rescaling moved out
                              of the weights (absent when it is zero)

The reconstruction error goes in customLayerData["facegen"]["reconstruction"] (see `layer_info`).
"""

from __future__ import annotations

import numpy as np

from facegen.errors import FacegenError
from facegen.exchange.morph_targets import REST_SHAPE
from facegen.exchange.pca import MorphBasis

SKELETON_PATH = "/Face/Skeleton"
ANIMATION_PATH = "/Face/Skeleton/Animation"
JOINT = "root"


def layer_info(basis: MorphBasis, count: int) -> dict:
    """customLayerData["facegen"]["reconstruction"]: how far the blendshapes are from the source frames.

    rig is "pca" or "arkit"; max_error is in model units (the largest vertex distance over every frame),
    relative_error is it divided by size (the template's bounding-box diagonal), tolerance the relative
    bound K was chosen for (absent when K was fixed or the rig's shapes are), targets the number of
    BlendShape prims (including `rest`); lip_error_mm and face_error_mm the ARKit fit's mean errors."""
    info = {
        "rig": basis.rig,
        "targets": int(count),
        "max_error": float(basis.max_error),
        "relative_error": float(basis.relative_error),
        "size": float(basis.size),
    }
    if basis.tolerance is not None:
        info["tolerance"] = float(basis.tolerance)
    if basis.lip_error_mm is not None:
        info["lip_error_mm"] = float(basis.lip_error_mm)
    if basis.face_error_mm is not None:
        info["face_error_mm"] = float(basis.face_error_mm)
    return info


def frame_extents(template: np.ndarray, offsets: np.ndarray, weights: np.ndarray,
                  block: int = 64) -> np.ndarray:
    """[T, 2, 3] float32: the bounding box (min, max) of each blended frame template + weights[t] @
    offsets. The blend runs on x, y, z planes ([K, 3, V]) so each minimum and maximum is over a contiguous
    row (over [.., V, 3] numpy reduces the middle axis ~15x slower)."""
    template = np.asarray(template, np.float32)
    offsets = np.asarray(offsets, np.float32)
    planes = np.ascontiguousarray(offsets.transpose(0, 2, 1)).reshape(len(offsets), -1)
    template_planes = np.ascontiguousarray(template.T)
    out = np.empty((len(weights), 2, 3), np.float32)
    for start in range(0, len(weights), block):
        frames = (weights[start:start + block] @ planes).reshape(-1, *template_planes.shape)
        frames += template_planes
        out[start:start + block, 0] = frames.min(2)
        out[start:start + block, 1] = frames.max(2)
    return out


def point_extents(frames: np.ndarray, block: int = 16) -> np.ndarray:
    """[T, 2, 3]: the bounding box (min, max) of each of `frames` [T, V, 3], reduced over x, y, z planes
    copied a block of frames at a time (see frame_extents)."""
    frames = np.asarray(frames)
    out = np.empty((len(frames), 2, 3), frames.dtype)
    for start in range(0, len(frames), block):
        planes = np.ascontiguousarray(frames[start:start + block].transpose(0, 2, 1))
        out[start:start + block, 0] = planes.min(2)
        out[start:start + block, 1] = planes.max(2)
    return out


def author_skeleton(stage, mesh_path: str, names: list[str], offsets: np.ndarray) -> None:
    """Skeleton, SkelAnimation (without weight samples), BlendShapes and the mesh's binding."""
    from pxr import Gf, Sdf, UsdSkel, Vt

    identity = Gf.Matrix4d(1.0)
    skeleton = UsdSkel.Skeleton.Define(stage, SKELETON_PATH)
    skeleton.CreateJointsAttr(Vt.TokenArray([JOINT]))
    skeleton.CreateBindTransformsAttr(Vt.Matrix4dArray([identity]))
    skeleton.CreateRestTransformsAttr(Vt.Matrix4dArray([identity]))
    animation = UsdSkel.Animation.Define(stage, ANIMATION_PATH)
    animation.CreateBlendShapesAttr(Vt.TokenArray(names))
    animation.CreateBlendShapeWeightsAttr()
    UsdSkel.BindingAPI.Apply(skeleton.GetPrim()).CreateAnimationSourceRel().SetTargets([animation.GetPath()])

    binding = UsdSkel.BindingAPI.Apply(stage.GetPrimAtPath(mesh_path))
    binding.CreateSkeletonRel().SetTargets([skeleton.GetPath()])
    binding.CreateBlendShapesAttr(Vt.TokenArray(names))
    binding.CreateJointIndicesPrimvar(True, 1).Set(Vt.IntArray([0]))
    binding.CreateJointWeightsPrimvar(True, 1).Set(Vt.FloatArray([1.0]))
    binding.CreateGeomBindTransformAttr(identity)
    targets = []
    for name, offset in zip(names, offsets, strict=True):
        shape = UsdSkel.BlendShape.Define(stage, Sdf.Path(mesh_path).AppendChild(name))
        moving = np.flatnonzero(np.any(offset != 0, axis=1))
        if 16 * len(moving) < 12 * len(offset):  # index + offset of the vertices it moves is smaller
            shape.CreatePointIndicesAttr(Vt.IntArray.FromNumpy(moving.astype(np.int32)))
            offset = offset[moving]
        shape.CreateOffsetsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(offset, dtype=np.float32)))
        targets.append(shape.GetPath())
    binding.CreateBlendShapeTargetsRel().SetTargets(targets)


def author_samples(layer, weights: np.ndarray, extents: np.ndarray, mesh_path: str, root_path: str) -> None:
    """One blendShapeWeights sample per frame at 0..T-1 and, at the same times, the extent of the blended
    mesh on the mesh and on the SkelRoot; straight into the layer (no stage open on it)."""
    from pxr import Sdf, Vt

    weights = np.ascontiguousarray(weights, dtype=np.float32)
    attr = Sdf.Path(ANIMATION_PATH).AppendProperty("blendShapeWeights")
    boxes = [Sdf.Path(path).AppendProperty("extent") for path in (mesh_path, root_path)]
    with Sdf.ChangeBlock():
        for i in range(len(weights)):
            layer.SetTimeSample(attr, float(i), Vt.FloatArray.FromNumpy(weights[i]))
            box = Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(extents[i]))
            for path in boxes:
                layer.SetTimeSample(path, float(i), box)


# ---- reading -----------------------------------------------------------------------------------------


def shape_names(mesh) -> list[str]:
    """The mesh's skel:blendShapes (empty when it has no UsdSkel binding)."""
    from pxr import UsdSkel

    prim = mesh.GetPrim()
    if not prim.HasAPI(UsdSkel.BindingAPI):
        return []
    return [str(n) for n in (UsdSkel.BindingAPI(prim).GetBlendShapesAttr().Get() or [])]


def has_blendshapes(mesh) -> bool:
    """True when the mesh is bound to blend shapes (skel:blendShapes authored and not empty)."""
    return bool(shape_names(mesh))


def animation_of(mesh):
    """The SkelAnimation driving the mesh's skeleton; a missing link is a FacegenError."""
    from pxr import UsdSkel

    binding = UsdSkel.BindingAPI(mesh.GetPrim())
    skeleton = binding.GetInheritedSkeleton()
    if not skeleton:
        raise FacegenError(f"mesh {mesh.GetPath()} has blend shapes but no skel:skeleton: the file is broken")
    source = UsdSkel.BindingAPI(skeleton.GetPrim()).GetInheritedAnimationSource()
    animation = UsdSkel.Animation(source) if source else None
    if not animation:
        raise FacegenError(
            f"skeleton {skeleton.GetPath()} has no skel:animationSource SkelAnimation: the file is broken"
        )
    return animation


def weight_samples(animation) -> tuple[list[str], list[float], list[np.ndarray]]:
    """(the animation's blendShapes names, the time codes of blendShapeWeights, the float32 array at each)."""
    names = [str(n) for n in (animation.GetBlendShapesAttr().Get() or [])]
    attr = animation.GetBlendShapeWeightsAttr()
    times = list(attr.GetTimeSamples())
    return names, times, [np.asarray(attr.Get(t), dtype=np.float32) for t in times]


def blend_targets(stage, mesh, num_points: int) -> tuple[list[str], np.ndarray]:
    """The mesh's blend shape names (skel:blendShapes order) and dense offsets [K, V, 3] float32.

    A target whose prim, offsets or pointIndices do not fit the mesh is a FacegenError."""
    from pxr import UsdSkel

    names = shape_names(mesh)
    targets = UsdSkel.BindingAPI(mesh.GetPrim()).GetBlendShapeTargetsRel().GetTargets()
    if len(targets) != len(names):
        raise FacegenError(
            f"mesh {mesh.GetPath()} names {len(names)} blend shapes but targets {len(targets)} prims: "
            "the file is broken"
        )
    dense = np.zeros((len(names), num_points, 3), np.float32)
    for i, path in enumerate(targets):
        shape = UsdSkel.BlendShape(stage.GetPrimAtPath(path))
        if not shape:
            raise FacegenError(f"blend shape target {path} is not a BlendShape prim: the file is broken")
        offsets = np.asarray(shape.GetOffsetsAttr().Get() or [], dtype=np.float32).reshape(-1, 3)
        indices = shape.GetPointIndicesAttr().Get()
        if indices is None or len(indices) == 0:
            if len(offsets) != num_points:
                raise FacegenError(
                    f"blend shape {path} has {len(offsets)} offsets for a mesh of {num_points} points"
                )
            dense[i] = offsets
            continue
        indices = np.asarray(indices, dtype=np.int64)
        if len(indices) != len(offsets) or indices.min() < 0 or indices.max() >= num_points:
            raise FacegenError(
                f"blend shape {path}: {len(offsets)} offsets for {len(indices)} pointIndices "
                f"(range {indices.min()}..{indices.max()}, the mesh has {num_points} points)"
            )
        dense[i, indices] = offsets
    return names, dense


def blendshape_frames(stage, mesh, rest: np.ndarray) -> tuple[list[float], np.ndarray]:
    """The time codes of the weight samples and the blended points [T, V, 3] float32 at each:
    rest + weights @ offsets, with the animation's weights mapped onto the mesh's shapes by name
    (a shape the animation does not drive has weight 0, as in UsdSkel). The skinning is the identity
    (one joint, identity transforms), which facegen writes; other skeletons are not evaluated here."""
    names, offsets = blend_targets(stage, mesh, len(rest))
    anim_names, times, samples = weight_samples(animation_of(mesh))
    if not times:
        raise FacegenError(f"{ANIMATION_PATH}: blendShapeWeights has no time samples: nothing to read")
    bad = [t for t, w in zip(times, samples, strict=True) if len(w) != len(anim_names)]
    if bad:
        raise FacegenError(
            f"blendShapeWeights at time {bad[0]:g} has a different count than the "
            f"{len(anim_names)} blendShapes"
        )
    column = {name: i for i, name in enumerate(anim_names)}
    weights = np.zeros((len(times), len(names)), np.float32)
    for j, name in enumerate(names):
        if name in column:
            weights[:, j] = np.stack(samples)[:, column[name]]
    flat = weights @ offsets.reshape(len(names), -1) + np.asarray(rest, np.float32).reshape(1, -1)
    return times, flat.reshape(len(times), -1, 3).astype(np.float32, copy=False)


def skel_points(stage, mesh, time: float) -> np.ndarray:
    """The mesh's points at `time` as UsdSkel evaluates them (blend shapes, then skinning) — what a DCC
    that follows the UsdSkel spec shows."""
    from pxr import Usd, UsdSkel

    root = UsdSkel.Root.Find(mesh.GetPrim())
    if not root:
        raise FacegenError(f"mesh {mesh.GetPath()} is not under a SkelRoot: UsdSkel will not evaluate it")
    cache = UsdSkel.Cache()
    cache.Populate(root, Usd.PrimDefaultPredicate)
    skinning = cache.GetSkinningQuery(mesh.GetPrim())
    skeleton = cache.GetSkelQuery(UsdSkel.BindingAPI(mesh.GetPrim()).GetInheritedSkeleton())
    if not skinning or not skeleton:
        raise FacegenError(f"UsdSkel finds no skinning for {mesh.GetPath()}: the skel binding is broken")
    points = mesh.GetPointsAttr().Get(time)
    if skinning.HasBlendShapes():
        weights = skinning.GetBlendShapeMapper().Remap(skeleton.GetAnimQuery().ComputeBlendShapeWeights(time))
        query = UsdSkel.BlendShapeQuery(UsdSkel.BindingAPI(mesh.GetPrim()))
        sub_weights, shape_indices, sub_indices = query.ComputeSubShapeWeights(weights)
        if not query.ComputeDeformedPoints(
            sub_weights, shape_indices, sub_indices, query.ComputeBlendShapePointIndices(),
            query.ComputeSubShapePointOffsets(), points,
        ):
            raise FacegenError(f"UsdSkel cannot apply the blend shapes of {mesh.GetPath()} at time {time:g}")
    if not skinning.ComputeSkinnedPoints(skeleton.ComputeSkinningTransforms(time), points, time):
        raise FacegenError(f"UsdSkel cannot skin {mesh.GetPath()} at time {time:g}")
    return np.asarray(points, dtype=np.float32)


def describe(names: list[str]) -> str:
    """'K blend shapes (+ rest)' for messages."""
    count = len(names) - (REST_SHAPE in names)
    return f"{count} blend shapes" + (f" + {REST_SHAPE!r}" if REST_SHAPE in names else "")
