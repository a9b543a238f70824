"""The ARKit solver: per-frame weights of the 52 ARKit shapes that best reproduce an animation of facegen's
face.

For frame offsets d_t (the frame minus the template) and shape offsets S ([3V, 52], `Shapes.offsets`), the
weights W ([T, 52]) minimise

    sum_t ||S w_t - d_t||^2 / V  +  smoothness * sum_t ||w_t - w_{t-1}||^2
        +  ridge * sum_t sum_k ||S_k||^2 w_tk^2 / V

subject to 0 <= W <= 1 (the data term in mm^2 per vertex, so `smoothness` means the same on any mesh scale or
vertex count). S also holds `Shapes.hidden`, the rig's motion no ARKit shape holds (its jaw turns on an arc,
jawOpen moves on a line): the fit solves for their weights and drops them, and the errors are those of the
52 weights alone. The small ridge, relative to each shape's own size, decides where shapes cancel each other
(jawLeft + jawRight, mouthLeft + mouthRight move nothing on a symmetric face): the smallest weights win. The
frames only enter through G = S^T S (52 x 52) and B = D S (T x 52), accumulated block by block, so a streamed
animation is never held whole. The bounded problem is solved by ADMM over all frames at once: its linear step
(G + rho I) W + smoothness L W = B + rho (Z - U), with L the temporal Laplacian, is diagonal after an
eigendecomposition of G (over shapes) and a DCT-II (over time), so one iteration costs O(T 52^2); the
projection is a clip to [0, 1]. Its penalty rho follows the residuals (residual balancing, Boyd et al. 2011,
3.4.1): the shapes' curvatures span four decades, and with a fixed rho the primal residual shrank so slowly
that every clip ran the 5,000 iterations allowed, still 0.01 from the optimum; balanced, a clip converges in
about 400.
Long clips are solved in overlapping blocks of SOLVE_FRAMES (`solve_weights`): the smoothness couples a
frame to its neighbours, but its pull fades by over a million times within SOLVE_MARGIN frames, so each block
is solved with that many frames of context on either side and keeps its middle. Time and memory per block
stay the same however long the clip.
The frames of a stream (inference.FrameStream) are never computed for B: the output layer is affine, so B
comes from the decoder states (`FrameStream.project`). The fit's errors (mean per-vertex distance between the
posed weights and the animation, on the lips and on the whole face) take one pass over the frames, over
ERROR_FRAMES_MEASURED evenly spread ones in a longer clip (computing every frame of two hours is 6.5 TFLOP).
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from scipy.fft import dct, idct

from facegen.animation import Animation, check_animation
from facegen.arkit.shapes import Shapes, arkit_shapes
from facegen.errors import FacegenError
from facegen.inference import FrameStream
from facegen.runtime import threads

DEFAULT_SMOOTHNESS = 0.01  # mm^2 per vertex that a full-range weight step between frames costs
RIDGE = 1e-5  # x each shape's own curvature: breaks exact ties only (jawLeft + jawRight cancel on the face)
RELAXATION = 1.6  # ADMM over-relaxation (1.5-1.8 usually halves the iterations)
CHECK_EVERY = 10  # iterations between two convergence tests (the norms cost as much as an iteration)
BALANCE_EVERY = 50  # iterations between two updates of rho (each needs the residuals of a test)
BALANCE = 2.0  # rho doubles (halves) when the primal residual is this many times the dual one (or less):
# 2 rather than the textbook 10 (the residuals of the ARKit fit often settle within a factor of 10, converging
# slowly: 4,500 iterations on a test problem against 920; the fit of a real clip takes ~480 either way)
SOLVE_FRAMES = 3000  # frames solved together (2 minutes at 25 fps); longer clips in overlapping blocks
SOLVE_MARGIN = 300  # frames of context on either side of a block (the coupling fades as 0.94^frames at worst)
BLOCK_FRAMES = 256  # frames per block when reading an animation (bounds the memory of both passes)
ERROR_FRAMES = 16  # frames per step of the error pass
ERROR_FRAMES_MEASURED = 15000  # a longer clip's errors: on this many evenly spread frames (10 minutes)
# ARKit tongueOut when the tongue's tip is fully forward (facegen.tongue's tipForward 1: a th, the tip between
# the teeth); tongueOut 1 is the tongue stuck out past the lips, a th shows half as much
TONGUE_OUT = 0.5


@dataclass(frozen=True)
class Fit:
    """ARKit weights of an animation: `weights` [T, 52] float32 in [0, 1] for `names` (ARKit's, in order) of
    `shapes`; the mean per-vertex reconstruction error over all frames on the lips and the whole face, in
    mm."""

    names: tuple[str, ...]
    weights: np.ndarray
    shapes: Shapes
    lip_error_mm: float
    face_error_mm: float


def fit_arkit(anim: Animation, smoothness: float = DEFAULT_SMOOTHNESS, *,
              shapes: Shapes | None = None) -> Fit:
    """The ARKit weights of `anim` (an animation of facegen's face, arrays or a stream); `shapes` defaults to
    the ARKit shapes built on the animation's template (a mesh without the rig's regions is a
    FacegenError)."""
    check_animation(anim)
    if not (np.isfinite(smoothness) and smoothness >= 0):
        raise FacegenError(f"ARKit fit smoothness must be a number >= 0, got {smoothness}")
    shapes = shapes if shapes is not None else arkit_shapes(anim.mesh)
    lips = anim.regions.get("lips")
    if lips is None or len(lips) == 0:
        raise FacegenError("the animation's template has no 'lips' region: use a template with facegen's "
                           "regions")
    offsets = np.asarray(shapes.offsets, np.float32)
    if offsets.shape[1:] != (anim.num_vertices, 3):
        raise FacegenError(f"the ARKit shapes have {offsets.shape[1]} vertices but the animation has "
                           f"{anim.num_vertices}: fit an animation of the shapes' face")
    # [K + 2H, 3V] in mesh units: the 52 shapes, then the hidden ones with either sign (the weights are >= 0),
    # solved for and dropped
    hidden = np.asarray(shapes.hidden, np.float32)
    basis = np.concatenate([offsets, hidden, -hidden]).reshape(-1, offsets[0].size)
    scale = 1.0 / (anim.num_vertices * shapes.mm**2)  # mesh units^2 summed over vertices -> mm^2 per vertex
    rest = np.asarray(anim.template, np.float32).reshape(-1)
    with threads(1, ("blas",)):
        gram = (basis @ basis.T).astype(np.float64) * scale
        if isinstance(anim.vertices, FrameStream):  # from the decoder states: no frame computed
            rhs = anim.vertices.project(basis, rest) * scale
        else:
            rhs = np.empty((anim.num_frames, len(basis)), np.float64)
            for start, block in anim.frame_blocks(BLOCK_FRAMES):
                rhs[start : start + len(block)] = (block.reshape(len(block), -1) - rest) @ basis.T * scale
        weights = np.ascontiguousarray(solve_weights(gram, rhs, smoothness, ridge=RIDGE)[:, : len(offsets)],
                                       np.float32)
        basis = basis[: len(offsets)]  # the errors are those of the 52 weights, as an ARKit rig poses them
        set_tongue_out(weights, shapes.names, anim)
        every = -(-anim.num_frames // ERROR_FRAMES_MEASURED)
        lip_error, face_error = fit_errors(anim, _every(anim, every), basis, weights[::every],
                                           np.asarray(lips, np.int64))
    return Fit(tuple(shapes.names), weights, shapes, lip_error / shapes.mm, face_error / shapes.mm)


def set_tongue_out(weights: np.ndarray, names: tuple[str, ...], anim: Animation) -> None:
    """Set the tongueOut column of `weights` [T, K] (`names`) from the animation's tongue: TONGUE_OUT x its
    tipForward weight (facegen.tongue, from the phones). The face has no tongue, so the fit cannot see it
    (its tongueOut shape is the lower lip a tongue pushes out, which the solve leaves near 0); without
    `anim.parts` (a file read back: no phones) the fit's value stays."""
    if anim.parts is None or "tongueOut" not in names:
        return
    forward = np.asarray(anim.parts.tongue, np.float32)[:, 1]  # one row per frame (layers.py)
    weights[:, names.index("tongueOut")] = np.clip(TONGUE_OUT * forward, 0.0, 1.0)


def solve_weights(gram: np.ndarray, rhs: np.ndarray, smoothness: float = 0.0, *, ridge: float = 0.0,
                  tol: float = 3e-6, max_iter: int = 5000, block_frames: int = SOLVE_FRAMES,
                  margin: int = SOLVE_MARGIN) -> np.ndarray:
    """W [T, K] in [0, 1] minimising sum_t (w_t H w_t - 2 w_t b_t) + smoothness sum_t ||w_t - w_{t-1}||^2
    with H = G + ridge diag(G) for G = `gram` [K, K] (symmetric, positive semi-definite) and the rows b_t of
    `rhs` [T, K]. More than `block_frames` frames are solved in blocks of about that many, each with `margin`
    frames of context on either side (see the module docstring); each block by `admm`."""
    with threads(1, ("blas",)):  # small products, many of them: on a busy machine threads only add waiting
        return _solve_blocks(np.asarray(gram, np.float64), rhs, smoothness, ridge, tol, max_iter,
                             block_frames, margin)


def _solve_blocks(gram: np.ndarray, rhs: np.ndarray, smoothness: float, ridge: float, tol: float,
                  max_iter: int, block_frames: int, margin: int) -> np.ndarray:
    frames, k = rhs.shape
    curvature = np.diag(gram)
    lam, q = np.linalg.eigh(gram + ridge * np.diag(curvature))
    rho = float(curvature[curvature > 0].min()) if (curvature > 0).any() else 1.0
    system = (np.maximum(lam, 0.0), q, rho)
    count = -(-frames // block_frames) if frames > block_frames else 1
    if count == 1:
        return admm(system, np.asarray(rhs, np.float64), smoothness, tol, max_iter)
    weights = np.empty((frames, k))
    cuts = np.linspace(0, frames, count + 1).round().astype(int)
    for start, stop in itertools.pairwise(cuts):
        lo, hi = max(0, start - margin), min(frames, stop + margin)
        block = admm(system, np.asarray(rhs[lo:hi], np.float64), smoothness, tol, max_iter)
        weights[start:stop] = block[start - lo : stop - lo]
    return weights


def admm(system: tuple[np.ndarray, np.ndarray, float], rhs: np.ndarray, smoothness: float, tol: float,
         max_iter: int) -> np.ndarray:
    """The bounded problem of `solve_weights` over `rhs` [T, K] by ADMM: the linear step diagonalised by
    eig(H) = (lam, q) and the DCT-II over time, the projection a clip, over-relaxed. rho starts at the given
    value (the smallest shape's curvature) and is balanced against the residuals every BALANCE_EVERY
    iterations. Stops when the primal and dual residuals are below `tol` per entry."""
    lam, q, rho = system
    frames, k = rhs.shape
    laplace = smoothness * (2.0 - 2.0 * np.cos(np.pi * np.arange(frames) / frames))[:, None]  # Neumann L

    def to_modes(x: np.ndarray) -> np.ndarray:
        return dct(x, type=2, norm="ortho", axis=0) @ q

    def from_modes(x: np.ndarray) -> np.ndarray:
        return idct(x @ q.T, type=2, norm="ortho", axis=0)

    rhs_modes = to_modes(rhs)
    denominator = lam + rho + laplace
    z = np.zeros((frames, k))
    u = np.zeros((frames, k))
    size = np.sqrt(z.size)
    for step in range(max_iter):
        w = from_modes((rhs_modes + rho * to_modes(z - u)) / denominator)
        z_old = z
        relaxed = RELAXATION * w + (1.0 - RELAXATION) * z_old
        z = np.clip(relaxed + u, 0.0, 1.0)
        u += relaxed - z
        if step % CHECK_EVERY:
            continue
        primal = _norm(w - z) / (size + max(_norm(w), _norm(z)))
        dual = rho * _norm(z - z_old) / (size + rho * _norm(u))
        if primal <= tol and dual <= tol:
            break
        if step % BALANCE_EVERY == 0 and max(primal, dual) > BALANCE * min(primal, dual):
            factor = 2.0 if primal > dual else 0.5
            rho *= factor
            u /= factor  # the scaled dual variable follows rho
            denominator = lam + rho + laplace
    return z


def _norm(x: np.ndarray) -> float:
    return float(np.sqrt(np.vdot(x, x)))


def _every(anim: Animation, every: int) -> Iterable[tuple[int, np.ndarray]]:
    """Every `every`-th frame of `anim` as (first, block) pairs numbered among them (all frames when 1)."""
    if every == 1:
        return anim.frame_blocks(BLOCK_FRAMES)
    if isinstance(anim.vertices, FrameStream):
        return anim.vertices.every(every).blocks(BLOCK_FRAMES)
    frames = anim.vertices[::every]
    return ((s, np.asarray(frames[s:s + BLOCK_FRAMES], np.float32))
            for s in range(0, len(frames), BLOCK_FRAMES))


def fit_errors(anim: Animation, blocks: Iterable[tuple[int, np.ndarray]], basis: np.ndarray,
               weights: np.ndarray,
               lips: np.ndarray) -> tuple[float, float]:
    """Mean per-vertex distance (mesh units) between the posed weights (`basis` [K, 3V] in mesh units) and the
    animation's frames (`blocks` as `anim.frame_blocks()` yields them; `weights`: those frames' weights) over
    the frames given: on the `lips` vertices and on the whole face."""
    rest = np.asarray(anim.template, np.float32).reshape(-1)
    lip_sum = face_sum = 0.0
    count = 0
    for start, block in blocks:
        count += len(block)
        # a few frames at a time: the residual stays in cache
        for first in range(0, len(block), ERROR_FRAMES):
            frames = block[first : first + ERROR_FRAMES]
            residual = weights[start + first : start + first + len(frames)] @ basis
            residual += rest
            residual -= frames.reshape(len(frames), -1)
            residual = residual.reshape(frames.shape)
            dist = np.sqrt(np.einsum("tvc,tvc->tv", residual, residual))
            lip_sum += float(dist[:, lips].sum(dtype=np.float64))
            face_sum += float(dist.sum(dtype=np.float64))
        block = frames = None  # released before the next block is made: one block of frames alive, not two
    return lip_sum / (max(count, 1) * len(lips)), face_sum / (max(count, 1) * anim.num_vertices)
