"""Import a facegen animation (.usd/.usda/.usdc/.usdz, .glb/.gltf) into Blender, with what Blender's
importers leave out: the scene's frame rate, the frame range 0..T-1 and the sound strip of the clip.

Blender reads neither the fps of a USD stage nor glTF's times in seconds as anything but "seconds at
the scene's current fps", and it ignores KHR_audio_emitter and UsdMedia.SpatialAudio. This helper
reads the fps and frame count from the file (USD stage metadata; glTF asset.extras.facegen), sets the
scene to them *before* importing (so glTF keys land on frames 0..T-1), imports with Blender's own
importer, and adds the WAV written beside the file (`out.wav`) as a sound strip from frame 0, with
audio-synced playback.

Three ways to use it:

    blender --python facegen_import.py -- out.glb [--fps 25] [--audio out.wav] [--empty] [--save out.blend]
    import facegen_import; facegen_import.import_file("out.usdc")      # inside Blender's Python / bpy
    the add-on (this folder zipped, see docs/dcc.md): File > Import > facegen animation

This file imports nothing from facegen (Blender's Python does not have it installed).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import struct
import sys
from pathlib import Path

GLTF_EXTENSIONS = (".glb", ".gltf")
USD_EXTENSIONS = (".usd", ".usda", ".usdc", ".usdz")
EXTENSIONS = GLTF_EXTENSIONS + USD_EXTENSIONS


# ---- what the file says (no bpy needed) ----------------------------------------------------------------


def file_info(path: str | os.PathLike) -> dict:
    """{"fps": float | None, "frames": int | None, "start": float, "audio": WAV path | None} of a file."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in GLTF_EXTENSIONS:
        info = _gltf_info(path)
    elif suffix in USD_EXTENSIONS:
        info = _usd_info(path)
    else:
        raise ValueError(f"{path.name}: not a facegen animation file (use one of {', '.join(EXTENSIONS)})")
    if info.get("audio") is None:
        wav = path.with_suffix(".wav")
        info["audio"] = str(wav) if wav.is_file() else None
    return info


def gltf_json(path: Path) -> dict:
    """The JSON document of a .gltf or .glb file."""
    data = path.read_bytes()
    if data[:4] == b"glTF":
        length, kind = struct.unpack_from("<II", data, 12)
        if kind != 0x4E4F534A:
            raise ValueError(f"{path}: the first GLB chunk is not JSON")
        return json.loads(data[20:20 + length])
    return json.loads(data)


def _gltf_info(path: Path) -> dict:
    doc = gltf_json(path)
    extras = (doc.get("asset") or {}).get("extras") or {}
    facegen = extras.get("facegen") if isinstance(extras, dict) else None
    facegen = facegen if isinstance(facegen, dict) else {}
    audio = None
    sidecar = (facegen.get("audio") or {}).get("sidecar") if isinstance(facegen.get("audio"), dict) else None
    if sidecar and (path.parent / sidecar).is_file():
        audio = str(path.parent / sidecar)
    fps = facegen.get("fps")
    frames = facegen.get("frames")
    return {
        "format": "gltf",
        "fps": float(fps) if isinstance(fps, int | float) and fps > 0 else None,
        "frames": int(frames) if isinstance(frames, int) and frames > 0 else None,
        "start": 0.0,
        "audio": audio,
    }


def _pxr():
    """pxr (USD's Python API): Blender ships it in its own Python's site-packages."""
    try:
        from pxr import Sdf, Usd, UsdMedia
    except ImportError:
        try:
            import bpy
        except ImportError:
            return None
        version = f"python{sys.version_info.major}.{sys.version_info.minor}"
        folder = Path(bpy.utils.resource_path("LOCAL")) / "python" / "lib" / version / "site-packages"
        if not (folder / "pxr").is_dir():
            return None
        sys.path.append(str(folder))
        try:
            from pxr import Sdf, Usd, UsdMedia
        except ImportError:
            return None
    return Sdf, Usd, UsdMedia


def _usd_info(path: Path) -> dict:
    pxr = _pxr()
    if pxr is None:
        return _usda_text_info(path)
    _, Usd, UsdMedia = pxr
    stage = Usd.Stage.Open(str(path))
    layer = stage.GetRootLayer()
    fps = stage.GetTimeCodesPerSecond() if (layer.HasTimeCodesPerSecond() or layer.HasFramesPerSecond()) else None
    start, end = stage.GetStartTimeCode(), stage.GetEndTimeCode()
    frames = round(end - start) + 1 if layer.HasStartTimeCode() and layer.HasEndTimeCode() else None
    audio, packaged = None, False
    for prim in stage.Traverse():
        if prim.IsA(UsdMedia.SpatialAudio):
            asset = UsdMedia.SpatialAudio(prim).GetFilePathAttr().Get()
            resolved = asset.resolvedPath if asset is not None else ""
            if resolved and os.path.isfile(resolved):
                audio = resolved
            elif resolved.endswith("]") and "[" in resolved:  # inside a .usdz: Blender needs a real file
                audio = _extract_from_package(resolved)
                packaged = audio is not None
            break
    return {"format": "usd", "fps": float(fps) if fps else None, "frames": frames, "start": float(start),
            "audio": audio, "packaged_audio": packaged}


def _extract_from_package(resolved: str) -> str | None:
    """Copy `pkg.usdz[inner.wav]` out of the (zip) package into a temporary folder; its path."""
    import tempfile
    import zipfile

    package, inner = resolved[:-1].split("[", 1)
    try:
        with zipfile.ZipFile(package) as archive:
            data = archive.read(inner)
    except (OSError, KeyError, zipfile.BadZipFile):
        return None
    target = Path(tempfile.mkdtemp(prefix="facegen_audio_")) / Path(inner).name
    target.write_bytes(data)
    return str(target)


def _usda_text_info(path: Path) -> dict:
    """Stage metadata from a text .usda's header when pxr is not importable."""
    info = {"format": "usd", "fps": None, "frames": None, "start": 0.0, "audio": None}
    if path.suffix.lower() not in (".usda", ".usd"):
        return info
    head = path.read_bytes()[:4096]
    if not head.startswith(b"#usda"):
        return info
    text = head.decode("utf-8", errors="replace")

    def number(key: str) -> float | None:
        found = re.search(rf"\b{key}\s*=\s*([-+0-9.eE]+)", text)
        return float(found.group(1)) if found else None

    fps = number("timeCodesPerSecond") or number("framesPerSecond")
    start, end = number("startTimeCode"), number("endTimeCode")
    info["fps"] = fps
    if start is not None and end is not None:
        info["start"], info["frames"] = start, round(end - start) + 1
    return info


# ---- Blender -------------------------------------------------------------------------------------------


def set_scene_fps(scene, fps: float) -> None:
    """Blender's rate is render.fps / render.fps_base (29.97 = 30 / 1.001)."""
    whole = max(1, round(fps))
    scene.render.fps = whole
    scene.render.fps_base = whole / float(fps)


def scene_fps(scene) -> float:
    return scene.render.fps / scene.render.fps_base


def import_file(
    path: str | os.PathLike,
    *,
    fps: float | None = None,
    audio: str | os.PathLike | None = None,
    sound: bool = True,
    scene=None,
) -> dict:
    """Import a facegen animation into `scene` (default: the current one) and set it up for playback.

    `fps` overrides the file's rate (needed only for files that do not state one); `audio` replaces
    the WAV sidecar; `sound=False` adds no sound strip. Returns what was done: objects, mesh, fps,
    frames, sound (strip name or None), audio (its file).
    """
    import bpy

    path = Path(path).resolve()
    if not path.is_file():
        raise FileNotFoundError(f"{path} does not exist")
    scene = scene or bpy.context.scene
    info = file_info(path)
    rate = float(fps or info["fps"] or scene_fps(scene))
    before = set(bpy.data.objects)
    if info["format"] == "gltf":
        # the importer turns seconds into frames with render.fps * render.fps_base: make that the rate
        whole = max(1, round(rate))
        scene.render.fps, scene.render.fps_base = whole, rate / whole
        result = bpy.ops.import_scene.gltf(filepath=str(path))
    else:
        set_scene_fps(scene, rate)
        result = bpy.ops.wm.usd_import(filepath=str(path), set_frame_range=True, apply_unit_conversion_scale=True)
    set_scene_fps(scene, rate)
    if "FINISHED" not in result:
        raise RuntimeError(f"Blender could not import {path} ({result})")
    objects = [o for o in bpy.data.objects if o not in before]
    meshes = [o for o in objects if o.type == "MESH"]
    for obj in meshes:
        keys = obj.data.shape_keys
        if keys is not None and keys.animation_data is not None and keys.animation_data.action is not None:
            snap_keys_to_frames(keys.animation_data.action)
    frames = info["frames"] or _imported_frames(scene, meshes, info["format"])
    scene.frame_start = 0
    scene.frame_end = max(0, frames - 1)
    scene.frame_set(0)
    strip = None
    wav = str(audio) if audio is not None else info["audio"]
    if sound and wav:
        strip = add_sound(scene, wav)
        scene.sync_mode = "AUDIO_SYNC"
        if info.get("packaged_audio"):  # extracted from a .usdz into a temporary folder: keep it in the .blend
            strip.sound.pack()
    return {
        "objects": [o.name for o in objects],
        "mesh": meshes[0].name if meshes else None,
        "fps": scene_fps(scene),
        "frames": frames,
        "sound": strip.name if strip is not None else None,
        "audio": wav,
    }


def action_fcurves(action):
    """The F-curves of an action: layered actions (Blender 4.4+) and the older flat ones."""
    layers = getattr(action, "layers", None)
    if layers:
        for layer in layers:
            for strip in layer.strips:
                for slot in action.slots:
                    bag = strip.channelbag(slot)
                    if bag is not None:
                        yield from bag.fcurves
    elif hasattr(action, "fcurves"):
        yield from action.fcurves


def snap_keys_to_frames(action, within: float = 1e-3) -> int:
    """Move keys that sit a hair off a whole frame onto it (glTF times frame / fps are float32, so
    frame 59 at 25 fps arrives as 58.999996); returns how many keys moved."""
    moved = 0
    for fcurve in action_fcurves(action):
        for key in fcurve.keyframe_points:
            whole = round(key.co.x)
            shift = whole - key.co.x
            if shift and abs(shift) <= within:
                key.co.x = whole
                key.handle_left.x += shift
                key.handle_right.x += shift
                moved += 1
        fcurve.update()
    return moved


def _imported_frames(scene, meshes, kind: str) -> int:
    """The frame count when the file does not state it: the shape-key action's or the stage's range."""
    if kind == "gltf":
        for obj in meshes:
            keys = obj.data.shape_keys
            action = keys.animation_data.action if keys and keys.animation_data else None
            if action is not None:
                return round(action.frame_range[1]) + 1
    return int(scene.frame_end - scene.frame_start) + 1


def add_sound(scene, wav: str | os.PathLike, channel: int = 1, frame_start: int = 0):
    """A sound strip of `wav` starting at `frame_start` (replacing facegen's earlier one)."""
    editor = scene.sequence_editor or scene.sequence_editor_create()
    strips = editor.strips if hasattr(editor, "strips") else editor.sequences  # Blender 4.4+ / older
    name = "facegen audio"
    old = strips.get(name) if hasattr(strips, "get") else None
    if old is not None:
        strips.remove(old)
    return strips.new_sound(name, str(wav), channel, frame_start)


# ---- command line (blender --python facegen_import.py -- FILE ...) ----------------------------------------


def main(argv: list[str] | None = None) -> dict:
    if argv is None:
        argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    parser = argparse.ArgumentParser(prog="facegen_import", description=__doc__.splitlines()[0])
    parser.add_argument("file", help="a facegen .glb/.gltf/.usd/.usda/.usdc/.usdz file")
    parser.add_argument("--fps", type=float, help="frame rate, when the file does not state one")
    parser.add_argument("--audio", help="a WAV to use instead of the sidecar beside the file")
    parser.add_argument("--no-sound", action="store_true", help="add no sound strip")
    parser.add_argument("--empty", action="store_true", help="start from an empty scene")
    parser.add_argument("--save", help="save the scene as this .blend file")
    args = parser.parse_args(argv)
    import bpy

    if args.empty:
        bpy.ops.wm.read_factory_settings(use_empty=True)
    done = import_file(args.file, fps=args.fps, audio=args.audio, sound=not args.no_sound)
    if args.save:
        bpy.ops.wm.save_as_mainfile(filepath=str(Path(args.save).resolve()))
    print("facegen_import: " + json.dumps(done))
    return done


if __name__ == "__main__":
    main()
