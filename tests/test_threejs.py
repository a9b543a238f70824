"""The three.js example (examples/threejs/arkit_player.js) in node with the real `three` package: a clip built
from an Audio2Face-layout JSON (written here by a small generator) drives the morph targets of a generated
avatar whose targets are named in mixed styles; the influences sampled through THREE.AnimationMixer equal the
JSON's weights (at frames, and linearly between them), the unmatched ARKit names are reported, a JSON that is
not ARKit-shaped is refused, and the module's name rule agrees with facegen.arkit.names.

Skips when node or the npm package three is missing (`make node-deps`); in CI (CI=true) it must run.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from facegen.arkit.names import ARKIT_NAMES, LIVE_LINK_COLUMNS, arkit_name

REPO = Path(__file__).resolve().parents[1]
PLAYER = REPO / "examples" / "threejs" / "arkit_player.js"
CHECK = Path(__file__).resolve().parent / "threejs_check.mjs"
MODULES = REPO / "facegen" / "assets" / "node_modules"
FPS = 25
FRAMES = 40

# the avatar's meshes and morph targets: several naming styles, a target not ARKit's, jawOpen on both meshes
MESHES = {"Head": ["jawOpen", "blendShape1.eyeBlinkLeft", "eyeBlink_R", "ARKit_mouthSmile_L",
                   "MouthSmileRight",
                   "Face:browInnerUp", "bs_cheekPuff", "wrinkle"],
          "Teeth": ["Wolf3D.jawOpen", "tongueOut"]}


@pytest.fixture(scope="module")
def node_folder(tmp_path_factory) -> Path:
    """A folder with the player module, the check script and node_modules (three) beside them."""
    if not (shutil.which("node") and (MODULES / "three" / "package.json").is_file()):
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail("node or the npm package three is missing in CI: `make node-deps` should have run")
        pytest.skip("node or the npm package three is missing: run `make node-deps`")
    folder = tmp_path_factory.mktemp("threejs")
    shutil.copy(PLAYER, folder / PLAYER.name)
    shutil.copy(CHECK, folder / CHECK.name)
    (folder / "node_modules").symlink_to(MODULES, target_is_directory=True)
    return folder


def arkit_weights(frames: int, seed: int = 0) -> np.ndarray:
    """[frames, 52] plausible ARKit weights in 0..1 (a talking jaw, blinks, smooth noise elsewhere)."""
    rng = np.random.default_rng(seed)
    weights = np.clip(0.2 + 0.2 * np.sin(np.cumsum(rng.normal(0, 0.05, (frames, 52)), axis=0)), 0, 1)
    weights[:, ARKIT_NAMES.index("jawOpen")] = 0.35 + 0.3 * np.sin(2 * np.pi * 4 * np.arange(frames) / FPS)
    weights[:, ARKIT_NAMES.index("eyeBlinkLeft")] = (np.arange(frames) % 20 < 3).astype(float)
    return weights.astype(np.float32)


def run_check(folder: Path, spec: dict) -> dict:
    (folder / "spec.json").write_text(json.dumps(spec))
    done = subprocess.run(["node", CHECK.name, "spec.json"], cwd=folder, capture_output=True, text=True,
                          timeout=120, check=False)
    lines = [line for line in done.stdout.splitlines() if line.startswith("threejs_check: ")]
    assert done.returncode == 0 and lines, (f"node failed (exit {done.returncode}):\n{done.stdout}\n"
                                            f"{done.stderr}")
    return json.loads(lines[-1].removeprefix("threejs_check: "))


def test_threejs_player_drives_arkit_named_morph_targets(node_folder):
    weights = arkit_weights(FRAMES)
    head = np.stack([5 * np.sin(np.arange(FRAMES) / 7), 3 * np.cos(np.arange(FRAMES) / 5),
                     2 * np.sin(np.arange(FRAMES) / 3)], 1)
    doc = {"exportFps": FPS, "trackPath": "/World/audio2face/Player", "numPoses": 52, "numFrames": FRAMES,
           "facsNames": list(ARKIT_NAMES), "weightMat": weights.tolist(), "facegen": {"audio": "out.wav"},
           "facegenHead": {"angles": ["yaw", "pitch", "roll"], "units": "degrees", "values": head.tolist()}}
    (node_folder / "out.json").write_text(json.dumps(doc))
    frames = [0, 1, 12.5, 13, FRAMES - 1]  # 12.5: halfway between two frames (linear)
    times = [f / FPS for f in frames]
    rule_names = [*ARKIT_NAMES, *MESHES["Head"], *MESHES["Teeth"], *LIVE_LINK_COLUMNS, "blendShape2.JawOpen",
                  "ARKIT-eyeWide_L", "facs_mouthPress-R", "Head|browDown_L", "mouthClose.001", "Basis", "",
                  "MOUTHFUNNEL", "EYEBLINK_L"]
    bad = [{"exportFps": FPS, "facsNames": ["a", "b"], "weightMat": [[0.1, 0.2]]},
           {"exportFps": FPS, "facsNames": ["jawOpen"], "weightMat": [[0.1, 0.2]]},
           {"facsNames": ["jawOpen"], "weightMat": [[0.1]]}]
    result = run_check(node_folder, {"weights": "out.json", "names": rule_names, "meshes": MESHES,
                                     "times": times, "bad": bad})

    assert result["rule"] == [arkit_name(n) for n in rule_names]  # the module's copy of facegen's rule
    found = {arkit_name(t) for targets in MESHES.values() for t in targets} - {None}
    assert result["unmatched"] == result["player_unmatched"] == [n for n in ARKIT_NAMES if n not in found]
    assert sorted(result["matched"]["jawOpen"]) == ["Head/jawOpen", "Teeth/Wolf3D.jawOpen"]
    assert result["tracks"] == 10 and result["duration"] == pytest.approx((FRAMES - 1) / FPS)
    from scipy.spatial.transform import Rotation

    from facegen.head import rotations

    for frame, quaternion in zip(frames, result["quaternions"], strict=True):
        if frame % 1 == 0:  # the head's rotation at each frame (x, y, z, w): facegen.head's matrix
            want = rotations(head[int(frame)][None])[0]
            assert np.allclose(Rotation.from_quat(quaternion).as_matrix(), want, atol=1e-5), frame

    for samples in (result["sampled"], result["played"]):
        for i, influences in enumerate(samples):
            low, part = int(frames[i]), frames[i] % 1
            row = (1 - part) * weights[low] + part * weights[min(low + 1, FRAMES - 1)]
            for mesh, targets in MESHES.items():
                for target in targets:
                    name = arkit_name(target)
                    want = 0.0 if name is None else float(row[ARKIT_NAMES.index(name)])
                    assert influences[mesh][target] == pytest.approx(want, abs=1e-6), (mesh, target, times[i])

    shape, width, fps = result["errors"]
    assert shape.startswith("not ARKit-shaped")
    assert "every weightMat row must hold 1 weights" in width
    assert "exportFps must be a positive number" in fps
