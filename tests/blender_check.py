"""Run inside the Blender venv (.venv-blender/bin/python, bpy 5.0): import facegen files through the shipped
helper (facegen/blender/facegen_import.py) and report what Blender made of them, as JSON. Three modes:

    .venv-blender/bin/python tests/blender_check.py FILE --expect-json EXPECT.json
    .venv-blender/bin/python tests/blender_check.py --arkit SPEC.json
    .venv-blender/bin/python tests/blender_check.py --addon ZIP --arkit SPEC.json

FILE mode, EXPECT.json: {"vertices": V, "frames": T, "fps": fps, "meters_per_unit": m, "tolerance": absolute
error allowed in file units, "positions": {"FRAME": "path/to/[V,3].npy", ...}, "sound_frames": T,
"packed": whether the sound must be packed into the .blend}. Positions are in the file's Y-up units;
Blender's world coordinates (Z-up, meters) are mapped back as (x, z, -y) / m. Exits 0 only when every check
passed.

--arkit mode, SPEC.json: {"keys": [shape key names of the generated character], "frames": [frames to
sample], "apply": [{"file": .json/.csv, "target": object name, "head": object name or absent}, ...],
"errors": [{"file", "target"}, ...],
"timed": {"file": a long .json, "keys": [names], "vertices": approx. vertex count}}. A UV sphere "Character"
gets the keys (each moving a few vertices), a cube "Prop" none, a sphere "Other" keys not named like
ARKit's. Reports per application the helper's result, the scene's fps, frame range and sound strips,
each shape key's value at the sampled frames and (with "head") the head object's world rotation there;
per error case the message; the seconds the timed one took. With --addon the applications go through the
installed add-on's operator instead of the helper.

Prints one line "blender_check: {...}". Only bpy and numpy are needed (no facegen install).
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
            add("animation", span == [0.0, float(T - 1)], {"kind": "shape keys",
                                                           "keys": len(keys.key_blocks) - 1,
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
        packed = s.sound.packed_file is not None
        add("sound", s.frame_final_start == 0 and s.frame_final_duration == expect["sound_frames"]
            and packed == expect.get("packed", False),
            {"file": bpy.path.abspath(s.sound.filepath), "start": s.frame_final_start,
             "frames": s.frame_final_duration, "samplerate": s.sound.samplerate, "packed": packed})
    else:
        add("sound", False, {"strips": [s.name for s in strips]})
    out["ok"] = all(c["ok"] for c in out["checks"].values())
    return out


def character(name: str, keys: list[str], segments: int = 32, rings: int = 16):
    """A UV sphere with one shape key per name (the reference key "Basis" first), each moving a band."""
    import bpy

    bpy.ops.mesh.primitive_uv_sphere_add(segments=segments, ring_count=rings)
    obj = bpy.context.active_object
    obj.name = name
    obj.shape_key_add(name="Basis")
    count = len(obj.data.vertices)
    for i, key in enumerate(keys):
        block = obj.shape_key_add(name=key, from_mix=False)
        block.value = 0.0
        for v in range(i % count, count, max(1, count // 8)):
            block.data[v].co.z += 0.05
    return obj


def sampled(scene, objects, frames: list[int]) -> dict:
    """{object: {shape key: [its value at each frame]}} (the reference key left out)."""
    values = {o.name: {b.name: [] for b in o.data.shape_keys.key_blocks[1:]} for o in objects}
    for frame in frames:
        scene.frame_set(frame)
        for obj in objects:
            for block in obj.data.shape_keys.key_blocks[1:]:
                values[obj.name][block.name].append(block.value)
    return values


def scene_state(scene) -> dict:
    editor = scene.sequence_editor
    sounds = [s for s in (editor.strips if editor is not None else []) if s.type == "SOUND"]
    return {"fps": scene.render.fps / scene.render.fps_base, "frame_start": scene.frame_start,
            "frame_end": scene.frame_end,
            "sounds": [{"start": s.frame_final_start, "frames": s.frame_final_duration,
                        "packed": s.sound.packed_file is not None} for s in sounds]}


def check_arkit(spec: dict, addon: Path | None) -> dict:
    import time

    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    helper = load_helper()
    scene = bpy.context.scene
    if addon is not None:
        import addon_utils

        bpy.ops.preferences.addon_install(filepath=str(addon))
        bpy.ops.preferences.addon_enable(module="facegen_blender")
        module = sys.modules.get("facegen_blender")
        installed = {"module": module.__file__ if module else None, "operator": hasattr(bpy.ops.facegen,
                     "import_animation"), "enabled": [m.__name__ for m in addon_utils.modules()
                                                     if addon_utils.check(m.__name__)[1]]}
    out: dict = {"applied": [], "errors": [], "addon": installed if addon is not None else None}
    characters = [character("Character", spec["keys"])]
    bpy.ops.mesh.primitive_cube_add()
    bpy.context.active_object.name = "Prop"
    character("Other", ["smile", "Key 1"], 8, 4)
    for case in spec["apply"]:
        if addon is not None:
            result = bpy.ops.facegen.import_animation(filepath=case["file"], target=case["target"])
            done = {"operator": sorted(result)}
        else:
            done = helper.import_file(case["file"], target=case["target"], head=case.get("head"))
        applied = {"import": done, "scene": scene_state(scene), "values": sampled(scene, characters,
                                                                                  spec["frames"])}
        if case.get("head"):  # the head object's world rotation at the sampled frames
            obj = bpy.data.objects[case["head"]]
            applied["head"] = []
            for frame in spec["frames"]:
                scene.frame_set(frame)
                applied["head"].append([list(r) for r in obj.matrix_world.to_3x3()])
        out["applied"].append(applied)
    for case in spec["errors"]:
        try:
            helper.import_file(case["file"], target=case["target"])
            out["errors"].append(None)
        except (OSError, ValueError, RuntimeError) as exc:
            out["errors"].append(str(exc))
    if spec.get("timed"):
        timed = spec["timed"]
        side = max(8, int((timed["vertices"] / 2) ** 0.5))
        big = character("Big", timed["keys"], side * 2, side)
        start = time.perf_counter()
        done = helper.import_file(timed["file"], target="Big")
        out["timed"] = {"seconds": time.perf_counter() - start, "vertices": len(big.data.vertices),
                        "keys": done["keys"], "frames": done["frames"]}
    return out


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("file", nargs="?")
    parser.add_argument("--expect-json")
    parser.add_argument("--arkit", help="an ARKit SPEC.json (see the module's docstring)")
    parser.add_argument("--addon", help="the add-on zip: install it, apply through its operator")
    args = parser.parse_args()
    if args.arkit:
        result = check_arkit(json.loads(Path(args.arkit).read_text()), Path(args.addon) if args.addon
                             else None)
        print("blender_check: " + json.dumps(result), flush=True)
        return 0
    result = check(Path(args.file).resolve(), json.loads(Path(args.expect_json).read_text()))
    print("blender_check: " + json.dumps(result), flush=True)
    return 0 if result["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
