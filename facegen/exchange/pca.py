"""Morph targets for an animation: a PCA basis of its vertex offsets from the template.

Frame t is stored as

    vertices[t] ~= template + rest + sum_k weights[t, k] * targets[k]

with K targets chosen so the largest vertex error over every frame stays under `tolerance` x the face's
size (the template's bounding-box diagonal), or a K the caller fixes. `rest` is zero unless
`unit_weights=True`, which rescales every weight curve into [0, 1] (moving each curve's minimum into
`rest`): Blender clamps a shape key's value to its slider range (0..1 unless widened), so glTF weights
outside it would be cut off there.

The basis comes from a randomized SVD of the [T, 3V] offset matrix (a range finder over its T-dim column
space, grown until the tolerance is met), so 1500 frames of 23,370 vertices take about a second. The error
is always measured on the stored float32 arrays, never estimated.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facegen.animation import Animation
from facegen.errors import FacegenError
from facegen.runtime import threads

DEFAULT_TOLERANCE = 1e-3  # largest vertex error, as a fraction of the face's bounding-box diagonal
MAX_FRAME_TARGETS = 300  # `k="all"` (one target per frame) is refused for longer clips
_OVERSAMPLE = 16  # extra random directions in the range finder beyond the targets kept
_FIRST_RANK = 48  # range finder size tried first when K is chosen from the tolerance
# K is searched on this many evenly spaced frames (the counts under half the clip's), coarse to fine, then
# confirmed on every frame
_SEARCH_FRAMES = (24, 96, 384)
_TILE = (64, 3 * 2048)  # rows x columns (x, y, z of 2048 vertices) per block when measuring errors
SPARSE_SEARCH_SHARE = 0.9  # with sparse=True, K is chosen for this share of the tolerance


@dataclass
class MorphBasis:
    """Morph targets reproducing an animation: frame t = template + rest + weights[t] @ targets.

    The PCA basis of this module, or any other rig's named shapes (exchange/morph_targets.py: `rig`, and the
    fit's stated lip and whole-face errors in millimetres when the rig has them)."""

    targets: np.ndarray  # [K, V, 3] float32 offsets
    weights: np.ndarray  # [T, K] float32
    rest: np.ndarray  # [V, 3] float32 constant offset (zeros unless the weights were moved into [0, 1])
    max_error: float  # largest vertex distance between reconstruction and source, in model units
    size: float  # the face's size (template bounding-box diagonal) the tolerance refers to
    tolerance: float | None  # the relative tolerance K was chosen for (None when K was fixed)
    names: list[str]  # one name per target
    rig: str = "pca"
    lip_error_mm: float | None = None
    face_error_mm: float | None = None

    @property
    def k(self) -> int:
        return int(self.targets.shape[0])

    @property
    def relative_error(self) -> float:
        return self.max_error / self.size if self.size > 0 else 0.0

    def offsets(self) -> np.ndarray:
        """The reconstructed offsets from the template, [T, V, 3] float32."""
        flat = self.weights @ self.targets.reshape(self.k, -1) + self.rest.reshape(1, -1)
        return flat.reshape(len(self.weights), -1, 3).astype(np.float32, copy=False)


def parse_morph_targets(value: int | str | None) -> int | str | None:
    """The number of morph targets as given (`--morph-targets`, the `morph_targets` write option): None or
    "" (the fewest within the tolerance), "all" (one per frame) or a whole number >= 1 (int or digits)."""
    if value is None or value == "":
        return None
    if isinstance(value, str):
        text = value.strip()
        if text.lower() == "all":
            return "all"
        k = int(text) if text.lstrip("-").isdigit() else None
    elif isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool):
        k = int(value) if float(value).is_integer() else None
    else:
        k = None
    if k is None:
        raise FacegenError(f"morph targets take a number of targets or 'all', got {value!r}",
                           param="morph_targets")
    if k < 1:
        raise FacegenError(f"morph targets must be a whole number >= 1, got {k}", param="morph_targets")
    return k


def morph_basis(
    anim: Animation,
    k: int | str | None = None,
    tolerance: float = DEFAULT_TOLERANCE,
    *,
    unit_weights: bool = False,
    sparse: bool = False,
    seed: int = 0,
) -> MorphBasis:
    """Morph targets for `anim`: `k=None` picks the fewest meeting `tolerance`; an int fixes K;
    "all" makes one target per frame (exact; refused beyond MAX_FRAME_TARGETS frames).

    `sparse=True` zeroes, per vertex, the smallest target entries whose sum stays within the error
    budget the components leave (K is chosen within SPARSE_SEARCH_SHARE of the tolerance), so targets
    can be stored as sparse accessors; the stated max_error is measured after that.
    """
    frames, template = _frames(anim)
    size = float(anim.size)
    k = parse_morph_targets(k)
    if k == "all":
        return frame_basis(anim, tolerance=tolerance, sparse=sparse)
    if not tolerance > 0:
        raise FacegenError(f"the morph target tolerance must be positive, got {tolerance}")
    T = frames.shape[0]
    flat = frames.reshape(T, -1)
    shift = template.reshape(-1)
    rng = np.random.default_rng(seed)
    with threads(1, ("blas",)):  # many small products: threads only add waiting
        moving = (flat != shift).any(0)  # coordinates that ever leave the template's
        if k is not None:
            k = min(int(k), T)
            temporal, coeffs = _principal_components(flat, shift, moving, min(T, k + _OVERSAMPLE), rng)
            basis = _finish(flat, shift, temporal[:, :k], coeffs[:k], size, None, unit_weights)
            return _sparsify(basis, flat, shift, 0.0) if sparse else basis
        if not sparse:
            return _search(flat, shift, moving, size, tolerance, unit_weights, rng)
        basis = _search(flat, shift, moving, size, tolerance * SPARSE_SEARCH_SHARE, unit_weights, rng)
        basis.tolerance = tolerance
        return _sparsify(basis, flat, shift, tolerance * size - basis.max_error)


def _search(
    flat: np.ndarray, shift: np.ndarray, moving: np.ndarray, size: float, tolerance: float,
    unit_weights: bool, rng: np.random.Generator,
) -> MorphBasis:
    """The fewest components within tolerance x size, growing the range finder until they exist."""
    T = flat.shape[0]
    bound = tolerance * size
    rank = min(T, _FIRST_RANK)
    subsets = [_even_rows(T, n) for n in _SEARCH_FRAMES if 2 * n <= T] or [np.arange(T)]
    while True:
        temporal, coeffs = _principal_components(flat, shift, moving, rank, rng)
        kept = temporal.shape[1]
        # the last few random directions are less accurate, unless the range finder caught every
        # direction there is (full rank, or fewer components than it tried: the data's rank is lower)
        usable = kept if rank >= T or kept < rank else max(1, kept - _OVERSAMPLE // 2)
        # K found on a few frames is a lower bound for more frames: search coarse to fine, then confirm
        # (and raise K where needed) on every frame with the stored arrays
        k: int | None = 1
        for i, rows in enumerate(subsets):
            k = _smallest_k(flat[rows], shift, temporal[rows], coeffs, k, usable, bound, gallop=i > 0)
            if k is None:
                break
        while k is not None:
            basis = _finish(flat, shift, temporal[:, :k], coeffs[:k], size, tolerance, unit_weights)
            if basis.max_error <= bound or (k >= usable and rank >= T):
                return basis
            k = k + 1 if k < usable else None
        if rank >= T:  # every component is in and the tolerance is still not met (float32 rounding)
            return _finish(flat, shift, temporal, coeffs, size, tolerance, unit_weights)
        rank = min(T, 2 * rank)


def frame_basis(anim: Animation, tolerance: float | None = None, sparse: bool = False) -> MorphBasis:
    """One target per frame (each frame's offsets) and one-hot weights: exact at every frame
    (`sparse` only matters for storage: static vertices are exactly zero already)."""
    frames, template = _frames(anim)
    T = frames.shape[0]
    if T > MAX_FRAME_TARGETS:
        raise FacegenError(
            f"one morph target per frame ('all') is for clips of at most {MAX_FRAME_TARGETS} frames, and "
            f"this one has {T}: {suggest_k(anim, tolerance or DEFAULT_TOLERANCE)} or leave the option out",
            param="morph_targets"
        )
    offsets = frames - template[None]
    flat = offsets.reshape(T, -1)
    return MorphBasis(
        targets=offsets,
        weights=np.eye(T, dtype=np.float32),
        rest=np.zeros(offsets.shape[1:], np.float32),
        max_error=_max_error(frames.reshape(T, -1), np.eye(T, dtype=np.float32), flat, template.reshape(-1)),
        size=float(anim.size),
        tolerance=None,
        names=[f"frame_{t:05d}" for t in range(T)],
    )


def suggest_k(anim: Animation, tolerance: float = DEFAULT_TOLERANCE) -> str:
    """A hint naming the K that meets `tolerance` for `anim` (for error messages)."""
    basis = morph_basis(anim, None, tolerance)
    return f"use {basis.k} morph targets (meets the tolerance {tolerance:g} of the face size)"


def max_vertex_error(anim: Animation, basis: MorphBasis) -> float:
    """The largest distance between a vertex of `anim` and its reconstruction from `basis`."""
    frames, template = _frames(anim)
    rest = (template + basis.rest).reshape(-1)
    return _max_error(frames.reshape(len(frames), -1), basis.weights, basis.targets.reshape(basis.k, -1),
                      rest)


# ---- internals ---------------------------------------------------------------------------------------


def _frames(anim: Animation) -> tuple[np.ndarray, np.ndarray]:
    """The animation's [T, V, 3] float32 frames (no copy when they already are) and its template."""
    vertices = np.ascontiguousarray(anim.vertices, dtype=np.float32)
    template = np.ascontiguousarray(anim.template, dtype=np.float32)
    if vertices.ndim != 3 or vertices.shape[1:] != template.shape or vertices.shape[0] == 0:
        raise FacegenError(f"animation vertices {list(vertices.shape)} do not match the template "
                           f"{list(template.shape)}")
    if not (np.isfinite(vertices).all() and np.isfinite(template).all()):
        raise FacegenError("the animation has NaN or infinite vertex coordinates: nothing sensible can be "
                           "stored")
    return vertices, template


def _principal_components(
    flat: np.ndarray, shift: np.ndarray, moving: np.ndarray, rank: int, rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """(temporal [T, r] orthonormal, coefficients [r, 3V]) with flat - shift ~= temporal @ coefficients,
    components ordered by decreasing singular value. The offsets flat - shift are never materialised; the
    coefficients of a coordinate that never moves (`moving` False) are exactly zero (the products leave float
    rounding there), so targets and rest leave it where the template has it."""
    T = flat.shape[0]
    ones = np.ones(T, np.float32)
    if rank >= T:
        basis = np.eye(T, dtype=np.float32)  # the full column space: exact
    else:
        probe = rng.random((flat.shape[1], rank), dtype=np.float32)  # uniform: 4x faster to draw than normal
        probe -= 0.5
        sample = flat @ probe
        sample -= np.outer(ones, shift @ probe)
        basis, _ = np.linalg.qr(sample)
    small = basis.T @ flat  # [r, 3V]
    small -= np.outer(basis.T @ ones, shift)
    small[:, ~moving] = 0.0
    gram = (small @ small.T).astype(np.float64)
    values, vectors = np.linalg.eigh(gram)
    order = np.argsort(values)[::-1]
    keep = order[values[order] > values.max() * 1e-12] if values.max() > 0 else order[:1]
    vectors = vectors[:, keep].astype(np.float32)
    return np.ascontiguousarray(basis @ vectors), vectors.T @ small


def _even_rows(T: int, n: int) -> np.ndarray:
    return np.unique(np.linspace(0, T - 1, n).round().astype(np.int64))


def _smallest_k(
    flat: np.ndarray, shift: np.ndarray, temporal: np.ndarray, coeffs: np.ndarray, low: int, high: int,
    bound: float, gallop: bool = False,
) -> int | None:
    """The fewest leading components (in low..high) whose error on these rows is within `bound`; None
    when even `high` is not. With `gallop`, K is expected near `low`: try low, low+1, low+3, ... first."""

    def ok(k: int) -> bool:
        return _max_error(flat, temporal[:, :k], coeffs[:k], shift) <= bound

    if gallop:
        step, k = 1, low
        while not ok(k):
            if k >= high:
                return None
            low, k, step = k + 1, min(high, k + step), 2 * step
        high = k
    elif not ok(high):
        return None
    while low < high:
        mid = (low + high) // 2
        if ok(mid):
            high = mid
        else:
            low = mid + 1
    return low


def _finish(
    flat: np.ndarray, shift: np.ndarray, temporal: np.ndarray, coeffs: np.ndarray, size: float,
    tolerance: float | None, unit_weights: bool,
) -> MorphBasis:
    """Store the first K components as float32 targets and weights and measure their real error."""
    weights = np.ascontiguousarray(temporal, dtype=np.float32)
    targets = np.ascontiguousarray(coeffs, dtype=np.float32)
    rest = np.zeros(flat.shape[1], np.float32)
    if unit_weights:
        low, high = weights.min(0), weights.max(0)
        span = high - low
        span[span <= 0] = 1.0
        rest = (low @ targets).astype(np.float32)
        targets = (targets * span[:, None]).astype(np.float32)
        weights = np.clip((weights - low) / span, 0.0, 1.0).astype(np.float32)
    else:  # scale so the largest |weight| of each target is 1 (targets then show the motion's extent)
        scale = np.abs(weights).max(0)
        scale[scale <= 0] = 1.0
        targets = (targets * scale[:, None]).astype(np.float32)
        weights = (weights / scale).astype(np.float32)
    K = targets.shape[0]
    return MorphBasis(
        targets=targets.reshape(K, -1, 3),
        weights=weights,
        rest=rest.reshape(-1, 3),
        max_error=_max_error(flat, weights, targets, rest + shift),
        size=size,
        tolerance=tolerance,
        names=[f"pca_{i:03d}" for i in range(K)],
    )


def _sparsify(basis: MorphBasis, flat: np.ndarray, shift: np.ndarray, budget: float) -> MorphBasis:
    """Zero, per vertex, the smallest target entries whose lengths sum to at most `budget` (with every
    |weight| <= 1 a dropped entry moves the vertex by at most its length), then measure the error."""
    if budget > 0 and basis.k:
        lengths = np.linalg.norm(basis.targets, axis=2)  # [K, V]
        ranks = np.argsort(np.argsort(lengths, axis=0, kind="stable"), axis=0, kind="stable")
        cumulative = np.cumsum(np.sort(lengths, axis=0), axis=0)
        dropped = (cumulative <= budget).sum(axis=0)  # per vertex: how many of its smallest entries go
        basis.targets[ranks < dropped[None, :]] = 0.0
    rest = (shift + basis.rest.reshape(-1)).astype(np.float32)
    basis.max_error = _max_error(flat, basis.weights, basis.targets.reshape(basis.k, -1), rest)
    return basis


def _max_error(flat: np.ndarray, weights: np.ndarray, targets: np.ndarray, rest: np.ndarray) -> float:
    """max over frames and vertices of |flat - (rest + weights @ targets)| per vertex, in cache-sized
    tiles."""
    T, width = flat.shape
    weights = np.ascontiguousarray(weights, dtype=np.float32)
    rows, cols = _TILE
    buf = np.empty((min(rows, T), min(cols, width)), np.float32)
    worst = 0.0
    for r0 in range(0, T, rows):
        r1 = min(r0 + rows, T)
        for c0 in range(0, width, cols):
            c1 = min(c0 + cols, width)
            block = buf[: r1 - r0, : c1 - c0]
            np.matmul(weights[r0:r1], targets[:, c0:c1], out=block)
            block += rest[c0:c1]
            np.subtract(flat[r0:r1, c0:c1], block, out=block)
            np.square(block, out=block)
            xyz = block.reshape(r1 - r0, -1, 3)
            worst = max(worst, float((xyz[:, :, 0] + xyz[:, :, 1] + xyz[:, :, 2]).max()))
    return float(np.sqrt(worst))
