"""ARKit-52 blend-shape weights (Audio2Face JSON, Live Link Face CSV) keyed onto a character's shape keys in
Blender, matched by name.

Reading needs numpy only; `key_shapes` needs bpy. Like facegen_import.py this file imports nothing from
facegen (Blender's Python does not have it): it loads ARKit's 52 names and their name rule (`arkit_name`) from
the file facegen/arkit/names.py itself, which the add-on zip carries beside it.

    clip = read_weights("out.json")  # or out.csv; {"names", "weights" [T, N], "frames" [T], "fps", ...}
    done = key_shapes([bpy.data.objects["Face"]], clip)   # {"matched": {...}, "unmatched": [...]}

Keys are written a whole F-curve at a time (keyframe_points.add + foreach_set), LINEAR between frames,
into a new action "facegen ARKit <file>" on each object's shape keys.
"""

from __future__ import annotations

import csv
import importlib.util
import json
import math
import re
from pathlib import Path

import numpy as np

ARKIT_EXTENSIONS = (".json", ".csv")


def _names():
    """facegen's arkit/names.py, the one list of ARKit's 52 names and the one name rule, loaded from its file
    (it needs only `re`): beside this file in the add-on zip (blender/package.py puts it there as
    arkit_names.py), else from facegen/arkit/ of the tree this file is in."""
    here = Path(__file__).resolve().parent
    for path in (here / "arkit_names.py", here.parent / "arkit" / "names.py"):
        if path.is_file():
            spec = importlib.util.spec_from_file_location("facegen_arkit_names", path)
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            return module
    raise ImportError(f"ARKit's names (arkit_names.py) are missing beside {here}: reinstall the add-on")


_NAMES = _names()
ARKIT_NAMES: tuple[str, ...] = _NAMES.ARKIT_NAMES
arkit_name = _NAMES.arkit_name
_TIMECODE = re.compile(r"^(\d+):(\d+):(\d+)[:;](\d+)(?:\.(\d+))?$")


# ---- reading (numpy only) ----------------------------------------------------------------------------------


def read_weights(path: str | Path, fps: float | None = None) -> dict:
    """ARKit weights from an Audio2Face JSON or a Live Link Face CSV: {"names": ARKit names of the columns,
    "weights": [T, N] float64, "frames": [T] key positions (frames from 0), "fps",
    "audio": the WAV the file names or the one beside it (same stem), or None}. `fps` overrides the file's.
    Raises ValueError (one line) when the file is not ARKit-shaped."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".json":
        clip = _read_json(path, fps)
    elif suffix == ".csv":
        clip = _read_csv(path, fps)
    else:
        raise ValueError(f"{path.name}: ARKit weights are read from .json (Audio2Face) or .csv (Live Link "
                         "Face)")
    if not np.isfinite(clip["weights"]).all():
        raise ValueError(f"{path.name}: the weights hold NaN or infinite values")
    audio = clip.pop("audio_name", None)
    wav = path.parent / audio if isinstance(audio, str) and audio else path.with_suffix(".wav")
    clip["audio"] = str(wav) if wav.is_file() else None
    return clip


def _columns(path: Path, names: list[str]) -> tuple[list[str], list[int]]:
    """The ARKit names among `names` and their column indices; ValueError when there is none."""
    found = [(arkit_name(n), i) for i, n in enumerate(names)]
    found = [(n, i) for n, i in found if n is not None]
    if not found:
        shown = ", ".join(names[:4]) + (", ..." if len(names) > 4 else "")
        raise ValueError(f"{path.name}: not ARKit-shaped: none of its shape names ({shown or 'none'}) is one "
                         "of ARKit's 52 (eyeBlinkLeft ... tongueOut)")
    return [n for n, _ in found], [i for _, i in found]


def _read_json(path: Path, fps: float | None) -> dict:
    shape = (f"{path.name}: not an Audio2Face blend-shape JSON "
             "(exportFps, facsNames, weightMat [frames][shapes])")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{shape}: {exc}") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("facsNames"), list) or "weightMat" not in doc:
        raise ValueError(shape)
    names = doc["facsNames"]
    if not all(isinstance(n, str) for n in names):
        raise ValueError(f"{shape}: facsNames must be strings")
    try:
        weights = np.asarray(doc["weightMat"], dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{shape}: weightMat is not a table of numbers") from None
    if weights.ndim != 2 or weights.shape[1] != len(names) or not len(weights):
        raise ValueError(f"{shape}: weightMat is {list(weights.shape)}, expected [frames, {len(names)}]")
    if doc.get("numFrames") is not None and doc["numFrames"] != len(weights):
        raise ValueError(f"{shape}: numFrames is {doc['numFrames']} but weightMat has {len(weights)} rows")
    rate = fps or doc.get("exportFps")
    if not isinstance(rate, int | float) or isinstance(rate, bool) or not rate > 0 or not math.isfinite(rate):
        raise ValueError(f"{shape}: exportFps must be a positive number (or pass --fps)")
    ark, columns = _columns(path, names)
    extra = doc.get("facegen")
    audio = extra.get("audio") if isinstance(extra, dict) else None
    return {"names": ark, "weights": weights[:, columns], "frames": np.arange(len(weights), dtype=np.float64),
            "fps": float(rate), "audio_name": audio}


def _read_csv(path: Path, fps: float | None) -> dict:
    shape = f"{path.name}: not a Live Link Face CSV (Timecode,BlendShapeCount,EyeBlinkLeft,...)"
    try:
        with path.open(newline="", encoding="utf-8-sig") as file:
            rows = [r for r in csv.reader(file) if r]
    except (UnicodeDecodeError, csv.Error) as exc:
        raise ValueError(f"{shape}: {exc}") from None
    if len(rows) < 2 or [h.strip().lower() for h in rows[0][:2]] != ["timecode", "blendshapecount"]:
        raise ValueError(shape)
    header = [h.strip() for h in rows[0]]
    ark, columns = _columns(path, header[2:])
    columns = [c + 2 for c in columns]
    stamps = []
    for number, row in enumerate(rows[1:], start=2):
        found = _TIMECODE.match(row[0].strip())
        if found is None or len(row) < len(header):
            raise ValueError(f"{shape}: row {number} has {len(row)} of {len(header)} columns or a Timecode "
                             f"{row[0]!r} that is not HH:MM:SS:FF.mmm")
        stamps.append([int(found.group(i)) for i in range(1, 5)]
                      + [int((found.group(5) or "0")[:3].ljust(3, "0"))])
    try:
        weights = np.array([[float(row[c]) for c in columns] for row in rows[1:]], dtype=np.float64)
    except ValueError as exc:
        raise ValueError(f"{shape}: {exc}") from None
    stamps = np.array(stamps, dtype=np.int64)
    seconds = (stamps[:, 0] * 60 + stamps[:, 1]) * 60 + stamps[:, 2]
    if fps is None:
        if len(np.unique(seconds)) < 2:
            raise ValueError(f"{path.name}: its Timecodes stay within one second, which does not tell the "
                             "frame rate: pass --fps")
        fps = float(stamps[:, 3].max() + 1)
    whole = seconds * round(fps) + stamps[:, 3]
    # ".mmm" is a sub-frame: only used when rows share a whole frame (e.g. 60 Hz rows on a 30 fps timecode)
    frames = whole + stamps[:, 4] / 1000.0 if len(np.unique(whole)) < len(whole) else whole.astype(np.float64)
    return {"names": ark, "weights": weights, "frames": frames - frames[0], "fps": float(fps),
            "audio_name": None}


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


def _enum_value(item: str) -> int:
    import bpy

    return bpy.types.Keyframe.bl_rna.properties["interpolation"].enum_items[item].value


def _new_action(keys, name: str):
    """A new action animating `keys` (a Key datablock), replacing the one it had."""
    import bpy

    action = bpy.data.actions.new(name)
    data = keys.animation_data or keys.animation_data_create()
    data.action = action
    return action


def _fcurve(action, keys, data_path: str):
    if hasattr(action, "fcurve_ensure_for_datablock"):  # Blender 4.4+: layered actions
        return action.fcurve_ensure_for_datablock(keys, data_path)
    return action.fcurves.new(data_path)
