"""Import a facegen animation (.usd/.usda/.usdc/.usdz, .glb/.gltf) into Blender, with what Blender's
importers leave out: the scene's frame rate, the frame range 0..T-1 and the sound strip of the clip; or
key ARKit weights (.json Audio2Face, .csv Live Link Face) onto your own character's shape keys by name.

Blender reads neither the fps of a USD stage nor glTF's times in seconds as anything but "seconds at
the scene's current fps", and it ignores KHR_audio_emitter and UsdMedia.SpatialAudio. This helper
reads the fps and frame count from the file (USD stage metadata; glTF asset.extras.facegen), sets the
scene to them *before* importing (so glTF keys land on frames 0..T-1), imports with Blender's own
importer, and adds the WAV written beside the file (`out.wav`) as a sound strip from frame 0, with
audio-synced playback. Without a WAV it takes the sound inside the file (a .usdz's WAV, a glTF's
embedded MP3), packs it into the .blend and leaves no temporary file behind.

ARKit weights go onto the shape keys whose names match ARKit's 52 (facegen_arkit.py: case-insensitive,
prefixes such as `blendShape1.` or `ARKit_` stripped, `_L`/`_R` = Left/Right) of the target objects; the
scene gets the file's fps, frame range and sound, and the ARKit shapes without a shape key are listed. The
head's motion (the JSON's facegenHead, the CSV's HeadYaw/HeadPitch/HeadRoll) turns the object given as the
head (its delta rotation, about its origin: facegen_arkit.key_head); without one it is said to be left out.

Three ways to use it:

    blender --python facegen_import.py -- out.glb [--fps 25] [--audio out.wav] [--empty] [--save out.blend]
    blender avatar.blend --python facegen_import.py -- out.json --target Face [--head Head] [--save a.blend]
    import facegen_import; facegen_import.import_file("out.usdc")      # inside Blender's Python / bpy
    the add-on (this folder, zipped as facegen_blender, see docs/dcc.md): File > Import > facegen animation

This file imports nothing from facegen (Blender's Python does not have it installed). Every refusal is one
line: a ValueError/OSError/RuntimeError from the functions, exit 2 on the command line, nothing saved.
"""

from __future__ import annotations

import argparse
import base64
import importlib
import json
import math
import os
import re
import struct
import sys
import tempfile
from pathlib import Path
from urllib.parse import unquote

GLTF_EXTENSIONS = (".glb", ".gltf")
USD_EXTENSIONS = (".usd", ".usda", ".usdc", ".usdz")
EXTENSIONS = GLTF_EXTENSIONS + USD_EXTENSIONS


# ---- what the file says (no bpy needed) ----------------------------------------------------------------


def file_info(path: str | os.PathLike) -> dict:
    """{"fps": float | None, "frames": int | None, "start": float, "audio": WAV path | None,
    "embedded_audio": (file name, bytes) | None} of a file: the sound is the WAV it names or the one beside
    it; else the audio inside it (a .usdz's WAV, a glTF's KHR_audio_emitter MP3)."""
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
    if info["audio"] is not None:
        info["embedded_audio"] = None
    return info


def _gltf_parts(path: Path) -> tuple[dict, bytes | None]:
    """The JSON document of a .gltf/.glb and the .glb's binary chunk (None for a .gltf)."""
    data = path.read_bytes()
    if data[:4] != b"glTF":
        return json.loads(data), None
    length, kind = struct.unpack_from("<II", data, 12)
    if kind != 0x4E4F534A:
        raise ValueError(f"{path}: the first GLB chunk is not JSON")
    binary = None
    if len(data) >= 28 + length:
        size, kind = struct.unpack_from("<II", data, 20 + length)
        binary = data[28 + length:28 + length + size] if kind == 0x004E4942 else None
    return json.loads(data[20:20 + length]), binary


def _gltf_info(path: Path) -> dict:
    doc, binary = _gltf_parts(path)
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
        "embedded_audio": _gltf_mp3(path, doc, binary),
    }


def _gltf_mp3(path: Path, doc: dict, binary: bytes | None) -> tuple[str, bytes] | None:
    """("<stem>.mp3", bytes) of the first KHR_audio_emitter audio/mpeg in a bufferView, or None."""
    emitter = (doc.get("extensions") or {}).get("KHR_audio_emitter") or {}
    for item in emitter.get("audio") or []:
        view = item.get("bufferView") if isinstance(item, dict) else None
        if item.get("mimeType") != "audio/mpeg" or not isinstance(view, int):
            continue
        try:
            view = doc["bufferViews"][view]
            buffer = doc["buffers"][view["buffer"]]
            uri = buffer.get("uri")
            if uri is None:
                data = binary or b""
            elif uri.startswith("data:"):
                data = base64.b64decode(uri.split(",", 1)[1])
            else:
                data = (path.parent / unquote(uri)).read_bytes()
        except (KeyError, IndexError, TypeError, ValueError, OSError):
            return None
        start = view.get("byteOffset", 0)
        mp3 = data[start:start + view["byteLength"]]
        return (f"{path.stem}.mp3", mp3) if len(mp3) == view["byteLength"] else None
    return None


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
    fps = stage.GetTimeCodesPerSecond() if (layer.HasTimeCodesPerSecond()
                                            or layer.HasFramesPerSecond()) else None
    start, end = stage.GetStartTimeCode(), stage.GetEndTimeCode()
    frames = round(end - start) + 1 if layer.HasStartTimeCode() and layer.HasEndTimeCode() else None
    audio, embedded = None, None
    for prim in stage.Traverse():
        if prim.IsA(UsdMedia.SpatialAudio):
            asset = UsdMedia.SpatialAudio(prim).GetFilePathAttr().Get()
            resolved = asset.resolvedPath if asset is not None else ""
            if resolved and os.path.isfile(resolved):
                audio = resolved
            elif resolved.endswith("]") and "[" in resolved:  # inside a .usdz: Blender needs a real file
                embedded = _read_from_package(resolved)
            break
    return {"format": "usd", "fps": float(fps) if fps else None, "frames": frames, "start": float(start),
            "audio": audio, "embedded_audio": embedded}


def _read_from_package(resolved: str) -> tuple[str, bytes] | None:
    """(file name, bytes) of `pkg.usdz[inner.wav]`, read from the (zip) package."""
    import zipfile

    package, inner = resolved[:-1].split("[", 1)
    try:
        with zipfile.ZipFile(package) as archive:
            return Path(inner).name, archive.read(inner)
    except (OSError, KeyError, zipfile.BadZipFile):
        return None


def _usda_text_info(path: Path) -> dict:
    """Stage metadata from a text .usda's header when pxr is not importable."""
    info = {"format": "usd", "fps": None, "frames": None, "start": 0.0, "audio": None, "embedded_audio": None}
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


def import_file(path: str | os.PathLike, *, fps: float | None = None, audio: str | os.PathLike | None = None,
                sound: bool = True, scene=None, target=None, head=None) -> dict:
    """Import a facegen animation into `scene` (default: the current one) and set it up for playback.

    A .glb/.gltf/.usd* file is imported with Blender's importer. A .json (Audio2Face) or .csv (Live Link
    Face) of ARKit weights is keyed onto the shape keys named like ARKit's of `target` (an object or its
    name, or a list of them; default: every object with such shape keys), and its head motion onto `head` (an
    object or its name: the head, or the character's root; None: not keyed, a warning). `fps` overrides the
    file's rate
    (needed only for files that state none); `audio` replaces the WAV beside the file; `sound=False` adds
    no sound strip. Returns what was done: objects, fps, frames, sound (strip name or None), audio (its
    file), warnings; for glTF/USD also mesh; for ARKit weights also matched, unmatched (ARKit shapes no
    shape key stands for), keys. Raises ValueError/OSError/RuntimeError with a one-line message.
    """
    return _import(read_file(path, fps, target, audio), sound=sound, scene=scene, target=target, head=head)


def read_file(path: str | os.PathLike, fps: float | None = None, target=None,
              audio: str | os.PathLike | None = None) -> dict:
    """What import_file reads before Blender is touched (no bpy): the path and `audio` (regular files), the
    frame rate (in (0, 240], as facegen's), an ARKit file's weights (within facegen's bounds: read_weights).
    The command line calls it before it imports bpy: a refusal costs no Blender start (2 s, 270 MB)."""
    path = Path(path).resolve()
    arkit = _sibling("facegen_arkit")
    arkit.check_fps(fps)
    for given in (path, audio):  # missing, a FIFO, a device, a folder: one line now, not a hang later
        if given is not None:
            arkit.open_regular(Path(given)).close()
    clip = None
    if path.suffix.lower() in arkit.ARKIT_EXTENSIONS:
        clip = arkit.read_weights(path, fps)
    elif target:
        raise ValueError(f"{path.name}: a target applies ARKit weights (.json, .csv); import {path.suffix} "
                         "files without one")
    return {"path": path, "fps": fps, "audio": audio, "clip": clip, "arkit": arkit}


def _import(read: dict, *, sound: bool, scene, target, head=None) -> dict:
    """import_file after read_file."""
    import bpy

    path, fps, audio = read["path"], read["fps"], read["audio"]
    scene = scene or bpy.context.scene
    if read["clip"] is None and head is not None:
        raise ValueError(f"{path.name}: --head applies to ARKit weights (.json, .csv); a {path.suffix} file "
                         "carries the head's turn itself")
    if read["clip"] is not None:
        done, info = read["arkit"].apply_weights(path, read["clip"], target, scene, head)
        set_scene_fps(scene, read["clip"]["fps"])
        done["fps"] = scene_fps(scene)
    else:
        done, info = _import_animation(path, fps, scene)
    scene.frame_start = 0
    scene.frame_end = max(0, done["frames"] - 1)
    scene.frame_set(0)
    wav = str(audio) if audio is not None else info["audio"]
    embedded = info.get("embedded_audio") if wav is None else None
    done.update(sound=None, audio=wav, warnings=info.get("warnings", []))
    if sound and (wav or embedded):
        with tempfile.TemporaryDirectory(prefix="facegen_audio_") as folder:
            if embedded:  # inside the file: written out for Blender to read, packed into the .blend, removed
                wav = Path(folder) / embedded[0]
                wav.write_bytes(embedded[1])
                done["audio"] = f"{path.name}[{embedded[0]}]"
            strip = add_sound(scene, wav)
            if embedded:
                strip.sound.pack()
        done["sound"] = strip.name
        scene.sync_mode = "AUDIO_SYNC"
    elif sound:
        remove_sound(scene)  # an earlier clip's sound would play with this one
        done["warnings"].append(f"{path.name}: no sound: no {path.stem}.wav beside it and none inside it "
                                "(pass --audio FILE)")
    return done


def _sibling(name: str):
    """A module of this folder: relative inside the add-on package, else from this file's folder."""
    if __package__:
        return importlib.import_module(f"{__package__}.{name}")
    folder = str(Path(__file__).resolve().parent)
    if folder not in sys.path:
        sys.path.insert(0, folder)
    return importlib.import_module(name)


def _import_animation(path: Path, fps: float | None, scene) -> tuple[dict, dict]:
    """Import a glTF/USD file with Blender's importer at the file's rate; (what was done, file_info)."""
    import bpy

    info = file_info(path)
    rate = float(fps or info["fps"] or scene_fps(scene))
    if not 0 < rate < math.inf:
        raise ValueError(f"{path.name}: its frame rate is {rate:g}: pass --fps")
    before = set(bpy.data.objects)
    if info["format"] == "gltf":
        # the importer turns seconds into frames with render.fps * render.fps_base: make that the rate
        whole = max(1, round(rate))
        scene.render.fps, scene.render.fps_base = whole, rate / whole
        result = bpy.ops.import_scene.gltf(filepath=str(path))
    else:
        set_scene_fps(scene, rate)
        result = bpy.ops.wm.usd_import(filepath=str(path), set_frame_range=True,
                                       apply_unit_conversion_scale=True)
    set_scene_fps(scene, rate)
    if "FINISHED" not in result:
        raise RuntimeError(f"Blender could not import {path} ({result})")
    objects = [o for o in bpy.data.objects if o not in before]
    # the face first: the mesh with the most vertices (the eyes, teeth and tongue beside it are smaller)
    meshes = sorted((o for o in objects if o.type == "MESH"), key=lambda o: -len(o.data.vertices))
    for obj in meshes:
        keys = obj.data.shape_keys
        if keys is not None and keys.animation_data is not None and keys.animation_data.action is not None:
            snap_keys_to_frames(keys.animation_data.action)
    frames = info["frames"] or _imported_frames(scene, meshes, info["format"])
    done = {"objects": [o.name for o in objects], "mesh": meshes[0].name if meshes else None,
            "fps": scene_fps(scene), "frames": frames}
    return done, info


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


SOUND_STRIP = "facegen audio"


def add_sound(scene, wav: str | os.PathLike, channel: int = 1, frame_start: int = 0):
    """A sound strip of `wav` starting at `frame_start` (replacing facegen's earlier one)."""
    remove_sound(scene)
    editor = scene.sequence_editor or scene.sequence_editor_create()
    strips = editor.strips if hasattr(editor, "strips") else editor.sequences  # Blender 4.4+ / older
    return strips.new_sound(SOUND_STRIP, str(wav), channel, frame_start)


def remove_sound(scene) -> None:
    """Remove facegen's sound strip (of an earlier import), if there is one."""
    editor = scene.sequence_editor
    strips = (editor.strips if hasattr(editor, "strips")
              else editor.sequences) if editor is not None else None
    old = strips.get(SOUND_STRIP) if strips is not None else None
    if old is not None:
        strips.remove(old)


# ---- command line (blender --python facegen_import.py -- FILE ...) ----------------------------------------


def _fail(problem) -> None:
    """One line on stderr, exit 2: nothing has been saved."""
    print(f"facegen_import: error: {' '.join(str(problem).split())}", file=sys.stderr)
    raise SystemExit(2)


def check_save(path: str | os.PathLike) -> Path:
    """The .blend file to save, checked before any work: not a folder, in a folder that exists and can be
    written into (Blender would refuse it only after the import, with a traceback)."""
    target = Path(path).resolve()
    if target.is_dir():
        raise ValueError(f"cannot save to {path}: it is a folder: pass a .blend file name")
    if target.exists() and not target.is_file():
        raise ValueError(f"cannot save to {path}: it is not a regular file: pass a .blend file name")
    if not target.parent.is_dir():
        raise ValueError(f"cannot save to {path}: the folder {target.parent} does not exist: create it first")
    if not os.access(target.parent, os.W_OK | os.X_OK):
        raise ValueError(f"cannot save to {path}: the folder {target.parent} is not writable")
    return target


def main(argv: list[str] | None = None) -> dict:
    if argv is None:
        argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    parser = argparse.ArgumentParser(prog="facegen_import", description=__doc__.splitlines()[0])
    parser.error = lambda message: _fail(f"{message} (see --help)")  # one line, exit 2, as every refusal
    parser.add_argument("file", help="a facegen .glb/.gltf/.usd/.usda/.usdc/.usdz file, or ARKit weights "
                        "(.json Audio2Face, .csv Live Link Face)")
    parser.add_argument("--target", action="append", metavar="OBJECT",
                        help="the object whose ARKit-named shape keys get the weights (repeatable; default: "
                        "every object with such shape keys)")
    parser.add_argument("--head", metavar="OBJECT", help="the object the head motion of ARKit weights turns "
                        "(the head, or the character's root; about its origin)")
    parser.add_argument("--fps", type=float, help="frame rate, when the file does not state one")
    parser.add_argument("--audio", help="a WAV to use instead of the sidecar beside the file")
    parser.add_argument("--no-sound", action="store_true", help="add no sound strip")
    parser.add_argument("--empty", action="store_true", help="start from an empty scene")
    parser.add_argument("--save", help="save the scene as this .blend file")
    args = parser.parse_args(argv)
    try:  # everything that can be refused without Blender, before bpy starts (2 s, 270 MB)
        save = check_save(args.save) if args.save else None
        read = read_file(args.file, args.fps, args.target, args.audio)
    except (OSError, ValueError) as exc:
        _fail(exc)
    import bpy

    if args.empty:
        bpy.ops.wm.read_factory_settings(use_empty=True)
    try:
        done = _import(read, sound=not args.no_sound, scene=None, target=args.target, head=args.head)
    except (OSError, RuntimeError, ValueError) as exc:
        _fail(exc)
    for line in done["warnings"]:
        print(f"facegen_import: warning: {line}")
    if done.get("unmatched"):
        print(f"facegen_import: no shape key for {len(done['unmatched'])} ARKit shapes: "
              f"{', '.join(done['unmatched'])}")
    if save is not None:
        try:
            bpy.ops.wm.save_as_mainfile(filepath=str(save))
        except RuntimeError as exc:
            _fail(f"cannot save {save}: {exc}")
    print("facegen_import: " + json.dumps(done))
    return done


if __name__ == "__main__":
    main()
