"""The ARKit solver: per-frame weights of the 52 ARKit shapes that best reproduce an animation of facegen's
face.

For frame offsets d_t (the frame minus the template) and shape offsets S ([3V, 52], `Shapes.offsets`), the
weights W ([T, 52]) minimise

    sum_t ||S w_t - d_t||^2 / V  +  smoothness * sum_t ||w_t - w_{t-1}||^2
        +  ridge * sum_t sum_k ||S_k||^2 w_tk^2 / V

subject to 0 <= W <= 1 (the data term in mm^2 per vertex, so `smoothness` means the same on any mesh scale or
vertex count). The small ridge, relative to each shape's own size, decides where shapes cancel each other
(jawLeft + jawRight, mouthLeft + mouthRight move nothing on a symmetric face): the smallest weights win. The
frames only enter through G = S^T S (52 x 52) and B = D S (T x 52), accumulated block by block, so a streamed
animation is never held whole. The bounded problem is solved by ADMM over all frames at once: its linear step
(G + rho I) W + smoothness L W = B + rho (Z - U), with L the temporal Laplacian, is diagonal after an
eigendecomposition of G (over shapes) and a DCT-II (over time), so one iteration costs O(T 52^2); the
projection is a clip to [0, 1]. The fit's errors (mean per-vertex distance between the posed weights and the
animation, on the lips and on the whole face) take a second pass over the frames.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from scipy.fft import dct, idct

from facegen.animation import Animation, check_animation
from facegen.arkit.shapes import Shapes, arkit_shapes
from facegen.errors import FacegenError
from facegen.runtime import threads

DEFAULT_SMOOTHNESS = 0.01  # mm^2 per vertex that a full-range weight step between frames costs
RIDGE = 1e-5  # x each shape's own curvature: breaks exact ties only (jawLeft + jawRight cancel on the face)
RELAXATION = 1.6  # ADMM over-relaxation (1.5-1.8 usually halves the iterations)
CHECK_EVERY = 10  # iterations between two convergence tests (the norms cost as much as an iteration)
BLOCK_FRAMES = 256  # frames per block when reading an animation (bounds the memory of both passes)
KEEP_BYTES = 256 << 20  # clips whose frames take at most this are read once (a stream computes them once)
ERROR_FRAMES = 16  # frames per step of the error pass


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
    basis = offsets.reshape(len(offsets), -1)  # [K, 3V] in mesh units
    scale = 1.0 / (anim.num_vertices * shapes.mm**2)  # mesh units^2 summed over vertices -> mm^2 per vertex
    rest = np.asarray(anim.template, np.float32).reshape(-1)
    rhs = np.empty((anim.num_frames, len(basis)), np.float64)
    with threads(1, ("blas",)):  # a busy machine: threads only add waiting
        gram = (basis @ basis.T).astype(np.float64) * scale
        # else the errors' pass reads them again
        keep = anim.num_frames * anim.num_vertices * 12 <= KEEP_BYTES
        kept = []
        for start, block in anim.frame_blocks(BLOCK_FRAMES):
            rhs[start : start + len(block)] = (block.reshape(len(block), -1) - rest) @ basis.T * scale
            kept += [(start, block)] if keep else []
        weights = solve_weights(gram, rhs, smoothness, ridge=RIDGE).astype(np.float32)
        blocks = kept if keep else anim.frame_blocks(BLOCK_FRAMES)
        lip_error, face_error = fit_errors(anim, blocks, basis, weights, np.asarray(lips, np.int64))
    return Fit(tuple(shapes.names), weights, shapes, lip_error / shapes.mm, face_error / shapes.mm)


def solve_weights(gram: np.ndarray, rhs: np.ndarray, smoothness: float = 0.0, *, ridge: float = 0.0,
                  tol: float = 3e-6, max_iter: int = 5000) -> np.ndarray:
    """W [T, K] in [0, 1] minimising sum_t (w_t H w_t - 2 w_t b_t) + smoothness sum_t ||w_t - w_{t-1}||^2
    with H = G + ridge diag(G) for G = `gram` [K, K] (symmetric, positive semi-definite) and the rows b_t of
    `rhs` [T, K]. ADMM: the linear step diagonalised by eig(H) and the DCT-II over time, the projection a
    clip, over-relaxed; rho is the smallest shape's curvature (measured best on the ARKit shapes, whose
    scales span four decades). Stops when the primal and dual residuals are below `tol` per entry."""
    frames, k = rhs.shape
    gram = np.asarray(gram, np.float64)
    curvature = np.diag(gram)
    lam, q = np.linalg.eigh(gram + ridge * np.diag(curvature))
    lam = np.maximum(lam, 0.0)
    laplace = smoothness * (2.0 - 2.0 * np.cos(np.pi * np.arange(frames) / frames))[:, None]  # Neumann L

    def to_modes(x: np.ndarray) -> np.ndarray:
        return dct(x, type=2, norm="ortho", axis=0) @ q

    def from_modes(x: np.ndarray) -> np.ndarray:
        return idct(x @ q.T, type=2, norm="ortho", axis=0)

    rhs_modes = to_modes(np.asarray(rhs, np.float64))
    rho = float(curvature[curvature > 0].min()) if (curvature > 0).any() else 1.0
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
        if step % CHECK_EVERY == 0 and (
                _norm(w - z) <= tol * (size + max(_norm(w), _norm(z)))
                and rho * _norm(z - z_old) <= tol * (size + rho * _norm(u))):
            break
    return z


def _norm(x: np.ndarray) -> float:
    return float(np.sqrt(np.vdot(x, x)))


def fit_errors(anim: Animation, blocks: Iterable[tuple[int, np.ndarray]], basis: np.ndarray,
               weights: np.ndarray,
               lips: np.ndarray) -> tuple[float, float]:
    """Mean per-vertex distance (mesh units) between the posed weights (`basis` [K, 3V] in mesh units) and the
    animation's frames (`blocks` as `anim.frame_blocks()` yields them) over all frames: on the `lips`
    vertices and on the whole face."""
    rest = np.asarray(anim.template, np.float32).reshape(-1)
    lip_sum = face_sum = 0.0
    for start, block in blocks:
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
    return lip_sum / (anim.num_frames * len(lips)), face_sum / (anim.num_frames * anim.num_vertices)
