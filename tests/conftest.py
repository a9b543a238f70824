"""Shared test fixtures: the real BIWI template (when ../shared is present), small meshes, small bundles."""

from __future__ import annotations

import os
from pathlib import Path

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
    from facegen.face.mesh import read_mesh, read_region

    mesh = read_mesh(BIWI_DIR / "BIWI.ply")
    mesh.regions = {"lips": read_region(BIWI_DIR / "lve.txt"),
                    "upper_face": read_region(BIWI_DIR / "fdd.txt")}
    return mesh


@pytest.fixture(scope="session")
def grid_mesh():
    """A small 12 x 10 grid face stand-in (120 vertices), Y up, facing +Z."""
    from helpers import grid_face

    return grid_face(12, 10, height=0.8, bend=2.0)
