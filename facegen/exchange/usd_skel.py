"""UsdSkel blendshapes: the animation as a few BlendShape targets and one weight curve per target.

`facegen.exchange.usd.write(..., mode="blendshapes")` calls this module. The targets are the PCA basis of
`facegen.exchange.pca` (the same code path as glTF morph targets), with weights rescaled into [0, 1]
(Blender clamps a shape key's value to its 0..1 slider range), so a frame is

    points(t) = template + rest + sum_k weights[t, k] * offsets[k]

Layout (added to the points-mode layout of usd.py; /Face is a SkelRoot instead of an Xform, and the
mesh's `points` hold the template only, with no time samples):

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

from dataclasses import replace

import numpy as np

from facegen.animation import Animation
from facegen.errors import FacegenError
from facegen.exchange.pca import DEFAULT_TOLERANCE, MorphBasis, max_vertex_error, morph_basis

SKELETON_PATH = "/Face/Skeleton"
ANIMATION_PATH = "/Face/Skeleton/Animation"
JOINT = "root"
REST_SHAPE = "rest"


def basis_for(anim: Animation, morph_targets: int | str | None, tolerance: float | None) -> MorphBasis:
    """The PCA basis the blendshapes are made of: pca.morph_basis with weights in [0, 1] and sparse targets
    (the same basis as glTF morph targets).

    Vertices that never move in `anim` also get exactly zero offsets in every target and in `rest` (PCA
    leaves float rounding there, and a fixed K has no error budget to drop it), so BlendShapes can leave
    them out; the error is measured again then. `morph_targets` as pca.parse_morph_targets takes it.
    """
    basis = morph_basis(
        anim, morph_targets, DEFAULT_TOLERANCE if tolerance is None else float(tolerance),
        unit_weights=True, sparse=True,
    )
    moving = np.zeros(anim.num_vertices, bool)
    template = np.asarray(anim.template, np.float32)
    for _, block in anim.frame_blocks(256):  # in blocks: a [T, V, 3] boolean is large for long clips
        moving |= np.any(block != template, axis=(0, 2))
    if moving.all():
        return basis
    basis = replace(basis, targets=basis.targets * moving[None, :, None], rest=basis.rest * moving[:, None])
    basis.max_error = max_vertex_error(anim, basis)
    return basis


def shapes(basis: MorphBasis) -> tuple[list[str], np.ndarray, np.ndarray]:
    """(names, offsets [K', V, 3], weights [T, K']) as written: the basis's targets, plus the `rest`
    target with weight 1 in every frame when the basis has a nonzero constant offset."""
    names = list(basis.names)
    offsets = np.asarray(basis.targets, dtype=np.float32)
    weights = np.asarray(basis.weights, dtype=np.float32)
    if np.any(basis.rest):
        if REST_SHAPE in names:
            raise FacegenError(f"a morph target is already called {REST_SHAPE!r}: rename it")
        names.append(REST_SHAPE)
        offsets = np.concatenate([offsets, np.asarray(basis.rest, np.float32)[None]])
        weights = np.concatenate([weights, np.ones((len(weights), 1), np.float32)], axis=1)
    return names, offsets, weights


def layer_info(basis: MorphBasis, count: int) -> dict:
    """customLayerData["facegen"]["reconstruction"]: how far the blendshapes are from the source frames.

    max_error is in model units (the largest vertex distance over every frame), relative_error is it
    divided by size (the template's bounding-box diagonal), tolerance the relative bound K was chosen for
    (absent when K was fixed), targets the number of BlendShape prims (including `rest`)."""
    info = {
        "targets": int(count),
        "max_error": float(basis.max_error),
        "relative_error": float(basis.relative_error),
        "size": float(basis.size),
    }
    if basis.tolerance is not None:
        info["tolerance"] = float(basis.tolerance)
    return info


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


def author_weights(layer, weights: np.ndarray) -> None:
    """One blendShapeWeights sample per frame at 0..T-1, straight into the layer (no stage open on it)."""
    from pxr import Sdf, Vt

    weights = np.ascontiguousarray(weights, dtype=np.float32)
    attr = Sdf.Path(ANIMATION_PATH).AppendProperty("blendShapeWeights")
    with Sdf.ChangeBlock():
        for i in range(len(weights)):
            layer.SetTimeSample(attr, float(i), Vt.FloatArray.FromNumpy(weights[i]))


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
