"""Real DCC import: Blender (PyPI bpy 5.0 in .venv-blender, made by `make blender-venv`) opens every format
facegen writes through the shipped helper facegen/blender/facegen_import.py, in a subprocess running
tests/blender_check.py.

For each file: one mesh of the clip's vertex count, scene fps = the clip's, frame range 0..T-1, the
animation spanning it, evaluated positions at the first, middle and last frame equal to what was written
within 1e-4 of the face's size (in the file's Y-up units: Blender's Z-up meters mapped back), and a sound
strip of the WAV (beside the file, or inside the .usdz, or the MP3 inside a lone .glb) from frame 0 lasting
T frames, with no temporary file left behind.

ARKit weights (an Audio2Face JSON, a Live Link Face CSV, written here by a small generator) go onto a
generated character (a UV sphere, not facegen's topology) whose shape keys are named in several styles:
the keyed values at sampled frames equal the file's weights, fps, frame range and sound strip are set, the
shapes without a key are listed, and bad targets/files fail with one line. The same through the add-on,
installed from its zip as the module `facegen_blender`.

Outside CI the Blender tests skip when .venv-blender is missing; in CI (CI=true) they must run.
Adding a format is one entry in FORMATS.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import rig_clip

from facegen.arkit.names import ARKIT_NAMES, LIVE_LINK_COLUMNS, arkit_name
from facegen.audio import write_wav
from facegen.blender import facegen_arkit
from facegen.blender.package import write_addon
from facegen.exchange import read_animation, write_animation

REPO = Path(__file__).resolve().parents[1]
BLENDER_PYTHON = REPO / ".venv-blender" / "bin" / "python"
CHECK = Path(__file__).resolve().parent / "blender_check.py"
FRAMES = 60
TOLERANCE = 1e-4  # of the face's size

# (suffix, writer options, what Blender must show: "source" = the clip itself, "file" = what the file
# stores, i.e. glTF's PCA reconstruction, itself within the stated tolerance of the clip; where the sound
# comes from: "wav" beside the file, "inside" the file only (packed into the .blend))
FORMATS = [
    pytest.param(".usda", {}, "source", "wav", id="usda"),
    pytest.param(".usdc", {}, "source", "wav", id="usdc"),
    pytest.param(".usdz", {}, "source", "inside", id="usdz"),
    pytest.param(".usdc", {"mode": "blendshapes"}, "file", "wav", id="usdc-blendshapes"),
    pytest.param(".glb", {"morph_targets": "all"}, "source", "wav", id="glb"),
    pytest.param(".gltf", {"morph_targets": "all"}, "source", "wav", id="gltf"),
    pytest.param(".glb", {}, "file", "wav", id="glb-pca"),
    pytest.param(".glb", {}, "file", "inside", id="glb-lone"),  # no WAV beside: the embedded MP3
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


def run_check(blender_python: Path, args: list[str], tmp_path: Path, env: dict | None = None) -> dict:
    """Run blender_check.py in the Blender venv (TMPDIR inside tmp_path); its result line as a dict."""
    temp = tmp_path / "tmp"
    temp.mkdir(exist_ok=True)
    done = subprocess.run([str(blender_python), str(CHECK), *args], capture_output=True, text=True,
                          timeout=300,
                          cwd=tmp_path, check=False, env={**os.environ, "TMPDIR": str(temp), **(env or {})})
    lines = [line for line in done.stdout.splitlines() if line.startswith("blender_check: ")]
    assert lines, (f"blender_check printed no result (exit {done.returncode}):\n{done.stdout[-3000:]}\n"
                   f"{done.stderr[-3000:]}")
    result = json.loads(lines[-1].removeprefix("blender_check: "))
    result["returncode"] = done.returncode
    result["left_behind"] = sorted(p.name for p in temp.glob("facegen_audio_*"))
    return result


@pytest.mark.parametrize("suffix, options, shows, sound", FORMATS)
def test_blender_imports(blender_python, clip, tmp_path, suffix, options, shows, sound):
    path = tmp_path / f"clip{suffix}"
    write_animation(clip, path, **options)
    if sound == "inside":
        path.with_suffix(".wav").unlink(missing_ok=True)
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
        "packed": sound == "inside",
    }
    (tmp_path / "expect.json").write_text(json.dumps(expect))
    result = run_check(blender_python, [str(path), "--expect-json", str(tmp_path / "expect.json")], tmp_path)
    failed = {name: c["detail"] for name, c in result["checks"].items() if not c["ok"]}
    assert not failed, f"{suffix} {options}: {failed}"
    assert set(result["checks"]) == {"vertices", "fps", "frame range", "animation", "positions", "sound"}
    assert result["returncode"] == 0
    assert result["import"]["warnings"] == []
    assert result["left_behind"] == []  # no extracted sound left in the temporary folder
    sys.stdout.write(f"{path.name}: {result['checks']['positions']['detail']}\n")


# ---- ARKit weights onto a character's shape keys ---------------------------------------------------------

# the generated character's shape keys: several naming styles, one key not ARKit's, two keys for jawOpen
CHARACTER_KEYS = ["jawOpen", "blendShape1.eyeBlinkLeft", "eyeBlink_R", "ARKit_mouthSmile_L", "mouthSmile_R",
                  "BrowInnerUp", "Face:mouthClose", "bs_cheekPuff", "mouthfunnel", "Teeth:jawOpen",
                  "custom_wrinkle"]


def arkit_weights(frames: int, seed: int = 0) -> np.ndarray:
    """[frames, 52] plausible ARKit weights in 0..1: a talking jaw, blinks, smooth noise elsewhere."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / 25.0
    noise = np.cumsum(rng.normal(0, 0.05, (frames, len(ARKIT_NAMES))), axis=0)
    weights = np.clip(0.2 + 0.2 * np.sin(noise), 0, 1)
    weights[:, ARKIT_NAMES.index("jawOpen")] = 0.35 + 0.3 * np.sin(2 * np.pi * 4 * t)
    blink = (np.arange(frames) % 40 < 3).astype(float)
    weights[:, ARKIT_NAMES.index("eyeBlinkLeft")] = weights[:, ARKIT_NAMES.index("eyeBlinkRight")] = blink
    return weights.astype(np.float32)


def head_angles(frames: int) -> np.ndarray:
    """[frames, 3] yaw, pitch, roll in degrees: three different slow turns."""
    t = np.arange(frames) / 25.0
    return np.stack([8 * np.sin(2 * np.pi * 0.5 * t), 5 * np.sin(2 * np.pi * 0.8 * t + 1),
                     3 * np.sin(2 * np.pi * 0.3 * t + 2)], 1)


def write_audio2face(path: Path, weights: np.ndarray, fps: float, head: np.ndarray | None = None) -> Path:
    doc = {"exportFps": fps, "trackPath": "/World/audio2face/Player", "numPoses": len(ARKIT_NAMES),
           "numFrames": len(weights), "facsNames": list(ARKIT_NAMES), "weightMat": weights.tolist()}
    if head is not None:  # as facegen.exchange.arkit_json writes it
        doc["facegenHead"] = {"angles": ["yaw", "pitch", "roll"], "units": "degrees",
                              "order": "Ry(yaw) Rx(pitch) Rz(roll)", "pivot": [0.0, 0.0, 0.0],
                              "values": head.tolist()}
    path.write_text(json.dumps(doc))
    return path


def write_live_link(path: Path, weights: np.ndarray, fps: int, head: np.ndarray | None = None) -> Path:
    """`weights` [T, 52] in ARKIT_NAMES order, written in the CSV's own column order; `head` [T, 3] degrees
    as HeadYaw, HeadPitch, HeadRoll (radians), else 0 (the eyes' columns always 0)."""
    rows = [",".join(LIVE_LINK_COLUMNS)]
    columns = [ARKIT_NAMES.index(arkit_name(c)) for c in LIVE_LINK_COLUMNS[2:2 + len(ARKIT_NAMES)]]
    assert list(LIVE_LINK_COLUMNS[2 + len(ARKIT_NAMES):][:3]) == ["HeadYaw", "HeadPitch", "HeadRoll"]
    turns = np.radians(head) if head is not None else np.zeros((len(weights), 3))
    for i, row in enumerate(weights[:, columns]):
        seconds, frame = divmod(i, fps)
        timecode = f"10:{seconds // 60:02d}:{seconds % 60:02d}:{frame:02d}.{round(1000 * frame / fps):03d}"
        rows.append(",".join([timecode, "61", *(f"{w:.6f}" for w in row), *(f"{a:.8f}" for a in turns[i]),
                              *["0"] * 6]))
    path.write_text("\n".join(rows) + "\n")
    return path


def test_blender_helper_uses_facegen_arkit_names(tmp_path):
    """The Blender helper loads the names and the rule from facegen/arkit/names.py (Blender has no facegen),
    which the add-on zip carries beside it."""
    import zipfile

    from facegen.blender.package import ADDON_MODULE, write_addon

    with zipfile.ZipFile(write_addon(tmp_path / "addon.zip")) as archive:
        shipped = archive.read(f"{ADDON_MODULE}/arkit_names.py")
    assert shipped == (Path(facegen_arkit.__file__).parents[1] / "arkit" / "names.py").read_bytes()
    assert facegen_arkit.ARKIT_NAMES == ARKIT_NAMES
    names = [*ARKIT_NAMES, *CHARACTER_KEYS, *LIVE_LINK_COLUMNS, "blendShape2.JawOpen", "ARKIT-eyeWide_L",
             "facs_mouthPress-R", "Head|browDown_L", "bs.tongueOut", "eyeLookUp.L", "mouthClose.001",
             "jaw_open", "Basis", "", " cheekSquint R ", "MOUTHFUNNEL", "MOUTHROLLUPPER", "EYEBLINK_L"]
    assert [facegen_arkit.arkit_name(n) for n in names] == [arkit_name(n) for n in names]
    assert facegen_arkit.arkit_name("ARKit_mouthSmile_L") == "mouthSmileLeft"
    assert arkit_name("MOUTHFUNNEL") == "mouthFunnel" and arkit_name("MOUTHROLLUPPER") == "mouthRollUpper"


def test_read_weights_json_and_csv(tmp_path):
    weights = arkit_weights(70)
    clip = facegen_arkit.read_weights(write_audio2face(tmp_path / "a.json", weights, 25))
    assert clip["names"] == list(ARKIT_NAMES) and clip["fps"] == 25 and clip["audio"] is None
    np.testing.assert_allclose(clip["weights"], weights, atol=1e-7)
    np.testing.assert_array_equal(clip["frames"], np.arange(70))
    write_wav(np.zeros(16000, np.float32), 16000, tmp_path / "b.wav")
    clip = facegen_arkit.read_weights(write_live_link(tmp_path / "b.csv", weights, 30))
    assert (sorted(clip["names"]) == sorted(ARKIT_NAMES) and clip["fps"] == 30
            and clip["audio"] == str(tmp_path / "b.wav"))
    by_name = [clip["names"].index(n) for n in ARKIT_NAMES]  # the CSV's order: JawRight before JawLeft, ...
    np.testing.assert_allclose(clip["weights"][:, by_name], weights, atol=1e-6)
    np.testing.assert_array_equal(clip["frames"], np.arange(70))  # the ".mmm" of whole-frame rows is ignored
    # 60 rows a second on a 30 fps timecode: two rows per whole frame, told apart by the sub-frame
    lines = (tmp_path / "b.csv").read_text().splitlines()[:3]
    lines[2] = lines[1].replace(":00.000,", ":00.500,", 1)
    (tmp_path / "c.csv").write_text("\n".join(lines + [lines[1].replace("10:00:00:00.000",
                                                                        "10:00:01:29.500")]))
    clip = facegen_arkit.read_weights(tmp_path / "c.csv")
    assert clip["fps"] == 30
    np.testing.assert_allclose(clip["frames"], [0, 0.5, 59.5])


def test_read_weights_head_motion(tmp_path):
    weights, head = arkit_weights(30), head_angles(30)
    clip = facegen_arkit.read_weights(write_audio2face(tmp_path / "h.json", weights, 25, head))
    np.testing.assert_allclose(clip["head"], head, atol=1e-9)
    clip = facegen_arkit.read_weights(write_live_link(tmp_path / "h.csv", weights, 25, head))
    np.testing.assert_allclose(clip["head"], head, atol=1e-5)  # radians with 8 decimals
    assert clip["weights"].shape == (30, 52)  # the head's columns are not weights
    assert facegen_arkit.read_weights(write_live_link(tmp_path / "still.csv", weights, 25))["head"] is None
    assert facegen_arkit.read_weights(write_audio2face(tmp_path / "none.json", weights, 25))["head"] is None
    write_audio2face(tmp_path / "short.json", weights, 25, head[:29])
    with pytest.raises(ValueError, match=re.escape("facegenHead values are [29, 3], expected [30, 3]")):
        facegen_arkit.read_weights(tmp_path / "short.json")
    doc = json.loads((tmp_path / "h.json").read_text())
    doc["facegenHead"] = [1, 2]
    (tmp_path / "bad.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="facegenHead must be an object"):
        facegen_arkit.read_weights(tmp_path / "bad.json")


@pytest.mark.parametrize("content, message", [
    ("{\"weightMat\": [[0.1]]}", "not an Audio2Face blend-shape JSON"),
    (json.dumps({"exportFps": 25, "facsNames": ["a", "b"], "weightMat": [[0.1, 0.2]]}), "not ARKit-shaped"),
    (json.dumps({"exportFps": 25, "facsNames": ["jawOpen"], "weightMat": [[0.1, 0.2]]}),
     "expected [frames, 1]"),
    (json.dumps({"exportFps": 25, "numFrames": 3, "facsNames": ["jawOpen"], "weightMat": [[0.1]]}),
     "numFrames"),
    (json.dumps({"exportFps": 0, "facsNames": ["jawOpen"], "weightMat": [[0.1]]}), "exportFps"),
    ("[1, 2", "not an Audio2Face blend-shape JSON"),
])
def test_read_weights_refuses_what_is_not_arkit(tmp_path, content, message):
    path = tmp_path / "w.json"
    path.write_text(content)
    with pytest.raises(ValueError, match=re.escape(message)) as info:
        facegen_arkit.read_weights(path)
    assert "\n" not in str(info.value)


def test_read_weights_csv_needs_fps_within_one_second(tmp_path):
    path = write_live_link(tmp_path / "s.csv", arkit_weights(10), 30)
    with pytest.raises(ValueError, match="pass --fps"):
        facegen_arkit.read_weights(path)
    assert facegen_arkit.read_weights(path, fps=60)["fps"] == 60
    path.write_text("frame,jawOpen\n0,0.5\n")
    with pytest.raises(ValueError, match="not a Live Link Face CSV"):
        facegen_arkit.read_weights(path)


def expected_values(weights: np.ndarray, keys: list[str], frames: list[int]) -> dict[str, list[float] | None]:
    """What each shape key must read at `frames`: its ARKit column of `weights` (None: a key left alone)."""
    out = {}
    for key in keys:
        name = arkit_name(key)
        out[key] = None if name is None else [float(weights[f, ARKIT_NAMES.index(name)]) for f in frames]
    return out


def assert_keyed(values: dict, expected: dict) -> None:
    for key, want in expected.items():
        if want is None:
            assert values[key] == [0.0] * len(values[key]), key
        else:
            np.testing.assert_allclose(values[key], want, atol=1e-6, err_msg=key)


@pytest.fixture(scope="module")
def arkit_files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("arkit")
    weights = {"json": arkit_weights(50, seed=1), "csv": arkit_weights(45, seed=2)}
    write_audio2face(folder / "talk.json", weights["json"], 25)
    # 2 s = 50 frames
    write_wav((0.1 * np.sin(np.arange(32000) / 5)).astype(np.float32), 16000, folder / "talk.wav")
    write_live_link(folder / "take.csv", weights["csv"], 30)
    write_audio2face(folder / "turn.json", weights["json"], 25, head_angles(50))  # head motion: a json and
    write_live_link(folder / "turn.csv", weights["csv"], 30, head_angles(45))  # a csv
    (folder / "bad.json").write_text(json.dumps({"exportFps": 25, "facsNames": ["x"], "weightMat": [[0.0]]}))
    write_audio2face(folder / "long.json", arkit_weights(1500, seed=4), 25)  # 60 s
    return folder, weights


def test_blender_applies_arkit_weights_by_name(blender_python, arkit_files, tmp_path):
    folder, weights = arkit_files
    frames = [0, 1, 17, 31, 44]
    spec = {"keys": CHARACTER_KEYS, "frames": frames,
            "apply": [{"file": str(folder / "talk.json"), "target": "Character"},
                      {"file": str(folder / "take.csv"), "target": "Character"},
                      {"file": str(folder / "turn.json"), "target": "Character", "head": "Prop"},
                      {"file": str(folder / "turn.csv"), "target": "Character", "head": "Prop"}],
            "errors": [{"file": str(folder / "talk.json"), "target": "Nobody"},
                       {"file": str(folder / "talk.json"), "target": "Other"},
                       {"file": str(folder / "talk.json"), "target": "Prop"},
                       {"file": str(folder / "bad.json"), "target": "Character"}],
            "timed": {"file": str(folder / "long.json"), "keys": list(ARKIT_NAMES), "vertices": 20000}}
    (tmp_path / "spec.json").write_text(json.dumps(spec))
    result = run_check(blender_python, ["--arkit", str(tmp_path / "spec.json")], tmp_path)
    assert result["returncode"] == 0
    found = {arkit_name(k) for k in CHARACTER_KEYS} - {None}
    unmatched = [n for n in ARKIT_NAMES if n not in found]

    json_run, csv_run, *turned = result["applied"]
    done = json_run["import"]
    assert done["objects"] == ["Character"] and done["frames"] == 50 and done["keys"] == 10
    assert done["unmatched"] == unmatched and len(unmatched) == 52 - 9
    assert sorted(done["matched"]["jawOpen"]) == ["Character/Teeth:jawOpen", "Character/jawOpen"]
    assert done["matched"]["mouthSmileLeft"] == ["Character/ARKit_mouthSmile_L"]
    assert done["audio"] == str(folder / "talk.wav") and done["sound"] and done["warnings"] == []
    scene = json_run["scene"]
    assert (scene["fps"], scene["frame_start"], scene["frame_end"]) == (25, 0, 49)
    assert scene["sounds"] == [{"start": 0, "frames": 50, "packed": False}]
    assert_keyed(json_run["values"]["Character"], expected_values(weights["json"], CHARACTER_KEYS, frames))

    done = csv_run["import"]  # fps from the Timecode frames; no WAV beside it: a warning, no sound
    assert done["frames"] == 45 and sorted(done["unmatched"]) == sorted(unmatched) and done["sound"] is None
    assert done["warnings"] and "no sound" in done["warnings"][0]
    assert (csv_run["scene"]["fps"], csv_run["scene"]["frame_end"], csv_run["scene"]["sounds"]) == (30, 44,
                                                                                                    [])
    assert_keyed(csv_run["values"]["Character"], expected_values(weights["csv"], CHARACTER_KEYS, frames))

    # the head's turn: facegen's rotation (facegen.head, Y-up) seen in Blender's Z-up world, where its
    # importers put facegen's (x, y, z) at (x, -z, y)
    from facegen.head import rotations

    to_blender = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], np.float64)
    for run, count in zip(turned, (50, 45), strict=True):
        assert run["import"]["head"] == "Prop" and not any("head" in w for w in run["import"]["warnings"])
        want = to_blender @ rotations(head_angles(count)[frames]) @ to_blender.T
        np.testing.assert_allclose(np.array(run["head"]), want, atol=1e-5)
        assert_keyed(run["values"]["Character"], expected_values(weights["json" if count == 50 else "csv"],
                                                                 CHARACTER_KEYS, frames))
    missing, unnamed, bare, bad = result["errors"]
    assert missing.startswith("no object named 'Nobody': the objects "
                              "are ") and "Character, Other, Prop" in missing
    assert "'Other' has no shape key named like ARKit's" in unnamed and "Basis, smile, Key 1" in unnamed
    assert "'Prop'" in bare and "it has no shape keys" in bare
    assert "bad.json: not ARKit-shaped" in bad
    assert all("\n" not in e for e in result["errors"])

    timed = result["timed"]
    assert (timed["keys"], timed["frames"]) == (52, 1500)
    sys.stdout.write(f"60 s JSON onto 52 shape keys of {timed['vertices']} vertices: {timed['seconds']:.2f} "
                     "s\n")


def test_blender_addon_installs_as_facegen_blender(blender_python, arkit_files, tmp_path):
    folder, weights = arkit_files
    addon = write_addon(tmp_path / "facegen_blender.zip")
    spec = {"keys": CHARACTER_KEYS, "frames": [0, 25, 49], "errors": [],
            "apply": [{"file": str(folder / "talk.json"), "target": "Character"}]}
    (tmp_path / "spec.json").write_text(json.dumps(spec))
    user = tmp_path / "blender-user"  # the add-on installs here, not in the home folder
    result = run_check(blender_python, ["--addon", str(addon), "--arkit", str(tmp_path / "spec.json")],
                       tmp_path,
                       env={"BLENDER_USER_RESOURCES": str(user)})
    installed = result["addon"]
    assert installed["module"] == str(user / "scripts" / "addons" / "facegen_blender" / "__init__.py")
    assert installed["operator"] and "facegen_blender" in installed["enabled"]
    assert "blender" not in installed["enabled"]
    (run,) = result["applied"]
    assert run["import"]["operator"] == ["FINISHED"]
    assert (run["scene"]["fps"], run["scene"]["frame_end"], len(run["scene"]["sounds"])) == (25, 49, 1)
    assert_keyed(run["values"]["Character"], expected_values(weights["json"], CHARACTER_KEYS, [0, 25, 49]))


@pytest.mark.parametrize("suffix, options", [(".usdc", {}), (".glb", {"morph_targets": "all"})],
                         ids=["usdc", "glb"])
def test_blender_imports_the_head_motion(blender_python, clip, tmp_path, suffix, options):
    """The head's transform (facegen.head) animated in Blender: its evaluated world positions are the
    face-local frames turned about the pivot, frame by frame."""
    from dataclasses import replace

    from facegen.head import rotations

    t = np.arange(FRAMES) / clip.fps
    angles = np.stack([4 * np.sin(2 * np.pi * 0.7 * t), 3 * np.sin(2 * np.pi * 1.1 * t + 1),
                       2 * np.sin(2 * np.pi * 0.4 * t + 2)], 1).astype(np.float32)
    pivot = (clip.template.mean(0) - [0, 0.2 * clip.size, 0.1 * clip.size]).astype(np.float32)
    moving = replace(clip, head=angles, head_pivot=pivot)
    path = tmp_path / f"clip{suffix}"
    write_animation(moving, path, **options)
    positions = {}
    turns = rotations(angles)
    for frame in (0, 17, FRAMES - 1):
        world = pivot + (clip.vertices[frame].astype(np.float64) - pivot) @ turns[frame].T
        positions[str(frame)] = str(tmp_path / f"frame{frame}.npy")
        np.save(positions[str(frame)], world)
    expect = {"vertices": clip.num_vertices, "frames": FRAMES, "fps": clip.fps, "meters_per_unit": 0.2,
              "tolerance": TOLERANCE * clip.size, "positions": positions, "sound_frames": FRAMES,
              "packed": False}
    (tmp_path / "expect.json").write_text(json.dumps(expect))
    result = run_check(blender_python, [str(path), "--expect-json", str(tmp_path / "expect.json")], tmp_path)
    failed = {name: c["detail"] for name, c in result["checks"].items() if not c["ok"]}
    assert not failed, f"{suffix}: {failed}"
