"""Run inside the Blender venv (.venv-blender/bin/python, bpy 5.0): import one facegen file through the
shipped helper (facegen/blender/facegen_import.py) and report what Blender made of it, as JSON.

    .venv-blender/bin/python tests/blender_check.py FILE --expect-json EXPECT.json

EXPECT.json: {"vertices": V, "frames": T, "fps": fps, "meters_per_unit": m, "tolerance": absolute error
allowed in file units, "positions": {"FRAME": "path/to/[V,3].npy", ...}, "sound_frames": T}. Positions are
in the file's Y-up units; Blender's world coordinates (Z-up, meters) are mapped back as (x, z, -y) / m.
Prints one line "blender_check: {...}" with every measured value and check (ok, detail), and exits 0 only
when every check passed. Only bpy and numpy are needed (no facegen install).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
from pathlib import Path

import numpy as np

HELPER = Path(__file__).resolve().parents[1] / "facegen" / "blender" / "facegen_import.py"


def load_helper():
    spec = importlib.util.spec_from_file_location("facegen_import", HELPER)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def evaluated_positions(obj, scene, frame: int, meters_per_unit: float) -> np.ndarray:
    """The mesh's evaluated vertices at `frame`, world space mapped back to the file's Y-up units."""
    import bpy

    scene.frame_set(frame)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    try:
        co = np.empty(len(mesh.vertices) * 3, np.float64)
        mesh.vertices.foreach_get("co", co)
    finally:
        evaluated.to_mesh_clear()
    matrix = np.array(evaluated.matrix_world, dtype=np.float64)
    world = co.reshape(-1, 3) @ matrix[:3, :3].T + matrix[:3, 3]
    return np.stack([world[:, 0], world[:, 2], -world[:, 1]], axis=1) / meters_per_unit


def check(path: Path, expect: dict) -> dict:
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    helper = load_helper()
    done = helper.import_file(path)
    scene = bpy.context.scene
    out: dict = {"import": done, "checks": {}}

    def add(name: str, ok: bool, detail) -> None:
        out["checks"][name] = {"ok": bool(ok), "detail": detail}

    meshes = [o for o in bpy.data.objects if o.type == "MESH"]
    counts = [len(o.data.vertices) for o in meshes]
    add("vertices", counts == [expect["vertices"]], {"meshes": counts})
    fps = scene.render.fps / scene.render.fps_base
    add("fps", abs(fps - expect["fps"]) < 1e-6, {"scene_fps": fps})
    T = expect["frames"]
    add("frame range", (scene.frame_start, scene.frame_end) == (0, T - 1),
        {"frame_start": scene.frame_start, "frame_end": scene.frame_end})
    if meshes:
        obj = meshes[0]
        keys = obj.data.shape_keys
        action = keys.animation_data.action if keys and keys.animation_data else None
        cache = [m for m in obj.modifiers if m.type == "MESH_SEQUENCE_CACHE"]
        if action is not None:  # glTF: shape keys driven by an action
            span = [float(action.frame_range[0]), float(action.frame_range[1])]
            add("animation", span == [0.0, float(T - 1)], {"kind": "shape keys", "keys": len(keys.key_blocks) - 1,
                                                            "action_frames": span})
        else:  # USD: a mesh-sequence cache (its span is shown by the positions at the first/last frame)
            add("animation", bool(cache), {"kind": "mesh sequence cache" if cache else "none"})
        errors = {}
        for frame, file in expect["positions"].items():
            want = np.load(file)
            have = evaluated_positions(obj, scene, int(frame), expect["meters_per_unit"])
            errors[frame] = float(np.abs(have - want).max()) if have.shape == want.shape else None
        worst = [e for e in errors.values() if e is not None]
        add("positions", len(worst) == len(errors) and max(worst) <= expect["tolerance"],
            {"max_abs_error": errors, "tolerance": expect["tolerance"]})
    editor = scene.sequence_editor
    strips = list(editor.strips) if editor is not None else []
    sounds = [s for s in strips if s.type == "SOUND"]
    if sounds:
        s = sounds[0]
        add("sound", s.frame_final_start == 0 and s.frame_final_duration == expect["sound_frames"],
            {"file": bpy.path.abspath(s.sound.filepath), "start": s.frame_final_start,
             "frames": s.frame_final_duration, "samplerate": s.sound.samplerate})
    else:
        add("sound", False, {"strips": [s.name for s in strips]})
    out["ok"] = all(c["ok"] for c in out["checks"].values())
    return out


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("file")
    parser.add_argument("--expect-json", required=True)
    args = parser.parse_args()
    result = check(Path(args.file).resolve(), json.loads(Path(args.expect_json).read_text()))
    print("blender_check: " + json.dumps(result), flush=True)
    return 0 if result["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
