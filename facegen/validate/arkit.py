"""Checks on ARKit weight files (Audio2Face JSON, exchange/arkit_json.py; Live Link Face CSV,
exchange/arkit_csv.py), added to a Report, one finding per problem:

  file             the file parses: a JSON object / a CSV with a header row and frames, within facegen's
                   bounds (exchange/arkit_read.py: 4 hours, 512 MB; read in bounded memory)
  keys             (JSON) exportFps, numPoses, numFrames, facsNames and weightMat are there
  names            the 52 ARKit names (lowerCamel in JSON, UpperCamel in CSV), none missing, unknown or twice
  name order       (warning) the names in ARKit's / Live Link Face's order
  pose count       (JSON) numPoses equals the number of names, 52; every weightMat row holds that many weights
  fps              (JSON) exportFps is a finite number > 0 (and --fps when given)
  frame count      (JSON) numFrames equals the rows of weightMat, at least one; every row is a list
  row length       (CSV) every row has a value per column
  BlendShapeCount  (CSV) every row's count is the number of shape and rotation columns (61)
  timecode         (CSV) every timecode is HH:MM:SS:FF[.mmm] and they increase row by row
  finite           every weight (and rotation) is a finite number: in JSON a number, not a string ("0.5")
  range            every weight is in [0, 1]
  fit              (warning; JSON written by facegen) the fit's mean reconstruction error on the lips and the
                   whole face, in mm: above the 0.5 mm lip target it warns
  audio, audio duration   the audio (`audio_path`, else the file's trackPath / WAV sidecar), as in
                   checks.py; a trackPath that is not text, or names what is not a regular file, fails "audio"

The rows are checked as they are read, a block at a time: nothing holds the whole table.
"""

from __future__ import annotations

import bisect
import csv
import math
import os
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import numpy as np

from facegen.animation import DEFAULT_FPS
from facegen.arkit.names import ARKIT_NAMES, LIVE_LINK_COLUMNS, LIVE_LINK_ROTATIONS
from facegen.exchange import arkit_read
from facegen.exchange.arkit_csv import parse_timecode
from facegen.exchange.wav import sidecar_path
from facegen.input_files import open_input
from facegen.validate.checks import check_duration, read_audio, shown
from facegen.validate.report import Expected, Report

JSON_KEYS = ("exportFps", "numPoses", "numFrames", "facsNames", "weightMat")
LIP_ERROR_TARGET_MM = 0.5
RANGE_SLACK = 1e-6  # weights may exceed [0, 1] by float rounding only
_NUMBER_TYPES = {float, int}


def check(report: Report, path: Path, expected: Expected) -> None:
    """Add the ARKit weight-file checks for `path` (.json or .csv) to `report`; never raises for a bad
    file."""
    is_csv = path.suffix.lower() == ".csv"
    try:
        with open_input(path) as file:
            read = _read_csv(file, expected.fps) if is_csv else _read_json(file)
    except OSError as exc:
        report.add("file", False, f"cannot read {path.name} ({exc.strerror or exc})")
        return
    except arkit_read.TooLarge as exc:
        report.add("file", False, f"{path.name}: {exc}")
        return
    except (ValueError, csv.Error) as exc:  # not JSON / CSV, not UTF-8
        report.add("file", False, f"cannot read {path.name} as {'CSV' if is_csv else 'JSON'} ({exc})")
        return
    frames, fps, tracks = (_check_csv if is_csv else _check_json)(report, path, expected, read)
    if frames is not None:
        _check_audio(report, path, expected, frames, fps, tracks)


class _Weights:
    """finite + range over values met a block at a time: `count` values, `not_numbers` of them no number at
    all (JSON text, null, true; CSV text), the first of these said in `first`; `bad` numbers not finite."""

    def __init__(self) -> None:
        self.count = self.not_numbers = self.bad = self.outside = 0
        self.first, self.low, self.high = "", math.inf, -math.inf

    def add(self, values: list, where: Callable[[int], str], number: Callable) -> None:
        """`values` of a block; `number(value)`: the value as a float, None when it is no number; `where(i)`
        says where the i-th value is ("row 3, weight 5")."""
        try:  # the common case at C speed: JSON numbers / CSV cells that are numbers
            if number is _json_number and not set(map(type, values)) <= _NUMBER_TYPES:
                raise ValueError("not only numbers")
            return self._measure(np.array(values, np.float64))
        except (ValueError, OverflowError):  # text among them; an integer of hundreds of digits
            pass
        floats = []
        for i, value in enumerate(values):
            as_float = number(value)
            if as_float is None:
                self.count += 1
                self.not_numbers += 1
                self.first = self.first or f"{where(i)} is {arkit_read.short(value)}"
            else:
                floats.append(as_float)
        self._measure(np.array(floats, np.float64))

    def _measure(self, values: np.ndarray) -> None:
        finite = values[np.isfinite(values)]
        self.count += len(values)
        self.bad += len(values) - len(finite)
        self.outside += int(((finite < -RANGE_SLACK) | (finite > 1 + RANGE_SLACK)).sum())
        if len(finite):
            self.low, self.high = min(self.low, float(finite.min())), max(self.high, float(finite.max()))

    @property
    def ok(self) -> bool:
        return not self.bad and not self.not_numbers


def _json_number(value) -> float | None:
    """A JSON value as a weight: a number (inf past float's range); None for text ("0.5"), null, true, ..."""
    if type(value) not in _NUMBER_TYPES:
        return None
    try:
        return float(value)
    except OverflowError:
        return math.inf


def _cell_number(cell: str) -> float | None:
    try:
        return float(cell)
    except ValueError:
        return None


def _check_weights(report: Report, weights: _Weights, turns: _Weights | None = None) -> None:
    turns = turns or _Weights()
    if weights.ok and turns.ok:
        detail = f"{weights.count} weights" + (f" and {turns.count} rotations" if turns.count else "")
        report.add("finite", True, detail + " are finite numbers")
    else:
        detail = f"{weights.bad + weights.not_numbers} of {weights.count} weights" + (
            f", {turns.bad + turns.not_numbers} of {turns.count} rotations" if not turns.ok else "")
        first = weights.first or turns.first
        report.add("finite", False, detail + " are not finite numbers" + (f" ({first})" if first else ""))
    span = f"{weights.low:.4g} .. {weights.high:.4g}" if weights.high >= weights.low else "no weights"
    report.add("range", weights.outside == 0 and weights.high >= weights.low,
               f"weights {span}" + (f": {weights.outside} outside [0, 1]" if weights.outside
                                    else ", within [0, 1]"))


# ---- Audio2Face JSON -------------------------------------------------------------------------------------


class _JsonRows:
    """weightMat's rows as they are read: how many, the first row of each length, the first that is no list,
    and their weights."""

    def __init__(self) -> None:
        self.count, self.lengths, self.not_list = 0, {}, None
        self.weights = _Weights()

    def add(self, block: list) -> None:
        values, starts = [], []
        for i, row in enumerate(block, self.count):
            if type(row) is list:
                self.lengths.setdefault(len(row), i)
                starts.append(len(values))
                values.extend(row)
            elif self.not_list is None:
                self.not_list = i
        first = self.count

        def where(k: int) -> str:
            row = bisect.bisect_right(starts, k) - 1
            return f"weightMat row {first + row}, weight {k - starts[row]}"

        self.count += len(block)
        self.weights.add(values, where, _json_number)


def _read_json(file) -> tuple[dict, _JsonRows | None]:
    rows = _JsonRows()
    doc, count = arkit_read.read_json(file, rows.add)
    return doc, (rows if count is not None else None)


def _check_json(report: Report, path: Path, expected: Expected, read) -> tuple[int | None, float, list]:
    doc, rows = read
    report.add("file", True, f"JSON object with keys {', '.join(map(arkit_read.short, doc))}"
               + (", weightMat" if rows is not None else ""))
    missing = [k for k in JSON_KEYS if k not in doc and not (k == "weightMat" and rows is not None)]
    report.add("keys", not missing, "all Audio2Face keys present" if not missing
               else f"missing {', '.join(missing)} (Audio2Face files have {', '.join(JSON_KEYS)})")
    names = doc.get("facsNames")
    if isinstance(names, list) and all(isinstance(n, str) for n in names):
        _check_names(report, names, ARKIT_NAMES, "facsNames")
    elif "facsNames" in doc:
        report.add("names", False, "facsNames is not a list of names")
    if rows is None and "weightMat" in doc:
        report.add("frame count", False, "weightMat is not a list of rows (one list of weights per frame)")
    poses = doc.get("numPoses")
    if "numPoses" in doc:
        width = len(names) if isinstance(names, list) else len(ARKIT_NAMES)
        lengths = rows.lengths if rows is not None else {}
        bad = min((i for n, i in lengths.items() if n != poses), default=None)
        ok = _is_number(poses) and poses == width == len(ARKIT_NAMES) and bad is None
        wrong = next((n for n, i in lengths.items() if i == bad), None)
        detail = f"numPoses {arkit_read.short(poses)}, {width} names" + (
            f"; weightMat row {bad} holds {wrong} weights" if bad is not None else "")
        report.add("pose count", ok, detail + ("" if ok else f" (ARKit has {len(ARKIT_NAMES)})"))
    fps = arkit_read.rate_of(doc.get("exportFps"))
    if "exportFps" in doc:
        matches = fps is None or expected.fps is None or abs(fps - expected.fps) < 1e-6
        report.add("fps", fps is not None and matches, f"exportFps {arkit_read.short(doc['exportFps'])}" + (
            "" if fps is not None else ": must be a finite number > 0") + (
            "" if matches else f", expected {expected.fps:g}"))
    frames = doc.get("numFrames")
    if rows is not None:
        if "numFrames" in doc:
            ok = _is_number(frames) and frames == rows.count > 0 and rows.not_list is None
            report.add("frame count", ok, f"numFrames {arkit_read.short(frames)}, weightMat has {rows.count} "
                       "rows" + ("" if rows.not_list is None else f"; row {rows.not_list} is not a list")
                       + ("" if ok else " (must be equal and at least one, each a list of weights)"))
        _check_weights(report, rows.weights)
    facegen = doc.get("facegen")
    _report_fit(report, facegen)
    tracks = [("trackPath", doc.get("trackPath"))]
    if isinstance(facegen, dict):
        tracks.append(("facegen.audio", facegen.get("audio")))
    return (rows.count if rows is not None else None), fps or DEFAULT_FPS, tracks


# ---- Live Link Face CSV ----------------------------------------------------------------------------------


class _CsvRows:
    """A Live Link Face CSV's rows as they are read: per check the first row that fails it (rows counted from
    1 after the header), the Timecodes' course, the weights and rotations of the full rows."""

    def __init__(self, header: list[str], fps: float | None) -> None:
        self.header, self.fps = [c.strip() for c in header], fps
        column = {c: i for i, c in enumerate(self.header)}
        self.rotations = [c for c in self.header if c in LIVE_LINK_ROTATIONS]
        self.shapes = [i for c, i in column.items() if c not in ("Timecode", "BlendShapeCount")
                       and c not in self.rotations]
        self.turn_columns = [column[c] for c in self.rotations]
        self.count_column, self.time_column = column.get("BlendShapeCount"), column.get("Timecode")
        self.stated = str(len(self.shapes) + len(self.rotations))
        self.count, self.short, self.wrong_count = 0, None, None
        self.first_cell, self.last_cell, self.bad_time, self.back, self.over, self.previous = (None,) * 6
        self.first_second, self.seconds, self.max_frame = None, set(), 0
        self.weights, self.turns, self.block = _Weights(), _Weights(), []

    def add(self, row: list[str]) -> None:
        self.count += 1
        arkit_read.check_frames(self.count, None, more=True)
        if len(row) != len(self.header) and self.short is None:
            self.short = (self.count, len(row))
        if self.count_column is not None and self.wrong_count is None and _cell(
                row, self.count_column) != self.stated:
            self.wrong_count = (self.count, _cell(row, self.count_column))
        if self.time_column is not None:
            self._timecode(_cell(row, self.time_column))
        if len(row) == len(self.header):  # short rows are the "row length" finding
            self.block.append((self.count, row))
            if len(self.block) == arkit_read.BLOCK:
                self.flush()

    def _timecode(self, cell: str) -> None:
        self.first_cell = cell if self.first_cell is None else self.first_cell
        self.last_cell = cell
        parsed = parse_timecode(cell) if self.bad_time is None else None
        if parsed is None:
            self.bad_time = self.bad_time or (self.count, cell)
            return
        self.first_second = parsed[0] if self.first_second is None else self.first_second
        arkit_read.check_span(parsed[0] - self.first_second)
        if self.back is None and self.previous is not None and parsed <= self.previous[0]:
            self.back = (self.count, cell, self.previous[1])
        self.previous = (parsed, cell)
        if len(self.seconds) < 3:
            self.seconds.add(parsed[0])
        self.max_frame = max(self.max_frame, parsed[1])
        if self.fps is not None and self.over is None and parsed[1] >= math.ceil(self.fps):
            self.over = (self.count, parsed[1], cell)

    def flush(self) -> None:
        numbers, rows = [n for n, _ in self.block], [r for _, r in self.block]
        self.block = []
        for columns, scan in ((self.shapes, self.weights), (self.turn_columns, self.turns)):
            if not columns:
                continue

            def where(k: int, columns=columns) -> str:
                return f"row {numbers[k // len(columns)]}, {self.header[columns[k % len(columns)]]}"

            scan.add([r[i].strip() for r in rows for i in columns], where, _cell_number)


def _read_csv(file, fps: float | None) -> _CsvRows | None:
    rows = arkit_read.csv_rows(file)
    header = next(rows, None)
    if not header:
        return None
    table = _CsvRows(header, fps)
    for row in rows:
        table.add(row)
    table.flush()
    return table


def _check_csv(report: Report, path: Path, expected: Expected, table: _CsvRows | None
               ) -> tuple[int | None, float, list]:
    if table is None or not table.count:
        report.add("file", False, f"{path.name} has {'no header' if table is None else 'no frames'}: "
                                  "Live Link Face CSV has a header row and one row per frame")
        return None, DEFAULT_FPS, []
    header = table.header
    report.add("file", True, f"CSV with {len(header)} columns and {table.count} frames")
    shape_columns = LIVE_LINK_COLUMNS[2 : len(LIVE_LINK_COLUMNS) - len(LIVE_LINK_ROTATIONS)]
    fixed = [c for c in ("Timecode", "BlendShapeCount") if c not in header]
    _check_names(report, [header[i] for i in table.shapes], shape_columns, "columns", fixed)
    short = table.short
    report.add("row length", short is None, f"every row has {len(header)} values" if short is None
               else f"row {short[0]} has {short[1]} values, the header {len(header)} columns")
    if table.count_column is not None:
        wrong = table.wrong_count
        report.add("BlendShapeCount", wrong is None, f"{table.stated} in every row (shape and rotation "
                   "columns)" if wrong is None else f"row {wrong[0]} says {arkit_read.short(wrong[1])}, the "
                                                    f"file has {table.stated} shape and rotation columns")
    fps = expected.fps
    if table.time_column is not None:
        fps = _check_timecodes(report, table, expected.fps)
    _check_weights(report, table.weights, table.turns)
    return table.count, fps or DEFAULT_FPS, []


def _check_names(report: Report, names: list[str], canonical: tuple[str, ...], what: str,
                 missing_fixed: list[str] = ()) -> None:
    missing = [n for n in canonical if n not in names] + list(missing_fixed)
    unknown = [arkit_read.short(n) for n in names if n not in canonical]
    counts = Counter(names)
    twice = sorted(n for n, c in counts.items() if c > 1)
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


def _check_timecodes(report: Report, table: _CsvRows, fps: float | None) -> float | None:
    """The timecode check; returns `fps`, else the frames per second the timecodes count (None if unknown)."""
    if table.bad_time is not None:
        row, cell = table.bad_time
        report.add("timecode", False, f"row {row}: {arkit_read.short(cell)} is not HH:MM:SS:FF[.mmm]")
        return fps
    counted = table.max_frame + 1 if len(table.seconds) > 2 else None  # a whole second in the middle
    first, last = _text(table.first_cell), _text(table.last_cell)
    detail = f"{first} .. {last}, increasing" + (f"; {counted} frames per second" if counted else "")
    if table.back is not None:
        row, cell, before = table.back
        detail = f"row {row}: {_text(cell)} does not come after {_text(before)}"
    elif table.over is not None:
        row, frame, cell = table.over
        detail = f"row {row}: frame {frame} in {_text(cell)} does not exist at {fps:g} fps"
    report.add("timecode", table.back is None and table.over is None, detail)
    return fps if fps is not None else counted


def _report_fit(report: Report, info) -> None:
    if not isinstance(info, dict):
        return
    lip, face = info.get("lip_error_mm"), info.get("face_error_mm")
    if not (_is_number(lip) and _is_number(face) and math.isfinite(lip) and math.isfinite(face)):
        report.add("fit", False, "the facegen key has no lip_error_mm / face_error_mm numbers",
                   severity="warning")
        return
    report.add("fit", lip <= LIP_ERROR_TARGET_MM,
               f"52-shape fit error (mean per vertex): lips {lip:.3f} mm, whole face {face:.3f} mm"
               + ("" if lip <= LIP_ERROR_TARGET_MM else f" (lips above the {LIP_ERROR_TARGET_MM} mm target)"),
               severity="warning")


def _check_audio(report: Report, path: Path, expected: Expected, frames: int, fps: float,
                 tracks: list[tuple[str, object]]) -> None:
    """The audio: `audio_path`, else the first of the file's tracks (trackPath, facegen.audio; relative to
    the file) that exists, else the WAV sidecar. A track that is not text fails, and so does one naming a
    FIFO, a device or a folder (read_audio's reader refuses them): the file points at it."""
    bad = next(((key, t) for key, t in tracks if t is not None and not isinstance(t, str)), None)
    if expected.audio_path is None and bad is not None:
        report.add("audio", False, f"{bad[0]} is {arkit_read.short(bad[1])}, not the path of an audio file "
                                   "('' without audio)")
        check_duration(report, frames, fps, None, True)
        return
    candidates = [Path(expected.audio_path)] if expected.audio_path is not None else (
        [path.parent / t for _, t in tracks if t] + [sidecar_path(path)])
    wav = next((c for c in candidates if _exists(c)), None)
    audio = None
    if wav is not None:
        audio = read_audio(report, "audio", wav, shown(wav))
    else:
        report.add("audio", not expected.require_audio,
                   f"no audio file {shown(candidates[-1])}" + ("" if expected.require_audio
                                                               else " (not required)"))
    check_duration(report, frames, fps, audio, expected.require_audio)


def _exists(path: Path) -> bool:
    """Whether something is at `path` (links followed); True also when asking fails otherwise than by its
    absence (a NUL byte, a name too long): the reader says why it cannot be read."""
    try:
        os.stat(path)
    except (FileNotFoundError, NotADirectoryError):
        return False
    except (OSError, ValueError):
        return True
    return True


def _text(cell: str) -> str:
    """A cell as it is, when it is short and printable; else its repr, cut (one line, any length of file)."""
    return cell if len(cell) <= 40 and cell.isprintable() else arkit_read.short(cell)


def _cell(row: list[str], index: int) -> str:
    return row[index].strip() if index < len(row) else ""


def _is_number(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)
