"""The morph basis a glTF or USD-blendshapes writer stores, chosen by rig, and what the writers derive from
it.

A rig gives named targets (offsets from the template) and a weight curve per target:

    pca     the PCA basis of the clip's offsets (exchange/pca.py): the fewest targets within the tolerance,
            weights rescaled into [0, 1] (Blender clamps shape keys there), sparse targets, vertices the
            clip never moves exactly zero in every target
    arkit   Apple's 52 ARKit blend shapes of the face (facegen.arkit.shapes) with the weights the solver
            fits to the clip (facegen.arkit.solve): an asset any ARKit-aware engine retargets by name

Both are a pca.MorphBasis, so every writer has one code path. As written (`targets_as_written`), a frame is

    points(t) = template + sum_k weights[t, k] * offsets[k]

with the template as the base mesh (a real pose, the neutral face) and, when the basis has a constant
offset (`rest`, from the [0, 1] rescaling), a target named "rest" whose weight is 1 in every frame.
`normal_deltas` gives each stored target the NORMAL offsets that glTF morph targets carry.
"""

from __future__ import annotations

import numpy as np

from facegen.animation import Animation
from facegen.errors import FacegenError
from facegen.exchange.pca import DEFAULT_TOLERANCE, MorphBasis, max_vertex_error, morph_basis
from facegen.face.mesh import Mesh, vertex_normals

RIGS = ("pca", "arkit")
REST_SHAPE = "rest"
# ridge weight (share of the mean weight energy) pulling a normal delta to its shape's own
_NORMAL_PRIOR = 1e-3
_NORMAL_BLOCK = 64  # frames whose normals are computed at once
NORMAL_EPSILON = 1e-2  # shorter normal offsets (under 0.6 degrees at weight 1) are stored as exactly zero


def check_rig(rig: str, mesh: Mesh | None = None) -> str:
    """`rig` when it is one facegen writes; with `mesh`, also refuse a template without the rig's regions
    (before any work: the ARKit shapes are built, and cached, from its regions)."""
    if rig not in RIGS:
        raise FacegenError(f"unknown rig {rig!r}: use one of {', '.join(RIGS)}")
    if rig == "arkit" and mesh is not None:
        from facegen.arkit.shapes import arkit_shapes

        arkit_shapes(mesh)
    return rig


def writer_basis(
    anim: Animation, rig: str = "pca", morph_targets: int | str | None = None, tolerance: float | None = None,
) -> MorphBasis:
    """The basis a writer stores `anim` with. `morph_targets` and `tolerance` choose the PCA basis's size
    (see pca.morph_basis) and do not apply to the ARKit rig, whose 52 shapes are fixed."""
    check_rig(rig)
    if rig == "arkit":
        given = [n for n, v in (("morph_targets", morph_targets), ("tolerance", tolerance)) if v is not None]
        if given:
            raise FacegenError(f"{' and '.join(n.replace('_', ' ') for n in given)} size the PCA basis: drop "
                               "them with the arkit rig", param=(*given, "rig"))
        return _arkit_basis(anim)
    return _pca_basis(anim, morph_targets, DEFAULT_TOLERANCE if tolerance is None else float(tolerance))


def _pca_basis(anim: Animation, morph_targets: int | str | None, tolerance: float) -> MorphBasis:
    """pca.morph_basis with weights in [0, 1] and sparse targets (a vertex that never moves in `anim` has
    exactly zero offsets in every target and in `rest`)."""
    return morph_basis(anim, morph_targets, tolerance, unit_weights=True, sparse=True)


def _arkit_basis(anim: Animation) -> MorphBasis:
    """The 52 ARKit shapes of the animation's face with the solver's weights, and their measured error."""
    from facegen.arkit.solve import fit_arkit

    fit = fit_arkit(anim)
    basis = MorphBasis(
        targets=np.ascontiguousarray(fit.shapes.offsets, dtype=np.float32),
        weights=np.ascontiguousarray(fit.weights, dtype=np.float32),
        rest=np.zeros((anim.num_vertices, 3), np.float32),
        max_error=0.0, size=float(anim.size), tolerance=None, names=list(fit.names), rig="arkit",
        lip_error_mm=float(fit.lip_error_mm), face_error_mm=float(fit.face_error_mm),
    )
    basis.max_error = max_vertex_error(anim, basis)
    return basis


def targets_as_written(basis: MorphBasis) -> tuple[list[str], np.ndarray, np.ndarray]:
    """(names, offsets [K', V, 3], weights [T, K']) as written over the template: the basis's targets,
    plus the `rest` target with weight 1 in every frame when the basis has a nonzero constant offset."""
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


def normal_deltas(template: np.ndarray, faces: np.ndarray, offsets: np.ndarray,
                  weights: np.ndarray) -> np.ndarray:
    """NORMAL offsets [K, V, 3] float32 for stored targets: the normals of the template plus
    sum_k weights[t, k] * deltas[k] come as close as they can (least squares over the frames) to the true
    vertex normals of each blended frame t.

    A small ridge term pulls each delta towards its own shape's normal change (normals of template +
    offsets[k] minus the template's): a target the clip barely uses keeps the normals of its own shape.
    Deltas are not unit vectors (glTF renderers normalise after blending); those shorter than
    NORMAL_EPSILON are exactly zero, so targets stay sparse."""
    template = np.asarray(template, np.float32)
    K, V = offsets.shape[0], template.shape[0]
    base = vertex_normals(template, faces)
    flat = offsets.reshape(K, -1)
    prior = np.stack([vertex_normals(template + offsets[k], faces) - base for k in range(K)]).reshape(K, -1)
    weights = np.asarray(weights, np.float32)
    gram = weights.astype(np.float64).T @ weights
    rhs = np.zeros((K, 3 * V), np.float64)
    normals = np.empty((_NORMAL_BLOCK, V, 3), np.float32)
    for start in range(0, len(weights), _NORMAL_BLOCK):
        w = weights[start:start + _NORMAL_BLOCK]
        frames = (w @ flat).reshape(len(w), V, 3) + template
        for i, frame in enumerate(frames):
            normals[i] = vertex_normals(frame, faces)
        rhs += w.T @ (normals[: len(w)] - base).reshape(len(w), -1)
    ridge = _NORMAL_PRIOR * max(float(np.trace(gram)) / K, 1e-12)
    deltas = np.linalg.solve(gram + ridge * np.eye(K),
                             rhs + ridge * prior).reshape(K, V, 3).astype(np.float32)
    deltas[np.linalg.norm(deltas, axis=2) < NORMAL_EPSILON] = 0.0
    return deltas
