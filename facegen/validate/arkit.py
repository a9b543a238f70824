"""Checks on ARKit weight files (Audio2Face JSON, exchange/arkit_json.py; Live Link Face CSV,
exchange/arkit_csv.py), added to a Report, one finding per problem:

  file             the file parses: a JSON object / a CSV with a header row and frames
  keys             (JSON) exportFps, numPoses, numFrames, facsNames and weightMat are there
  names            the 52 ARKit names (lowerCamel in JSON, UpperCamel in CSV), none missing, unknown or twice
  name order       (warning) the names in ARKit's / Live Link Face's order
  pose count       (JSON) numPoses equals the number of names, 52; every weightMat row holds that many weights
  fps              (JSON) exportFps is a finite number > 0 (and --fps when given)
  frame count      (JSON) numFrames equals the rows of weightMat, at least one
  row length       (CSV) every row has a value per column
  BlendShapeCount  (CSV) every row's count is the number of shape and rotation columns (61)
  timecode         (CSV) every timecode is HH:MM:SS:FF[.mmm] and they increase row by row
  finite           every weight (and rotation) is a finite number
  range            every weight is in [0, 1]
  fit              (warning; JSON written by facegen) the fit's mean reconstruction error on the lips and the
                   whole face, in mm: above the 0.5 mm lip target it warns
  audio, audio duration   the audio (`audio_path`, else the file's track / WAV sidecar), as in checks.py
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np

from facegen.animation import DEFAULT_FPS
from facegen.arkit.names import ARKIT_NAMES, LIVE_LINK_COLUMNS, LIVE_LINK_ROTATIONS
from facegen.exchange.arkit_csv import parse_timecode
from facegen.exchange.wav import sidecar_path
from facegen.validate.checks import check_duration, read_audio
from facegen.validate.report import Expected, Report

JSON_KEYS = ("exportFps", "numPoses", "numFrames", "facsNames", "weightMat")
LIP_ERROR_TARGET_MM = 0.5
RANGE_SLACK = 1e-6  # weights may exceed [0, 1] by float rounding only


def check(report: Report, path: Path, expected: Expected) -> None:
    """Add the ARKit weight-file checks for `path` (.json or .csv) to `report`; never raises for a bad
    file."""
    if path.suffix.lower() == ".csv":
        frames, fps, tracks = _check_csv(report, path, expected)
    else:
        frames, fps, tracks = _check_json(report, path, expected)
    if frames is None:
        return
    _check_audio(report, path, expected, frames, fps, tracks)


def _check_json(report: Report, path: Path, expected: Expected) -> tuple[int | None, float, list[str]]:
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        report.add("file", False, f"cannot read {path.name} as JSON ({exc})")
        return None, DEFAULT_FPS, []
    if not isinstance(doc, dict):
        report.add("file", False, f"{path.name} holds a JSON {type(doc).__name__}, not an Audio2Face object")
        return None, DEFAULT_FPS, []
    report.add("file", True, f"JSON object with keys {', '.join(doc)}")
    missing = [k for k in JSON_KEYS if k not in doc]
    report.add("keys", not missing, "all Audio2Face keys present" if not missing
               else f"missing {', '.join(missing)} (Audio2Face files have {', '.join(JSON_KEYS)})")
    names = doc.get("facsNames")
    if isinstance(names, list) and all(isinstance(n, str) for n in names):
        _check_names(report, names, ARKIT_NAMES, "facsNames")
    elif "facsNames" in doc:
        report.add("names", False, "facsNames is not a list of names")
    rows = doc.get("weightMat")
    rows = rows if isinstance(rows, list) and all(isinstance(r, list) for r in rows) else None
    if rows is None and "weightMat" in doc:
        report.add("frame count", False, "weightMat is not a list of rows (one list of weights per frame)")
    poses = doc.get("numPoses")
    if "numPoses" in doc:
        width = len(names) if isinstance(names, list) else len(ARKIT_NAMES)
        bad = next((i for i, r in enumerate(rows or []) if len(r) != poses), None)
        ok = _is_number(poses) and poses == width == len(ARKIT_NAMES) and bad is None
        detail = f"numPoses {poses!r}, {width} names" + (
            f"; weightMat row {bad} holds {len(rows[bad])} weights" if bad is not None else "")
        report.add("pose count", ok, detail + ("" if ok else f" (ARKit has {len(ARKIT_NAMES)})"))
    fps = doc.get("exportFps")
    fps_ok = _is_number(fps) and math.isfinite(fps) and fps > 0
    if "exportFps" in doc:
        matches = not fps_ok or expected.fps is None or abs(fps - expected.fps) < 1e-6
        report.add("fps", fps_ok and matches, f"exportFps {fps!r}" + (
            "" if fps_ok else ": must be a finite number > 0") + ("" if matches
                                                                  else f", expected {expected.fps:g}"))
    frames = doc.get("numFrames")
    if rows is not None and "numFrames" in doc:
        ok = _is_number(frames) and frames == len(rows) > 0
        report.add("frame count", ok, f"numFrames {frames!r}, weightMat has {len(rows)} rows"
                   + ("" if ok else " (must be equal and at least one)"))
    if rows is not None:
        _check_weights(report, [v for r in rows for v in r], [])
    _report_fit(report, doc.get("facegen"))
    tracks = [t for t in (doc.get("trackPath"), (doc.get("facegen") or {}).get("audio")) if isinstance(t, str)
              and t]
    return (len(rows) if rows is not None else None), (float(fps) if fps_ok else DEFAULT_FPS), tracks


def _check_csv(report: Report, path: Path, expected: Expected) -> tuple[int | None, float, list[str]]:
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            table = list(csv.reader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        report.add("file", False, f"cannot read {path.name} as CSV ({exc})")
        return None, DEFAULT_FPS, []
    if len(table) < 2 or not table[0]:
        report.add("file", False, f"{path.name} has {'no header' if not table else 'no frames'}: "
                                  "Live Link Face CSV has a header row and one row per frame")
        return None, DEFAULT_FPS, []
    header, rows = [c.strip() for c in table[0]], table[1:]
    report.add("file", True, f"CSV with {len(header)} columns and {len(rows)} frames")
    shape_columns = LIVE_LINK_COLUMNS[2 : len(LIVE_LINK_COLUMNS) - len(LIVE_LINK_ROTATIONS)]
    fixed = [c for c in ("Timecode", "BlendShapeCount") if c not in header]
    rotations = [c for c in header if c in LIVE_LINK_ROTATIONS]
    _check_names(report, [c for c in header if c not in ("Timecode", "BlendShapeCount")
                          and c not in rotations],
                 shape_columns, "columns", fixed)
    bad = next((i for i, r in enumerate(rows) if len(r) != len(header)), None)
    report.add("row length", bad is None, f"every row has {len(header)} values" if bad is None
               else f"row {bad + 1} has {len(rows[bad])} values, the header {len(header)} columns")
    column = {c: i for i, c in enumerate(header)}
    shapes = [i for c, i in column.items() if c not in ("Timecode", "BlendShapeCount") and c not in rotations]
    if "BlendShapeCount" in column:
        count = len(shapes) + len(rotations)
        wrong = next((i for i, r in enumerate(rows) if _cell(r, column["BlendShapeCount"]) != str(count)),
                     None)
        report.add("BlendShapeCount", wrong is None, f"{count} in every row (shape and rotation columns)"
                   if wrong is None else f"row {wrong + 1} says "
                                         f"{_cell(rows[wrong], column['BlendShapeCount'])!r}, the file has "
                                         f"{count} shape and rotation columns")
    fps = expected.fps
    if "Timecode" in column:
        fps = _check_timecodes(report, [_cell(r, column["Timecode"]) for r in rows], expected.fps)
    full = [r for r in rows if len(r) == len(header)]  # short rows are the "row length" finding
    _check_weights(report, [_cell(r, i) for r in full for i in shapes],
                   [_cell(r, column[c]) for r in full for c in rotations])
    return len(rows), fps or DEFAULT_FPS, []


def _check_names(report: Report, names: list[str], canonical: tuple[str, ...], what: str,
                 missing_fixed: list[str] = ()) -> None:
    missing = [n for n in canonical if n not in names] + list(missing_fixed)
    unknown = [n for n in names if n not in canonical]
    twice = sorted({n for n in names if names.count(n) > 1})
    problems = [f"missing {', '.join(missing)}" if missing else "", f"unknown {', '.join(unknown)}" if unknown
                else "",
                f"twice: {', '.join(twice)}" if twice else ""]
    ok = not any(problems)
    report.add("names", ok, f"{len(names)} {what}: the {len(canonical)} ARKit shapes" if ok
               else f"{len(names)} {what}: " + "; ".join(p for p in problems if p))
    if ok:
        same = tuple(names) == canonical
        report.add("name order", same, "in ARKit's order" if same else "the ARKit shapes in another order "
                                                                       "(importers that read by position "
                                                                       "differ)",
                   severity="warning")


def _check_timecodes(report: Report, cells: list[str], fps: float | None) -> float | None:
    """The timecode check; returns `fps`, else the frames per second the timecodes count (None if unknown)."""
    parsed = [parse_timecode(c) for c in cells]
    bad = next((i for i, p in enumerate(parsed) if p is None), None)
    if bad is not None:
        report.add("timecode", False, f"row {bad + 1}: {cells[bad]!r} is not HH:MM:SS:FF[.mmm]")
        return fps
    back = next((i for i in range(1, len(parsed)) if parsed[i] <= parsed[i - 1]), None)
    seconds = {p[0] for p in parsed}
    counted = max(p[1] for p in parsed) + 1 if len(seconds) > 2 else None  # a whole second in the middle
    over = None if fps is None else next((i for i, p in enumerate(parsed) if p[1] >= math.ceil(fps)), None)
    detail = f"{cells[0]} .. {cells[-1]}, increasing" + (f"; {counted} frames per second" if counted else "")
    if back is not None:
        detail = f"row {back + 1}: {cells[back]} does not come after {cells[back - 1]}"
    elif over is not None:
        detail = f"row {over + 1}: frame {parsed[over][1]} in {cells[over]} does not exist at {fps:g} fps"
    report.add("timecode", back is None and over is None, detail)
    return fps if fps is not None else counted


def _check_weights(report: Report, weights: list, rotations: list) -> None:
    values = np.array([_number(v) for v in weights], np.float64)
    turns = np.array([_number(v) for v in rotations], np.float64)
    bad, bad_turns = int((~np.isfinite(values)).sum()), int((~np.isfinite(turns)).sum())
    report.add("finite", not bad and not bad_turns, f"{len(values)} weights" + (
        f" and {len(turns)} rotations" if len(turns) else "") + " are finite numbers" if not bad
               and not bad_turns
        else f"{bad} of {len(values)} weights" + (f", {bad_turns} of {len(turns)} rotations" if bad_turns
                                                  else "")
        + " are not finite numbers")
    finite = values[np.isfinite(values)]
    outside = int(((finite < -RANGE_SLACK) | (finite > 1 + RANGE_SLACK)).sum())
    span = f"{finite.min():.4g} .. {finite.max():.4g}" if len(finite) else "no weights"
    report.add("range", outside == 0 and len(finite) > 0,
               f"weights {span}" + (f": {outside} outside [0, 1]" if outside else ", within [0, 1]"))


def _report_fit(report: Report, info) -> None:
    if not isinstance(info, dict):
        return
    lip, face = info.get("lip_error_mm"), info.get("face_error_mm")
    if not (_is_number(lip) and _is_number(face)):
        report.add("fit", False, "the facegen key has no lip_error_mm / face_error_mm numbers",
                   severity="warning")
        return
    report.add("fit", lip <= LIP_ERROR_TARGET_MM,
               f"52-shape fit error (mean per vertex): lips {lip:.3f} mm, whole face {face:.3f} mm"
               + ("" if lip <= LIP_ERROR_TARGET_MM else f" (lips above the {LIP_ERROR_TARGET_MM} mm target)"),
               severity="warning")


def _check_audio(report: Report, path: Path, expected: Expected, frames: int, fps: float,
                 tracks: list[str]) -> None:
    candidates = [Path(expected.audio_path)] if expected.audio_path is not None else (
        [path.parent / t for t in tracks] + [sidecar_path(path)])
    wav = next((c for c in candidates if c.is_file()), None)
    audio = None
    if wav is not None:
        audio = read_audio(report, "audio", wav, str(wav))
    else:
        report.add("audio", not expected.require_audio,
                   f"no audio file {candidates[-1]}" + ("" if expected.require_audio else " (not required)"))
    check_duration(report, frames, fps, audio, expected.require_audio)


def _cell(row: list[str], index: int) -> str:
    return row[index].strip() if index < len(row) else ""


def _is_number(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _number(value) -> float:
    """A weight as a float (NaN when it is not a number: text, null, true/false)."""
    if _is_number(value):
        return float(value)
    try:
        return float(value) if isinstance(value, str) else math.nan
    except ValueError:
        return math.nan
