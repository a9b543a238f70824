"""Build small but real model bundles for tests (random weights that move the face)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from facegen.audio import FeatureConfig, mel_filters
from facegen.bundle import Bundle, save_bundle
from facegen.mesh import Mesh
from facegen.model import FaceModel, ModelConfig


def make_bundle(template: Mesh, path: Path | None = None, *, speakers=("F2", "F3", "M3"),
                text_backend: str = "minilm", text_dim: int = 384, modalities: str = "both",
                fusion: str = "tensor", seed: int = 0, scale: float = 0.002, small: bool = True) -> Bundle:
    """A bundle with random weights; the output layer scaled so offsets are a few mm-ish of motion."""
    torch.manual_seed(seed)
    dims = {"audio_dim": 16, "text_hidden": 16, "text_dim_out": 8, "decoder_dim": 16, "lstm_dim": 16} if small else {}
    cfg = ModelConfig(num_vertices=template.num_vertices, num_speakers=len(speakers), text_dim=text_dim,
                      modalities=modalities, fusion=fusion, **dims)
    model = FaceModel(cfg)
    with torch.no_grad():
        torch.nn.init.normal_(model.fc_out.weight, std=scale)
        model.mel_mean.fill_(-50.0)
        model.mel_std.fill_(20.0)
    feats = FeatureConfig()
    bundle = Bundle(model=model.eval(), features=feats, mel_filters=mel_filters(feats),
                    text_backend=text_backend if model.cfg.uses_text else "none", speakers=list(speakers),
                    template=template, provenance={"data": "random test weights"})
    if path is not None:
        save_bundle(bundle, path)
        bundle.path = Path(path)
    return bundle


def grid_face(nx: int = 20, ny: int = 10, height: float = 0.5, bend: float = 2.5) -> Mesh:
    """A curved nx x ny grid standing in for a face (Y up, facing +Z): the bottom three rows are the lips,
    the top three the upper face."""
    xs, ys = np.meshgrid(np.linspace(-0.5, 0.5, nx), np.linspace(-height / 2, height / 2, ny))
    z = 0.1 * np.cos(xs * bend) * np.cos(ys * bend)
    vertices = np.stack([xs, ys, z], -1).reshape(-1, 3).astype(np.float32)
    faces = []
    for j in range(ny - 1):
        for i in range(nx - 1):
            a, b, c, d = j * nx + i, j * nx + i + 1, (j + 1) * nx + i, (j + 1) * nx + i + 1
            faces += [[a, b, d], [a, d, c]]
    idx = np.arange(nx * ny)
    return Mesh(vertices, np.asarray(faces, np.int32), {"lips": idx[: nx * 3], "upper_face": idx[-nx * 3:]})
