"""ARKit-52 blend-shape weights (Audio2Face JSON, Live Link Face CSV) keyed onto a character's shape keys in
Blender, matched by name.

Reading needs numpy only; `key_shapes` needs bpy. Like facegen_import.py this file imports nothing from
facegen (Blender's Python does not have it): it loads ARKit's 52 names and their name rule (`arkit_name`) from
the file facegen/arkit/names.py itself, which the add-on zip carries beside it.

    clip = read_weights("out.json")  # or out.csv; {"names", "weights" [T, N], "frames" [T], "head", ...}
    done = key_shapes([bpy.data.objects["Face"]], clip)   # {"matched": {...}, "unmatched": [...]}
    key_head(bpy.data.objects["Head"], clip)   # the head's turns (JSON facegenHead, CSV HeadYaw/Pitch/Roll)

Keys are written a whole F-curve at a time (keyframe_points.add + foreach_set), LINEAR between frames,
into a new action "facegen ARKit <file>" on each object's shape keys.
"""

from __future__ import annotations

import csv
import importlib.util
import math
import os
import re
import stat
from pathlib import Path

import numpy as np

ARKIT_EXTENSIONS = (".json", ".csv")


def _load(name: str, shipped: str, tree: str):
    """A file of facegen that needs only the standard library, loaded from its path: beside this file in the
    add-on zip (blender/package.py puts it there as `shipped`), else at `tree` in the facegen tree this file
    is in. facegen's arkit/names.py is the one list of ARKit's 52 names and the one name rule;
    exchange/arkit_read.py reads ARKit weight files within facegen's bounds, as `facegen validate` does."""
    here = Path(__file__).resolve().parent
    for path in (here / shipped, here.parent / tree):
        if path.is_file():
            spec = importlib.util.spec_from_file_location(name, path)
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            return module
    raise ImportError(f"{shipped} is missing beside {here}: reinstall the add-on")


_NAMES = _load("facegen_arkit_names", "arkit_names.py", "arkit/names.py")
ARKIT_NAMES: tuple[str, ...] = _NAMES.ARKIT_NAMES
arkit_name = _NAMES.arkit_name
READ = _load("facegen_arkit_read", "arkit_read.py", "exchange/arkit_read.py")
# HH:MM:SS:FF[.mmm] (";" before FF: drop-frame); at most 9 digits a field, so every sum fits an int64
_TIMECODE = re.compile(r"^(\d{1,9}):(\d{1,9}):(\d{1,9})[:;](\d{1,9})(?:\.(\d{1,9}))?$")


# ---- reading (numpy only) ----------------------------------------------------------------------------------


def read_weights(path: str | Path, fps: float | None = None) -> dict:
    """ARKit weights from an Audio2Face JSON or a Live Link Face CSV: {"names": ARKit names of the columns,
    "weights": [T, N] float32, "frames": [T] key positions (frames from 0), "fps",
    "audio": the WAV the file names or the one beside it (same stem), or None, "head": [T, 3] yaw, pitch, roll
    in degrees (the JSON's facegenHead, the CSV's HeadYaw/HeadPitch/HeadRoll), or None when the file has
    none or they are all 0}. `fps` overrides the file's.
    Raises ValueError (one line) when the file is not ARKit-shaped, is not a regular file (a FIFO, a device:
    refused at once, not waited on), or is past facegen's bounds (arkit_read.py: 4 hours, 512 MB; read in
    bounded memory, most refusals before the rows are read)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in ARKIT_EXTENSIONS:
        raise ValueError(f"{path.name}: ARKit weights are read from .json (Audio2Face) or .csv (Live Link "
                         "Face)")
    check_fps(fps)
    try:
        with open_regular(path) as file:
            clip = _read_json(path, file, fps) if suffix == ".json" else _read_csv(path, file, fps)
    except READ.TooLarge as exc:
        raise ValueError(f"{path.name}: {exc}") from None
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path.name}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except OSError as exc:
        raise ValueError(f"{path.name}: cannot read it ({exc.strerror or exc})") from None
    if clip["fps"] > READ.MAX_FPS:
        raise ValueError(f"{path.name}: {clip['fps']:g} frames per second, more than facegen plays "
                         f"({READ.MAX_FPS:g}): pass --fps")
    if not np.isfinite(clip["weights"]).all():
        raise ValueError(f"{path.name}: the weights hold NaN or infinite values")
    head = clip.get("head")
    if head is not None and not np.isfinite(head).all():
        raise ValueError(f"{path.name}: the head rotations hold NaN or infinite values")
    clip["head"] = head if head is not None and np.any(head) else None
    audio = clip.pop("audio_name", None)
    wav = path.parent / audio if isinstance(audio, str) and audio else path.with_suffix(".wav")
    clip["audio"] = str(wav) if wav.is_file() else None
    return clip


def check_fps(fps) -> None:
    """Refuse a frame rate (None: the file's) that is not a number in (0, MAX_FPS], as facegen does."""
    rate = READ.rate_of(fps) if fps is not None else READ.MAX_FPS
    if rate is None or rate > READ.MAX_FPS:
        raise ValueError(f"the frame rate must be a number of frames per second in (0, {READ.MAX_FPS:g}], "
                         f"got {fps!r}")


def open_regular(path: Path):
    """`path` open for reading in binary when it is a regular file; a FIFO, a device, a folder is a
    ValueError at once (stat, then opened without blocking and checked again), as facegen's
    input_files.open_input refuses them."""
    try:
        mode = os.stat(path).st_mode
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)) if (
            stat.S_ISREG(mode)) else None
    except ValueError:
        raise ValueError(f"{path!r}: the path contains a NUL byte") from None
    if fd is not None and not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        fd = None
    if fd is None:
        raise ValueError(f"{path}: not a regular file (a folder, a FIFO or a device): pass an ARKit weight "
                         "file")
    return os.fdopen(fd, "rb")


def _columns(path: Path, names: list[str]) -> tuple[list[str], list[int]]:
    """The ARKit names among `names` and their column indices; ValueError when there is none."""
    found = [(arkit_name(n), i) for i, n in enumerate(names)]
    found = [(n, i) for n, i in found if n is not None]
    if not found:
        shown = ", ".join(names[:4]) + (", ..." if len(names) > 4 else "")
        raise ValueError(f"{path.name}: not ARKit-shaped: none of its shape names ({shown or 'none'}) is one "
                         "of ARKit's 52 (eyeBlinkLeft ... tongueOut)")
    return [n for n, _ in found], [i for _, i in found]


class _Table:
    """Rows of numbers gathered a block at a time as float32 (what Blender keys), never as Python floats:
    `add` raises ValueError (one line, said with `what`) for a row that is no list of numbers."""

    def __init__(self, what: str) -> None:
        self.what, self.blocks, self.count = what, [], 0

    def add(self, rows: list) -> None:
        for i, row in enumerate(rows, self.count):
            if type(row) is not list or not set(map(type, row)) <= {float, int}:
                bad = row if type(row) is not list else next(v for v in row if type(v) not in (float, int))
                raise ValueError(f"{self.what} row {i} holds {READ.short(bad)}, not a number")
        try:
            block = np.array(rows, np.float64)
        except OverflowError:  # an integer of hundreds of digits
            raise ValueError(f"{self.what} holds a number past float range") from None
        except ValueError:
            raise ValueError(f"{self.what}: its rows hold different numbers of weights") from None
        with np.errstate(over="ignore"):  # past float32: inf, refused as such
            self.blocks.append(block.astype(np.float32))
        self.count += len(rows)

    def array(self, width: int) -> np.ndarray:
        return np.concatenate(self.blocks) if self.blocks else np.zeros((0, width), np.float32)


def _read_json(path: Path, file, fps: float | None) -> dict:
    shape = (f"{path.name}: not an Audio2Face blend-shape JSON "
             "(exportFps, facsNames, weightMat [frames][shapes])")
    table = _Table("weightMat")
    try:
        doc, count = READ.read_json(file, table.add, fps)
    except READ.NotJson as exc:
        raise ValueError(f"{shape}: {exc}") from None
    except ValueError as exc:
        if isinstance(exc, READ.TooLarge | UnicodeDecodeError):
            raise
        raise ValueError(f"{shape}: {exc}") from None
    if not isinstance(doc.get("facsNames"), list) or count is None:
        raise ValueError(shape)
    names = doc["facsNames"]
    if not all(isinstance(n, str) for n in names):
        raise ValueError(f"{shape}: facsNames must be strings")
    weights = table.array(len(names))
    if weights.shape[1] != len(names) or not len(weights):
        raise ValueError(f"{shape}: weightMat is {list(weights.shape)}, expected [frames, {len(names)}]")
    if doc.get("numFrames") is not None and doc["numFrames"] != len(weights):
        raise ValueError(f"{shape}: numFrames is {READ.short(doc['numFrames'])} but weightMat has "
                         f"{len(weights)} rows")
    rate = fps or READ.rate_of(doc.get("exportFps"))
    if rate is None:
        raise ValueError(f"{shape}: exportFps must be a positive number (or pass --fps)")
    ark, columns = _columns(path, names)
    extra = doc.get("facegen")
    audio = extra.get("audio") if isinstance(extra, dict) else None
    weights = weights if columns == list(range(len(names))) else weights[:, columns]  # no copy when all are
    return {"names": ark, "weights": weights, "frames": np.arange(len(weights), dtype=np.float64),
            "fps": float(rate), "audio_name": audio, "head": _json_head(path, doc.get("facegenHead"),
                                                                       len(weights))}


def _json_head(path: Path, head, frames: int) -> np.ndarray | None:
    """facegenHead's values ([frames][yaw, pitch, roll] degrees, facegen.exchange.arkit_json) or None."""
    if head is None:
        return None
    table = _Table("facegenHead values")
    values = head.get("values") if isinstance(head, dict) else None
    if not isinstance(values, list):
        raise ValueError(f"{path.name}: facegenHead must be an object with values [frames][yaw, pitch, "  # noqa: TRY004
                         "roll]")
    table.add(values)
    angles = table.array(3).astype(np.float64)
    if angles.shape != (frames, 3):
        raise ValueError(f"{path.name}: facegenHead values are {list(angles.shape)}, expected [{frames}, 3] "
                         "(yaw, pitch, roll per frame)")
    return angles


def _read_csv(path: Path, file, fps: float | None) -> dict:
    shape = f"{path.name}: not a Live Link Face CSV (Timecode,BlendShapeCount,EyeBlinkLeft,...)"
    rows = (r for r in READ.csv_rows(file) if r)
    try:
        header = [h.strip() for h in next(rows, [])]
        if [h.lower() for h in header[:2]] != ["timecode", "blendshapecount"]:
            raise ValueError(shape)
        ark, columns = _columns(path, header[2:])
        columns = [c + 2 for c in columns]
        named = {h.lower(): i for i, h in enumerate(header)}
        turns = [named.get(n) for n in ("headyaw", "headpitch", "headroll")]
        turns = turns if None not in turns else []  # Live Link's head rotations, radians
        columns += turns
        table, stamps, block, first = _Table("the CSV"), [], [], None
        for number, row in enumerate(rows, start=2):
            found = _TIMECODE.match(row[0].strip())
            if found is None or len(row) < len(header):
                raise ValueError(f"{shape}: row {number} has {len(row)} of {len(header)} columns or a "
                                 f"Timecode {READ.short(row[0])} that is not HH:MM:SS:FF.mmm")
            stamp = [int(found.group(i)) for i in range(1, 5)]
            stamp.append(int((found.group(5) or "0")[:3].ljust(3, "0")))
            seconds = (stamp[0] * 60 + stamp[1]) * 60 + stamp[2]
            first = seconds if first is None else first
            READ.check_span(abs(seconds - first))
            READ.check_frames(number - 1, None, more=True)
            stamps.append(stamp)
            try:
                block.append([float(row[c]) for c in columns])
            except ValueError as exc:
                raise ValueError(f"{shape}: row {number}: {exc}") from None
            if len(block) == READ.BLOCK:
                table.add(block)
                block = []
    except csv.Error as exc:
        raise ValueError(f"{shape}: {exc}") from None
    table.add(block)
    if not stamps:
        raise ValueError(shape)
    weights = table.array(len(columns))
    stamps = np.array(stamps, dtype=np.int64)
    seconds = (stamps[:, 0] * 60 + stamps[:, 1]) * 60 + stamps[:, 2]
    seconds -= seconds.min()  # within 4 hours (check_span): the products below stay far inside int64
    if fps is None:
        if len(np.unique(seconds)) < 2:
            raise ValueError(f"{path.name}: its Timecodes stay within one second, which does not tell the "
                             "frame rate: pass --fps")
        fps = float(stamps[:, 3].max() + 1)
        if fps > READ.MAX_FPS:
            raise ValueError(f"{path.name}: its Timecodes count {fps:.0f} frames in a second, more than "
                             f"facegen plays ({READ.MAX_FPS:g}): pass --fps")
    head = None
    if turns:  # the last three columns read
        head, weights = np.degrees(weights[:, -3:].astype(np.float64)), weights[:, :-3]
    whole = seconds * round(fps) + stamps[:, 3]
    # ".mmm" is a sub-frame: only used when rows share a whole frame (e.g. 60 Hz rows on a 30 fps timecode)
    frames = whole + stamps[:, 4] / 1000.0 if len(np.unique(whole)) < len(whole) else whole.astype(np.float64)
    return {"names": ark, "weights": weights, "frames": frames - frames[0], "fps": float(fps),
            "audio_name": None, "head": head}


# ---- keying (bpy) ------------------------------------------------------------------------------------------


def arkit_keys(obj) -> dict[str, list]:
    """{ARKit name: [shape keys of `obj` named for it]} (the reference key excluded)."""
    keys = getattr(obj.data, "shape_keys", None) if obj.data is not None else None
    found: dict[str, list] = {}
    if keys is None:
        return found
    for block in keys.key_blocks:
        name = arkit_name(block.name) if block != keys.reference_key else None
        if name is not None:
            found.setdefault(name, []).append(block)
    return found


def key_shapes(objects, clip: dict, name: str = "facegen ARKit") -> dict:
    """Key `clip`'s weights (from read_weights) onto the ARKit-named shape keys of `objects`: one new action
    per object's shape keys. Returns {"matched": {ARKit name: ["object/key", ...]}, "unmatched": ARKit names
    of the clip no shape key stands for, "keys": number of F-curves written}. Raises ValueError (one line) for
    an object without any ARKit-named shape key."""
    found = {}
    for obj in objects:
        blocks = arkit_keys(obj)
        if not blocks:
            keys = getattr(obj.data, "shape_keys", None) if obj.data is not None else None
            have = ", ".join(b.name for b in keys.key_blocks) if keys is not None else ""
            has = f"its shape keys are {have}" if have else "it has no shape keys"
            raise ValueError(f"object {obj.name!r} has no shape key named like ARKit's (jawOpen, "
                             f"eyeBlinkLeft, blendShape1.mouthSmile_L, ...): {has}")
        found[obj] = blocks
    column: dict[str, int] = {}
    for i, shape in enumerate(clip["names"]):
        column.setdefault(shape, i)  # a name given twice: the first column, as the three.js player does
    count = len(clip["frames"])
    co = np.empty((count, 2), np.float32)
    co[:, 0] = clip["frames"]
    linear = np.full(count, _enum_value("LINEAR"), np.int32)
    matched: dict[str, list[str]] = {}
    written = 0
    for obj, blocks in found.items():
        keys = obj.data.shape_keys
        action = _new_action(keys, name)
        for shape, members in blocks.items():
            if shape not in column:
                continue
            co[:, 1] = clip["weights"][:, column[shape]]
            for block in members:
                fcurve = _fcurve(action, keys, block.path_from_id("value"))
                fcurve.keyframe_points.add(count)
                fcurve.keyframe_points.foreach_set("co", co.ravel())
                fcurve.keyframe_points.foreach_set("interpolation", linear)
                fcurve.update()
                matched.setdefault(shape, []).append(f"{obj.name}/{block.name}")
                written += 1
    unmatched = [n for n in column if n not in matched]
    return {"matched": matched, "unmatched": unmatched, "keys": written}


def key_head(obj, clip: dict, name: str = "facegen head") -> int:
    """Key the clip's head motion (read_weights' "head") onto `obj` (the head, or the character's root) as its
    delta rotation, in a new action: the object keeps its own rotation and turns on top of it, about its
    origin, as facegen's head turns about the top of the neck. facegen's angles are about its Y-up axes
    (yaw about up, pitch about x, roll about the facing axis: Ry(yaw) Rx(pitch) Rz(roll)); in Blender's Z-up
    world, as its glTF and USD importers bring facegen's face in (facing -Y), that is Rz(yaw) Rx(pitch)
    Ry(-roll): rotation mode YXZ with (pitch, -roll, yaw). Returns the number of frames keyed (0: no head
    motion in the clip)."""
    head = clip.get("head")
    if head is None:
        return 0
    radians = np.radians(np.asarray(head, np.float64))
    obj.rotation_mode = "YXZ"  # Blender converts the object's own rotation to the new order
    action = _new_action(obj, name)
    count = len(clip["frames"])
    co = np.empty((count, 2), np.float32)
    co[:, 0] = clip["frames"]
    linear = np.full(count, _enum_value("LINEAR"), np.int32)
    for axis, values in enumerate((radians[:, 1], -radians[:, 2], radians[:, 0])):
        co[:, 1] = values
        fcurve = _fcurve(action, obj, "delta_rotation_euler", axis)
        fcurve.keyframe_points.add(count)
        fcurve.keyframe_points.foreach_set("co", co.ravel())
        fcurve.keyframe_points.foreach_set("interpolation", linear)
        fcurve.update()
    return count


def apply_weights(path: Path, clip: dict, target, scene, head=None) -> tuple[dict, dict]:
    """Key an ARKit JSON/CSV's weights (read_weights) onto the shape keys of `target` (objects or names; None:
    every object of `scene` with ARKit-named keys), its head motion onto `head` (key_head); (what was done:
    key_shapes' result, objects, frames, head; {"audio", "warnings"}). facegen_import sets the scene's fps."""
    import bpy

    turned = bpy.data.objects.get(head) if isinstance(head, str) else head
    if head is not None and turned is None:
        raise ValueError(f"no object named {head!r} for the head: the objects are {_names(bpy.data.objects)}")
    if target is None:
        objects = [o for o in scene.objects if arkit_keys(o)]
        if not objects:
            raise ValueError(f"{path.name}: no object in the scene has shape keys named like ARKit's: "
                             f"pass the character as target (objects: {_names(scene.objects)})")
    else:
        objects = []
        for item in target if isinstance(target, list | tuple) else [target]:
            obj = bpy.data.objects.get(item) if isinstance(item, str) else item
            if obj is None:
                raise ValueError(f"no object named {item!r}: the objects are {_names(bpy.data.objects)}")
            objects.append(obj)
    done = key_shapes(objects, clip, name=f"facegen ARKit {path.stem}")
    warnings = []
    if turned is not None and clip["head"] is not None:
        key_head(turned, clip, name=f"facegen head {path.stem}")
    elif turned is not None:
        warnings.append(f"{path.name} has no head motion: {turned.name} was not keyed")
    elif clip["head"] is not None:
        warnings.append(f"{path.name} has head motion, left out: pass the head (or the character's root) as "
                        "--head OBJECT to turn it")
    frames = math.ceil(float(clip["frames"][-1])) + 1
    done.update(objects=[o.name for o in objects], frames=frames,
                head=turned.name if turned is not None and clip["head"] is not None else None)
    return done, {"audio": clip["audio"], "warnings": warnings}


def _names(objects) -> str:
    names = sorted(o.name for o in objects)
    return ", ".join(names) if names else "none"


def _enum_value(item: str) -> int:
    import bpy

    return bpy.types.Keyframe.bl_rna.properties["interpolation"].enum_items[item].value


def _new_action(keys, name: str):
    """A new action animating `keys` (a Key datablock, or an object), replacing the one it had."""
    import bpy

    action = bpy.data.actions.new(name)
    data = keys.animation_data or keys.animation_data_create()
    data.action = action
    return action


def _fcurve(action, keys, data_path: str, index: int = 0):
    if hasattr(action, "fcurve_ensure_for_datablock"):  # Blender 4.4+: layered actions
        return action.fcurve_ensure_for_datablock(keys, data_path, index=index)
    return action.fcurves.new(data_path, index=index)
