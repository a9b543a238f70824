"""Real DCC import: Blender (PyPI bpy 5.0 in .venv-blender, made by `make blender-venv`) opens every format
facegen writes through the shipped helper facegen/blender/facegen_import.py, in a subprocess running
tests/blender_check.py.

For each file: one mesh of the clip's vertex count, scene fps = the clip's, frame range 0..T-1, the
animation spanning it, evaluated positions at the first, middle and last frame equal to what was written
within 1e-4 of the face's size (in the file's Y-up units: Blender's Z-up meters mapped back), and a sound
strip of the WAV (beside the file, or inside the .usdz) from frame 0 lasting T frames.

Outside CI the test skips when .venv-blender is missing; in CI (CI=true) it must run.
Adding a format is one entry in FORMATS.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import rig_clip

from facegen.exchange import read_animation, write_animation

REPO = Path(__file__).resolve().parents[1]
BLENDER_PYTHON = REPO / ".venv-blender" / "bin" / "python"
CHECK = Path(__file__).resolve().parent / "blender_check.py"
FRAMES = 60
TOLERANCE = 1e-4  # of the face's size

# (suffix, writer options, what Blender must show: "source" = the clip itself, "file" = what the file
# stores, i.e. glTF's PCA reconstruction, itself within the stated tolerance of the clip)
FORMATS = [
    pytest.param(".usda", {}, "source", id="usda"),
    pytest.param(".usdc", {}, "source", id="usdc"),
    pytest.param(".usdz", {}, "source", id="usdz"),
    pytest.param(".usdc", {"mode": "blendshapes"}, "file", id="usdc-blendshapes"),
    pytest.param(".glb", {"morph_targets": "all"}, "source", id="glb"),
    pytest.param(".gltf", {"morph_targets": "all"}, "source", id="gltf"),
    pytest.param(".glb", {}, "file", id="glb-pca"),
]


@pytest.fixture(scope="module")
def blender_python() -> Path:
    if not BLENDER_PYTHON.is_file():
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(f"{BLENDER_PYTHON} is missing in CI: `make test` runs `make blender-venv` first")
        pytest.skip(f"{BLENDER_PYTHON} is missing: run `make blender-venv` to test the Blender import")
    return BLENDER_PYTHON


@pytest.fixture(scope="module")
def clip():
    return rig_clip(FRAMES, seed=3)


@pytest.mark.parametrize("suffix, options, shows", FORMATS)
def test_blender_imports(blender_python, clip, tmp_path, suffix, options, shows):
    path = tmp_path / f"clip{suffix}"
    write_animation(clip, path, **options)
    expected = clip.vertices
    if shows == "file":  # a PCA basis: Blender must show what the file stores, which is near the clip
        expected = read_animation(path).vertices
        assert np.linalg.norm(expected - clip.vertices, axis=2).max() <= 1e-3 * clip.size
    positions = {}
    for frame in (0, FRAMES // 2, FRAMES - 1):
        positions[str(frame)] = str(tmp_path / f"frame{frame}.npy")
        np.save(positions[str(frame)], expected[frame].astype(np.float64))
    expect = {
        "vertices": clip.num_vertices, "frames": FRAMES, "fps": clip.fps, "meters_per_unit": 0.2,
        "tolerance": TOLERANCE * clip.size, "positions": positions, "sound_frames": FRAMES,
    }
    (tmp_path / "expect.json").write_text(json.dumps(expect))
    done = subprocess.run([str(blender_python), str(CHECK), str(path), "--expect-json", str(tmp_path / "expect.json")],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path, check=False)
    lines = [line for line in done.stdout.splitlines() if line.startswith("blender_check: ")]
    assert lines, f"blender_check printed no result (exit {done.returncode}):\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    result = json.loads(lines[-1].removeprefix("blender_check: "))
    failed = {name: c["detail"] for name, c in result["checks"].items() if not c["ok"]}
    assert not failed, f"{suffix} {options}: {failed}"
    assert set(result["checks"]) == {"vertices", "fps", "frame range", "animation", "positions", "sound"}
    assert done.returncode == 0
    sys.stdout.write(f"{path.name}: {result['checks']['positions']['detail']}\n")

