"""The PCA basis of the training motion, and losses computed in it (training with `--output pca`).

The output layer FC 3V of the paper maps 256 decoder states to 70,110 vertex coordinates per frame; most of
a training step's time and memory go there and to the 70,110-wide loss. Trained instead as
offsets = B c + m, with B [3V, K] the first K principal directions of the training offsets (orthonormal
columns) and m their mean, the layer is exactly the paper's at rank K (facegen.model: `folded`), and since
||B (c - c*)||² = ||c - c*||², the vertex MSE is the coefficient MSE (up to the constant error of projecting
the targets): the loss never needs the 70,110 numbers. Lip- and upper-face-weighted and velocity terms stay
exact in K dimensions too (`CoefficientLoss`), as does the lips' term of the text-free pass
(`CoefficientLoss.lips`, `--text-free-lips`).
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence

import numpy as np
import torch

from facegen.errors import FacegenError

MAX_FRAMES = 6000  # frames sampled for the basis (6,000 x 70,110 float32 = 1.7 GB)


def offsets(item, frames: slice | None = None) -> np.ndarray:
    """A dataset item's motion (or the `frames` of it) as offsets from its subject's template, [T, 3V]
    float32. Rig-curve sequences pose only the frames asked for."""
    if frames is not None and item.seq.curves is not None and item.pose is not None:
        curves = np.load(item.seq.curves)[: item.num_frames][frames]
        v = item.pose(curves).reshape(len(curves), -1).astype(np.float32, copy=False)
    else:
        v = item.vertices()
        v = v[frames] if frames is not None else v
    v -= item.template.reshape(-1)
    return v


def fit_basis(items: Sequence, k: int, *, seed: int = 0, max_frames: int = MAX_FRAMES) -> tuple[np.ndarray,
                                                                                                 np.ndarray,
                                                                                                float]:
    """(basis [3V, K] float32 with orthonormal columns, mean [3V] float32, share of the motion's variance it
    keeps) from up to `max_frames` frames spread evenly over the training `items`."""
    total = sum(it.num_frames for it in items)
    if k < 1 or k > min(total, max_frames) - 1:
        raise FacegenError(f"a basis of {k} needs more training frames than there are ({total}, at most "
                           f"{max_frames} used): choose a basis of at most {min(total, max_frames) - 1}",
                           param="basis")
    step = max(1, int(np.ceil(total / max_frames)))
    rng = np.random.default_rng(seed)
    rows = []
    for it in items:
        rows.append(offsets(it, slice(int(rng.integers(step)) % it.num_frames, None, step)))
    x = np.concatenate(rows)[:max_frames]
    mean = x.mean(0)
    x -= mean
    torch.manual_seed(seed)
    _, s, v = torch.svd_lowrank(torch.from_numpy(x), q=min(k + 16, min(x.shape)), niter=4)
    basis = v[:, :k].numpy().astype(np.float32)
    total_variance = sum(float(np.dot(row, row)) for row in x)
    kept = float((s[:k].double() ** 2).sum()) / max(total_variance, 1e-30)
    return basis, mean.astype(np.float32), kept


def basis_digest(basis: np.ndarray, mean: np.ndarray) -> str:
    h = hashlib.sha256(np.ascontiguousarray(basis).tobytes())
    h.update(np.ascontiguousarray(mean).tobytes())
    return h.hexdigest()[:16]


def project(item, basis: np.ndarray, mean: np.ndarray) -> np.ndarray:
    """The item's motion in the basis: coefficients [T, K] float32."""
    return ((offsets(item) - mean) @ basis).astype(np.float32)


class CoefficientLoss:
    """MSE over all vertex coordinates (+ `lip_weight` x MSE over the lip vertices' coordinates,
    + `upper_weight` x MSE over the upper face's, + `velocity_weight` x MSE of the frame-to-frame motion),
    computed exactly in the K coefficients."""

    def __init__(self, basis: np.ndarray, lips: np.ndarray | None, lip_weight: float = 0.0,
                 velocity_weight: float = 0.0, device: torch.device | str = "cpu", *,
                 upper: np.ndarray | None = None, upper_weight: float = 0.0,
                 text_free_weight: float = 0.0) -> None:
        self.coords = basis.shape[0]
        self.velocity_weight = float(velocity_weight)
        self.text_free_weight = float(text_free_weight)
        self.regions = []  # (weight, basis rows of the region's coordinates)
        self.lip_rows = None
        if lip_weight > 0 or text_free_weight > 0:
            option = "lip_weight" if lip_weight > 0 else "text_free_lips"
            self.lip_rows = _rows(basis, lips, option, "lip region (regions/lve.txt)", device)
        if lip_weight > 0:
            self.regions.append((float(lip_weight), self.lip_rows))
        if upper_weight > 0:
            self.regions.append((float(upper_weight), _rows(basis, upper, "upper_weight",
                                                            "upper-face region (regions/fdd.txt)", device)))

    def __call__(self, pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """pred, target [T, K] coefficients."""
        err = pred - target
        loss = err.square().sum(-1).mean() / self.coords
        for weight, rows in self.regions:
            loss = loss + weight * (err @ rows.T).square().mean()
        if self.velocity_weight > 0 and len(err) > 1:
            loss = loss + self.velocity_weight * (err[1:] - err[:-1]).square().sum(-1).mean() / self.coords
        return loss

    def lips(self, pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """The MSE over the lip vertices' coordinates of pred, target [T, K] coefficients."""
        return ((pred - target) @ self.lip_rows.T).square().mean()


def _rows(basis: np.ndarray, vertices: np.ndarray | None, option: str, region: str, device) -> torch.Tensor:
    """The basis rows of the region's vertex coordinates, [3R, K]."""
    if vertices is None or len(vertices) == 0:
        raise FacegenError(f"a {option.replace('_', ' ')} needs the dataset's {region}", param=option)
    rows = (np.asarray(vertices)[:, None] * 3 + np.arange(3)[None]).reshape(-1)
    return torch.from_numpy(np.ascontiguousarray(basis[rows])).to(device)
