"""Shared test fixtures: the real BIWI template (when ../shared is present), small meshes, small bundles."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("TRANSFORMERS_OFFLINE", "1")

REPO = Path(__file__).resolve().parents[1]
BIWI_DIR = REPO.parent / "shared" / "biwi"


@pytest.fixture(scope="session")
def biwi_template():
    """The real BIWI template mesh with its lip and upper-face regions (skips when absent)."""
    if not (BIWI_DIR / "BIWI.ply").is_file():
        pytest.skip("../shared/biwi is not present")
    from facegen.mesh import read_mesh, read_region

    mesh = read_mesh(BIWI_DIR / "BIWI.ply")
    mesh.regions = {"lips": read_region(BIWI_DIR / "lve.txt"), "upper_face": read_region(BIWI_DIR / "fdd.txt")}
    return mesh


@pytest.fixture(scope="session")
def grid_mesh():
    """A small 12 x 10 grid face stand-in (120 vertices), Y up, facing +Z."""
    from facegen.mesh import Mesh

    nx, ny = 12, 10
    xs, ys = np.meshgrid(np.linspace(-0.5, 0.5, nx), np.linspace(-0.4, 0.4, ny))
    z = 0.1 * np.cos(xs * 2) * np.cos(ys * 2)
    vertices = np.stack([xs, ys, z], -1).reshape(-1, 3).astype(np.float32)
    faces = []
    for j in range(ny - 1):
        for i in range(nx - 1):
            a, b, c, d = j * nx + i, j * nx + i + 1, (j + 1) * nx + i, (j + 1) * nx + i + 1
            faces += [[a, b, d], [a, d, c]]
    idx = np.arange(nx * ny)
    regions = {"lips": idx[: nx * 3], "upper_face": idx[-nx * 3:]}
    return Mesh(vertices, np.asarray(faces, np.int32), regions)
