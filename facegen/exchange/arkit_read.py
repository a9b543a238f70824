"""ARKit weight files (Audio2Face JSON, Live Link Face CSV) read within facegen's bounds and in bounded
memory, by `facegen validate` (validate/arkit.py) and by the Blender helper (blender/facegen_arkit.py). The
helper loads this file by its path, so it imports the standard library only (Blender's Python has no
facegen); the add-on zip carries it as arkit_read.py.

The bounds, the same for both; a file past one is refused as soon as it shows, mostly before its rows:

  MAX_SECONDS  4 hours, the longest audio facegen animates (audio.MAX_SECONDS): a JSON's numFrames or its
               rows at its exportFps (at MAX_FPS when it states no rate before its rows), a CSV's Timecodes
  MAX_FPS      240, the highest rate facegen writes (animation.MAX_FPS); a CSV holds at most 4 hours of rows
               at this rate
  MAX_BYTES    512 MB: 4 hours of facegen's own files (5 decimals, ~420 bytes a frame) at up to 60 fps (363
               MB), or at 25 fps with weights written at full float precision (~1.3 kB a frame)
  MAX_VALUE    16 MB for one JSON value other than weightMat (facsNames is 1 kB), MAX_LINE 1 MB for one CSV
               line (a Live Link Face row is ~500 bytes)

Why not json.load: it holds a Python float per weight, 4.3 GB for a 1,000,000-frame file before anything can
look at its size. Here the text is read in 1 MB pieces: every value but weightMat is parsed whole with json's
own scanner, weightMat's rows one by one and handed on in blocks, so memory stays at a few MB plus what the
caller keeps. Refusals are ValueErrors of one line: NotJson (not JSON, not an object, nested deeper than
Python's recursion limit), TooLarge (past a bound).
"""

from __future__ import annotations

import codecs
import csv
import io
import json
import math
import os
import re
from collections.abc import Callable, Iterator
from typing import BinaryIO

MAX_SECONDS = 4 * 3600
MAX_FPS = 240.0
MAX_BYTES = 512_000_000
MAX_VALUE = 16 << 20
MAX_LINE = 1 << 20
BLOCK = 4096  # weightMat rows handed on at once

_PIECE = 1 << 20
_SPACE = re.compile(r"[ \t\n\r]*")
_SCAN = json.JSONDecoder().scan_once  # one JSON value at an index: (value, end)
_AFTER_VALUE = ",]}:"  # what follows a value inside an object or an array, or a key


class NotJson(ValueError):
    """The text is not JSON, or not a JSON object, or nested too deeply to parse."""


class TooLarge(ValueError):
    """The file is past one of the bounds."""


def check_size(file: BinaryIO) -> None:
    """Refuse a file larger than MAX_BYTES before reading it."""
    size = os.fstat(file.fileno()).st_size
    if size > MAX_BYTES:
        raise TooLarge(f"it is {size / 1e6:.0f} MB, more than facegen reads as ARKit weights "
                       f"({MAX_BYTES / 1e6:.0f} MB, {_hours(MAX_SECONDS)} at 60 fps): cut it into parts")


def rate_of(value) -> float | None:
    """`value` as a frame rate: a finite number > 0 (not a bool), else None."""
    if not isinstance(value, int | float) or isinstance(value, bool):
        return None
    try:
        rate = float(value)
    except OverflowError:  # an integer of hundreds of digits
        return None
    return rate if 0 < rate < math.inf else None


def check_frames(frames: int, fps: float | None, more: bool = False) -> None:
    """Refuse `frames` frames (`more`: counted so far) lasting longer than MAX_SECONDS at `fps` (a rate above
    MAX_FPS counts as MAX_FPS; unknown: MAX_FPS)."""
    rate = min(fps or MAX_FPS, MAX_FPS)
    if frames > MAX_SECONDS * rate:
        said = "" if fps else f" (it states no rate: {MAX_FPS:g} fps, the most facegen writes)"
        more = more or frames >= 1e15
        frames = min(frames, 10**15)  # a stated count of hundreds of digits
        hours = frames / rate / 3600
        raise TooLarge(f"it holds {'more than ' if more else ''}{frames:,} frames, {hours:.1f} hours at "
                       f"{rate:g} fps{said}; facegen reads ARKit weights of up to "
                       f"{_hours(MAX_SECONDS)} (the longest audio it animates): cut it into parts")


def check_span(seconds: float) -> None:
    """Refuse Timecodes spanning more than MAX_SECONDS."""
    if seconds > MAX_SECONDS:
        raise TooLarge(f"its Timecodes span {seconds / 3600:.1f} hours; facegen reads ARKit weights of up "
                       f"to {_hours(MAX_SECONDS)} (the longest audio it animates): cut it into parts")


def _hours(seconds: float) -> str:
    return f"{seconds / 3600:g} hours"


# ---- Audio2Face JSON -----------------------------------------------------------------------------------


def read_json(file: BinaryIO, on_rows: Callable[[list], None],
              fps: float | None = None) -> tuple[dict, int | None]:
    """The top-level object of an Audio2Face JSON read from `file` (binary, UTF-8) without weightMat, and
    the number of weightMat's rows (None without a weightMat list); the rows (any JSON values) go to
    `on_rows` in lists of up to BLOCK as they are parsed. `fps` (else the file's exportFps) sets the frame
    bound. Raises NotJson or TooLarge."""
    check_size(file)
    text = _Text(file)
    if text.peek() != "{":
        raise NotJson("it is not a JSON object (Audio2Face files are one object: exportFps, facsNames, "
                      "weightMat, ...)")
    text.at += 1
    doc: dict = {}
    rows = None
    if text.peek() == "}":
        text.at += 1
    else:
        while True:
            if text.peek() != '"':
                raise NotJson(f"expected a key in double quotes {text.where()}")
            key = text.value()
            if text.peek() != ":":
                raise NotJson(f"expected ':' after the key {short(key)} {text.where()}")
            text.at += 1
            if key == "weightMat" and text.peek() == "[":
                if rows is not None:
                    raise NotJson("weightMat is given twice")
                rows = _rows(text, on_rows, rate_of(fps) or rate_of(doc.get("exportFps")))
            else:
                doc[key] = text.value()
            check_frames(_whole(doc.get("numFrames")), rate_of(fps) or rate_of(doc.get("exportFps")))
            sign = text.peek()
            text.at += 1
            if sign == "}":
                break
            if sign != ",":
                raise NotJson(f"expected ',' or '}}' after the value of {short(key)} {text.where(-1)}")
    if text.peek():
        raise NotJson(f"more text after the object {text.where()}")
    if rows is not None:
        check_frames(rows, rate_of(fps) or rate_of(doc.get("exportFps")))
    return doc, rows


def _whole(value) -> int:
    """A stated frame count as an int (0 when it is none: the rows are counted instead)."""
    return int(value) if isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(
        value) else 0


def _rows(text: _Text, on_rows: Callable[[list], None], fps: float | None) -> int:
    """weightMat's rows, from its '[' to its ']', handed on in blocks; returns their number."""
    text.at += 1
    count, block = 0, []
    if text.peek() == "]":
        text.at += 1
        return 0
    while True:
        block.append(text.value())
        count += 1
        if len(block) == BLOCK:
            check_frames(count, fps, more=True)
            on_rows(block)
            block = []
        sign = text.peek()
        text.at += 1
        if sign == "]":
            break
        if sign != ",":
            raise NotJson(f"expected ',' or ']' after weightMat row {count - 1} {text.where(-1)}")
    check_frames(count, fps)
    if block:
        on_rows(block)
    return count


class _Text:
    """A file's UTF-8 text in a window that slides forward, `at` the index of the next character in it."""

    def __init__(self, file: BinaryIO) -> None:
        self.file, self.decoder = file, codecs.getincrementaldecoder("utf-8-sig")()
        self.text, self.at, self.before, self.read, self.eof = "", 0, 0, 0, False

    def more(self) -> None:
        """Read the next piece onto the window, dropping the text already used."""
        data = self.file.read(_PIECE)
        self.read += len(data)
        if self.read > MAX_BYTES:  # grown since it was measured
            raise TooLarge(f"it is more than {MAX_BYTES / 1e6:.0f} MB, more than facegen reads as ARKit "
                           "weights")
        self.eof = not data
        self.before += self.at
        self.text = self.text[self.at:] + self.decoder.decode(data, final=self.eof)
        self.at = 0

    def peek(self) -> str:
        """The next character that is not white space ('' at the end), not taken."""
        while True:
            self.at = _SPACE.match(self.text, self.at).end()
            if self.at < len(self.text) or self.eof:
                return self.text[self.at:self.at + 1]
            self.more()

    def where(self, offset: int = 0) -> str:
        return f"at character {self.before + self.at + offset}"

    def value(self):
        """The JSON value at `at`, taken. A value that may go on past the window is parsed again on a longer
        one: one the scanner cannot finish near the window's end, or not followed by one of ,]}: there (a
        number "1.5e" cut before its "3")."""
        self.peek()
        start = self.at
        while True:
            try:
                value, end = _SCAN(self.text, start)
                after = _SPACE.match(self.text, end).end()
                if self.eof or (after < len(self.text) and self.text[after] in _AFTER_VALUE):
                    self.at = end
                    return value
            except StopIteration as exc:  # no value starts at the index
                if self.eof or exc.value < len(self.text) - 10:  # not a cut "Infinity"
                    raise NotJson(f"expected a value at character {self.before + exc.value}") from None
            except json.JSONDecodeError as exc:
                cut = exc.pos >= len(self.text) - 6 or exc.msg.startswith("Unterminated string")
                if self.eof or not cut:
                    raise NotJson(f"{exc.msg} at character {self.before + exc.pos}") from None
            except RecursionError:
                raise NotJson(f"it is nested too deeply {self.where()}") from None
            except ValueError:  # an integer of thousands of digits (int's limit)
                raise NotJson(f"a number of thousands of digits {self.where()}") from None
            if len(self.text) - start > MAX_VALUE:
                raise TooLarge(f"a value {self.where()} is longer than {MAX_VALUE >> 20} MB")
            self.more()
            start = self.at  # more() moved the window: the value starts at its beginning


def short(value, limit: int = 40) -> str:
    """repr(value), cut to `limit` characters (a value from a file, said in a message)."""
    shown = repr(value)
    return shown if len(shown) <= limit else shown[:limit] + "..."


# ---- Live Link Face CSV --------------------------------------------------------------------------------


def csv_rows(file: BinaryIO) -> Iterator[list[str]]:
    """The rows of a CSV read from `file` (binary, UTF-8 with or without a byte order mark), as csv.reader's
    lists of cells, line by line; a line longer than MAX_LINE or more than MAX_BYTES in all is TooLarge."""
    check_size(file)
    text = io.TextIOWrapper(file, encoding="utf-8-sig", newline="")

    def lines() -> Iterator[str]:
        total = 0
        while line := text.readline(MAX_LINE):
            total += len(line)
            if len(line) == MAX_LINE and not line.endswith(("\n", "\r")):
                raise TooLarge(f"a line is longer than {MAX_LINE >> 20} MB (a Live Link Face row is ~500 "
                               "bytes)")
            if total > MAX_BYTES:
                raise TooLarge(f"it is more than {MAX_BYTES / 1e6:.0f} MB, more than facegen reads as ARKit "
                               "weights")
            yield line

    return csv.reader(lines())
