"""The package-level library API: lazy (``import facegen`` loads no torch), and the names work together."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
from helpers import make_bundle

import facegen

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "excellent_room.wav"


def test_import_is_lazy():
    code = ("import sys, facegen; heavy = [m for m in ('torch', 'pxr', 'transformers', 'numpy') if m in "
            "sys.modules];print(','.join(heavy))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == ""
    assert set(facegen.__all__) >= {"animate", "load_bundle", "Animation", "read_animation",
                                    "write_animation"}


def test_animate_write_read_round_trip(tmp_path, grid_mesh):
    bundle = make_bundle(grid_mesh, tmp_path / "m.safetensors", modalities="audio")
    loaded = facegen.load_bundle(tmp_path / "m.safetensors")
    assert loaded.speakers == bundle.speakers
    anim = facegen.animate(EXAMPLE, no_text=True, speaker="F3", bundle=loaded)
    assert isinstance(anim, facegen.Animation)
    assert anim.vertices.shape == (round(anim.duration * 25), grid_mesh.num_vertices, 3)
    assert anim.metadata["speaker"] == "F3" and np.abs(anim.vertices - grid_mesh.vertices).max() > 0
    files = facegen.write_animation(anim, tmp_path / "clip.npy")
    assert files == [tmp_path / "clip.npy", tmp_path / "clip.wav"]
    back = facegen.read_animation(tmp_path / "clip.npy", template=grid_mesh)
    np.testing.assert_array_equal(back.vertices, anim.vertices)
