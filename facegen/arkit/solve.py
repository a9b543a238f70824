"""The ARKit solver: per-frame weights of the 52 ARKit shapes that best reproduce an animation of facegen's face.

For frame offsets d_t (the frame minus the template) and shape offsets S ([3V, 52], `Shapes.offsets`), the
weights W ([T, 52]) minimise

    sum_t ||S w_t - d_t||^2 / V  +  smoothness * sum_t ||w_t - w_{t-1}||^2      subject to 0 <= W <= 1

(the data term in mm^2 per vertex, so `smoothness` means the same on any mesh scale or vertex count). The
frames only enter through G = S^T S (52 x 52) and B = D S (T x 52), accumulated block by block, so a streamed
animation is never held whole. The bounded problem is solved by ADMM over all frames at once: its linear step
(G + rho I) W + smoothness L W = B + rho (Z - U), with L the temporal Laplacian, is diagonal after an
eigendecomposition of G (over shapes) and a DCT-II (over time), so one iteration costs O(T 52^2); the
projection is a clip to [0, 1]. The fit's errors (mean per-vertex distance between the posed weights and the
animation, on the lips and on the whole face) take a second pass over the frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.fft import dct, idct
from threadpoolctl import threadpool_limits

from facegen.animation import Animation, check_animation
from facegen.arkit.shapes import Shapes, arkit_shapes
from facegen.errors import FacegenError

DEFAULT_SMOOTHNESS = 0.01  # mm^2 per vertex that a full-range weight step between frames costs
RELAXATION = 1.6  # ADMM over-relaxation (1.5-1.8 usually halves the iterations)
BLOCK_FRAMES = 256  # frames per block when reading an animation (bounds the memory of both passes)


@dataclass(frozen=True)
class Fit:
    """ARKit weights of an animation: `weights` [T, 52] float32 in [0, 1] for `names` (ARKit's, in order) of
    `shapes`; the mean per-vertex reconstruction error over all frames on the lips and the whole face, in mm."""

    names: tuple[str, ...]
    weights: np.ndarray
    shapes: Shapes
    lip_error_mm: float
    face_error_mm: float


def fit_arkit(anim: Animation, smoothness: float = DEFAULT_SMOOTHNESS, *, shapes: Shapes | None = None) -> Fit:
    """The ARKit weights of `anim` (an animation of facegen's face, arrays or a stream); `shapes` defaults to
    the ARKit shapes built on the animation's template (a mesh without the rig's regions is a FacegenError)."""
    check_animation(anim)
    if not (np.isfinite(smoothness) and smoothness >= 0):
        raise FacegenError(f"ARKit fit smoothness must be a number >= 0, got {smoothness}")
    lips = anim.regions.get("lips")
    if lips is None or len(lips) == 0:
        raise FacegenError("the animation's template has no 'lips' region: use a template with facegen's regions")
    shapes = shapes if shapes is not None else arkit_shapes(anim.mesh)
    offsets = np.asarray(shapes.offsets, np.float32)
    if offsets.shape[1:] != (anim.num_vertices, 3):
        raise FacegenError(f"the ARKit shapes have {offsets.shape[1]} vertices but the animation has "
                           f"{anim.num_vertices}: fit an animation of the shapes' face")
    basis = offsets.reshape(len(offsets), -1)  # [K, 3V] in mesh units
    scale = 1.0 / (anim.num_vertices * shapes.mm**2)  # mesh units^2 summed over vertices -> mm^2 per vertex
    gram = basis.astype(np.float64) @ basis.T.astype(np.float64) * scale
    rest = np.asarray(anim.template, np.float32).reshape(-1)
    rhs = np.empty((anim.num_frames, len(basis)), np.float64)
    for start, block in anim.frame_blocks(BLOCK_FRAMES):
        rhs[start : start + len(block)] = (block.reshape(len(block), -1) - rest) @ basis.T * scale
    with threadpool_limits(1, user_api="blas"):  # many small products: threads only add waiting
        weights = solve_weights(gram, rhs, smoothness).astype(np.float32)
    lip_error, face_error = fit_errors(anim, basis, weights, np.asarray(lips, np.int64))
    return Fit(tuple(shapes.names), weights, shapes, lip_error / shapes.mm, face_error / shapes.mm)


def solve_weights(gram: np.ndarray, rhs: np.ndarray, smoothness: float = 0.0, *, tol: float = 1e-6,
                  max_iter: int = 10000) -> np.ndarray:
    """W [T, K] in [0, 1] minimising sum_t (w_t G w_t - 2 w_t b_t) + smoothness sum_t ||w_t - w_{t-1}||^2
    for G = `gram` [K, K] (symmetric, positive semi-definite) and the rows b_t of `rhs` [T, K]: ADMM with the
    linear step diagonalised by eig(G) and the DCT-II over time, the penalty rho balanced on the residuals;
    stops when the primal and dual residuals are below `tol` per entry (relative terms included)."""
    frames, k = rhs.shape
    lam, q = np.linalg.eigh(np.asarray(gram, np.float64))
    lam = np.maximum(lam, 0.0)
    laplace = smoothness * (2.0 - 2.0 * np.cos(np.pi * np.arange(frames) / frames))[:, None]  # Neumann L

    def to_modes(x: np.ndarray) -> np.ndarray:
        return dct(x, type=2, norm="ortho", axis=0) @ q

    def from_modes(x: np.ndarray) -> np.ndarray:
        return idct(x @ q.T, type=2, norm="ortho", axis=0)

    rhs_modes = to_modes(np.asarray(rhs, np.float64))
    rho = max(float(np.sqrt(lam.max() * max(lam.min(), 1e-6 * lam.max()))), 1e-12) if lam.max() > 0 else 1.0
    z = np.zeros((frames, k))
    u = np.zeros((frames, k))
    size = np.sqrt(z.size)
    for _ in range(max_iter):
        w = from_modes((rhs_modes + rho * to_modes(z - u)) / (lam + rho + laplace))
        z_old = z
        relaxed = RELAXATION * w + (1.0 - RELAXATION) * z_old
        z = np.clip(relaxed + u, 0.0, 1.0)
        u += relaxed - z
        primal = np.linalg.norm(w - z)
        dual = rho * np.linalg.norm(z - z_old)
        if (primal <= tol * (size + max(np.linalg.norm(w), np.linalg.norm(z)))
                and dual <= tol * (size + rho * np.linalg.norm(u))):
            break
        if primal > 10 * dual:  # residual balancing: the linear step's denominator is rebuilt for free
            rho *= 2.0
            u /= 2.0
        elif dual > 10 * primal:
            rho /= 2.0
            u *= 2.0
    return z


def fit_errors(anim: Animation, basis: np.ndarray, weights: np.ndarray, lips: np.ndarray) -> tuple[float, float]:
    """Mean per-vertex distance (mesh units) between the posed weights (`basis` [K, 3V] in mesh units) and the
    animation over all frames: on the `lips` vertices and on the whole face."""
    rest = np.asarray(anim.template, np.float32)
    lip_sum = face_sum = 0.0
    for start, block in anim.frame_blocks(BLOCK_FRAMES):
        posed = (weights[start : start + len(block)] @ basis).reshape(block.shape)
        dist = np.linalg.norm(posed + rest - block, axis=2)
        lip_sum += float(dist[:, lips].sum(dtype=np.float64))
        face_sum += float(dist.sum(dtype=np.float64))
    return lip_sum / (anim.num_frames * len(lips)), face_sum / (anim.num_frames * anim.num_vertices)
