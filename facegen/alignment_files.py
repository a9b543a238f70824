"""Alignment files: word (and phone) timings on disk, read and written through one format table.

facegen reads Gentle, WhisperX and plain JSON, Praat/MFA TextGrid and CSV word lists (the format is recognised
from the content), and writes plain JSON, TextGrid and CSV (the format follows the extension:
`alignment_format` checks a name before any work). Each format's row in ALIGNMENT_FORMATS says whether facegen
writes it and whether it carries phones; `read_phones` reads them where a file has them (CMU/ARPAbet phones:
our JSON's "phones", Gentle's phones per word, a TextGrid's phones tier as MFA writes it). A file without them
gets its phones aligned inside its word times (facegen.phone_timing).
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

from facegen.atomic import atomic_path
from facegen.errors import FacegenError
from facegen.input_files import check_input, read_input
from facegen.phonetics import INDEX, SIL, is_pause
from facegen.runtime import SILENT, Reporter
from facegen.words import Word, check_word_rate, strip_edges

TOLERANCE = 0.05  # how far (s) read times may run past the audio's end
MAX_ALIGNMENT_BYTES = 64 << 20


@dataclass(frozen=True)
class AlignmentFormat:
    """A word-timing file format: its extensions as users write them, whether facegen writes it (the extension
    picks the writer; reading recognises the content) and whether it carries phones beside the words."""
    name: str
    extensions: tuple[str, ...]
    writes: bool = False
    phones: bool = False


ALIGNMENT_FORMATS = (AlignmentFormat("JSON", (".json",), writes=True, phones=True),  # alignment_json
                     AlignmentFormat("Gentle JSON", (".json",), phones=True),  # per word: "dh_B", durations
                     AlignmentFormat("WhisperX JSON", (".json",)),
                     AlignmentFormat("TextGrid", (".TextGrid",), writes=True, phones=True),  # Praat, MFA
                     AlignmentFormat("CSV", (".csv",), writes=True))  # word,start,end
Phone = tuple[str, float, float]  # (CMU phone without stress, start s, end s)
# the phone label of a word its aligner could not pronounce (Kaldi's and MFA's spoken noise, Gentle's
# out-of-vocabulary word): no phones for that word (they are aligned inside its time)
UNPRONOUNCED = frozenset({"spn", "oov", "nsn"})


def alignment_format(path: str | os.PathLike, phones: bool = False) -> AlignmentFormat:
    """The format facegen writes `path` in (by its extension), one that holds phones when `phones`: checked
    before any work; another name is a FacegenError naming the extensions that work."""
    suffix = Path(path).suffix.lower()
    found = next((f for f in ALIGNMENT_FORMATS if f.writes and suffix in map(str.lower, f.extensions)), None)
    if found is not None and (found.phones or not phones):
        return found
    usable = [e for f in ALIGNMENT_FORMATS if f.writes and (f.phones or not phones) for e in f.extensions]
    what = "phones to" if found is not None else "alignment"
    names = f"{', '.join(usable[:-1])} or {usable[-1]}"
    raise FacegenError(f"cannot write {what} {path}: use a {names} file name")


def _is_textgrid(path: Path, text: str) -> bool:
    return text.startswith('File type = "ooTextFile"') or path.suffix.lower() == ".textgrid"


def read_alignment(path: str | os.PathLike, duration: float | None = None) -> list[Word]:
    """Read word timings from a Gentle / WhisperX / plain JSON, Praat or MFA TextGrid, or CSV file.

    The format is detected from the content. Pauses and words not found in the audio are left out.
    With `duration` (s), times past the audio's end (beyond a small tolerance) are an error, as are
    negative, reversed or overlapping times; the error names the file and the problem.
    """
    path = Path(path)
    words = _parsed(path, _read_textgrid, _read_json, _read_csv,
                    lambda why: f"alignment {path} is malformed ({why}): write it as Gentle/WhisperX/plain "
                    "JSON, a TextGrid or a CSV with word,start,end columns")
    _validate(words, path, duration)
    return words


def _parsed(path: Path, textgrid, from_json, from_csv, malformed):
    """An alignment file's text parsed by its kind (a TextGrid, JSON, else CSV) with the given parser; a file
    that does not parse is a FacegenError saying `malformed(reason)`."""
    text = _read_text(path)
    try:
        if _is_textgrid(path, text):
            return textgrid(text)
        if text.startswith(("{", "[")):
            return from_json(json.loads(text))  # malformed JSON raises ValueError
        return from_csv(text)
    except RecursionError as exc:
        raise FacegenError(f"alignment {path} is nested too deeply to be word timings: write it as Gentle/"
                           "WhisperX/plain JSON, a TextGrid or a CSV with word,start,end columns") from exc
    except (ValueError, KeyError, TypeError, IndexError, AttributeError, csv.Error) as exc:
        raise FacegenError(malformed(exc)) from exc


def read_phones(path: str | os.PathLike, duration: float | None = None,
                reporter: Reporter = SILENT) -> list[Phone] | None:
    """The phones of an alignment file, (CMU phone without stress, start, end) in seconds, pauses left out:
    the "phones" list of our JSON (`facegen align --phones`), Gentle's phones per word ("dh_B", durations from
    the word's start), or a TextGrid's phones tier ("phones" or MFA's "<speaker> - phones", ARPAbet with
    stress digits: "AH0"). A word its aligner could not pronounce (MFA's "spn", Gentle's "oov") has none.

    None when the file has no phones, or phones that are not CMU/ARPAbet (e.g. MFA's IPA models: a note says
    so). Like `read_alignment`, negative, reversed or (with `duration`) late times are a FacegenError.
    """
    path = Path(path)
    labelled = _parsed(path, _textgrid_phones, _json_phones, lambda _text: None,  # CSV: words only
                       lambda why: f"the phones of {path} are malformed ({why}): fix the file or align again")
    return None if labelled is None else _cmu_phones(labelled, path, duration, reporter)


def _json_phones(data: object) -> list[tuple[str, float, float]] | None:
    """Our JSON's "phones" list, or Gentle's phones per timed word; None when neither is there."""
    if isinstance(data, dict) and "phones" in data:
        if not isinstance(data["phones"], list):
            raise TypeError("'phones' is not a list")
        return [(str(p["phone"]), _seconds(p["start"]), _seconds(p["end"])) for p in data["phones"]]
    items = data.get("words") if isinstance(data, dict) else data
    if not isinstance(items, list) or not any(isinstance(it, dict) and "phones" in it for it in items):
        return None
    phones = []
    for item in items:  # Gentle: each aligned word's phones, one after the other from its start
        if not isinstance(item, dict) or item.get("case", "success") != "success" or "start" not in item:
            continue
        at = _seconds(item["start"])
        for phone in item.get("phones") or []:
            end = at + _seconds(phone["duration"])
            phones.append((re.sub(r"_[BIES]$", "", str(phone["phone"])), at, end))  # Kaldi's word position
            at = end
    return phones


def _textgrid_phones(text: str) -> list[tuple[str, float, float]] | None:
    """The phones tier beside the words tier `_read_textgrid` reads (MFA: "<speaker> - phones" beside
    "<speaker> - words"); None without one."""
    tiers = _interval_tiers(text)
    words = _words_tier(tiers)
    prefix = re.sub(r"words?$", "", words["name"].strip(), flags=re.IGNORECASE)
    named = [t for t in tiers if re.fullmatch(r"phones?", t["name"].strip().removeprefix(prefix).lower())]
    named = named or [t for t in tiers if re.search(r"\bphones?$", t["name"].strip().lower())]
    return [(str(label), _seconds(a), _seconds(b)) for a, b, label in named[0]["entries"]] if named else None


def _cmu_phones(labelled: list[tuple[str, float, float]], path: Path, duration: float | None,
                reporter: Reporter) -> list[Phone] | None:
    """CMU phones from a file's labels: stress digits and case dropped, pauses and unpronounced words left
    out, times checked; None (and a note) when a label is no CMU phone."""
    phones: list[Phone] = []
    for label, start, end in labelled:
        name = label.strip()
        if end < start or start < 0 or (duration is not None and end > duration + TOLERANCE):
            problem = ("has a negative time" if start < 0 else "ends before it starts" if end < start
                       else f"ends after the audio's end at {duration:g} s")
            raise FacegenError(f"alignment {path}: phone {name!r} {problem} ({start:g}-{end:g} s): fix the "
                               "file or align again")
        if is_pause(name) or name.lower() in UNPRONOUNCED:
            continue
        cmu = name.upper().rstrip("012")
        if cmu not in INDEX or cmu == SIL:
            reporter.note(f"the phones of {path} are not CMU/ARPAbet phones ({name!r}): they are left out, "
                          "and the phones are aligned inside its word times")
            return None
        phones.append((cmu, start, end))
    return phones


_AS_FILE = {"what": "alignment", "limit": MAX_ALIGNMENT_BYTES, "param": "alignment",
            "too_big": "far more than the word timings of any recording; check the path"}


def check_alignment_file(path: str | os.PathLike) -> None:
    """Refuse now, without reading it, a path read_alignment could not read (missing, a FIFO, a device, a
    folder, larger than MAX_ALIGNMENT_BYTES): a front end checks it before it loads a model."""
    check_input(path, **_AS_FILE)


def _read_text(path: Path) -> str:
    """The text of an alignment file (a regular file of at most MAX_ALIGNMENT_BYTES), leading spaces
    dropped."""
    return _decode_text(read_input(path, **_AS_FILE)).lstrip()


def _decode_text(raw: bytes) -> str:
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):  # Praat writes UTF-16 when the text needs it
        return raw.decode("utf-16")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def _word(text: object, start: object, end: object) -> Word | None:
    """A Word from file values; None for a pause or punctuation."""
    label = strip_edges(str(text).strip())
    if is_pause(label):
        return None
    return Word(label, _seconds(start), _seconds(end))


def _seconds(value: object) -> float:
    if isinstance(value, bool) or value is None or value == "":
        raise ValueError(f"missing or invalid time {value!r}")
    number = float(value)  # ValueError for text
    if not math.isfinite(number):
        raise ValueError(f"time {value!r} is not a finite number")
    return number


def _read_json(data: object) -> list[Word]:
    if isinstance(data, dict) and ("segments" in data or "word_segments" in data):
        return _read_whisperx(data)
    items = data["words"] if isinstance(data, dict) else data
    if not isinstance(items, list):
        raise TypeError('expected a list of words or {"words": [...]}')
    gentle = any(isinstance(it, dict) and ("case" in it or "alignedWord" in it) for it in items)
    words = []
    for item in items:
        if not isinstance(item, dict):
            raise TypeError(f"word entry {item!r} is not an object")
        if gentle:  # Gentle: only "success" words have times
            if item.get("case", "success") != "success" or "start" not in item:
                continue
            word = _word(item.get("word", item.get("alignedWord", "")), item["start"], item["end"])
        else:
            label = item["word"] if "word" in item else item["text"]
            word = _word(label, item["start"], item["end"])
        if word:
            words.append(word)
    return words


def _read_whisperx(data: dict) -> list[Word]:
    """WhisperX (or Whisper with word timestamps): segments[].words[], else word_segments[].

    Words WhisperX could not time (often numbers) are placed in the gap between their neighbours.
    """
    segments = data.get("segments") or []
    if not isinstance(segments, list):
        raise TypeError("'segments' is not a list")
    items = [w for seg in segments for w in seg.get("words", [])] or data.get("word_segments") or []
    labels = [str(it["word"] if "word" in it else it["text"]) for it in items]
    starts = [it.get("start") for it in items]
    ends = [it.get("end") for it in items]
    i = 0
    while i < len(items):  # fill runs of untimed words between timed neighbours
        if starts[i] is not None and ends[i] is not None:
            i += 1
            continue
        j = i
        while j < len(items) and (starts[j] is None or ends[j] is None):
            j += 1
        left = _seconds(ends[i - 1]) if i > 0 else None
        right = _seconds(starts[j]) if j < len(items) else None
        if left is not None and right is not None and right >= left:
            step = (right - left) / (j - i)
            for k in range(i, j):
                starts[k], ends[k] = left + step * (k - i), left + step * (k - i + 1)
        i = j
    words = []
    for label, start, end in zip(labels, starts, ends, strict=True):
        if start is None or end is None:
            continue  # untimed at the edges: nothing to place it by
        word = _word(label, start, end)
        if word:
            words.append(word)
    return words


_TEXTGRID_HEADER = re.compile(r'File type = "ooTextFile"\s+Object class = "TextGrid"')
# praatio reads "xmin = -0.5" as 0.5: refuse a negative time before it does ("-0" is a valid start)
_NEGATIVE_TIME = re.compile(r"^\s*(?:(?:xmin|xmax|number)\s*=\s*)?(-[\d.]+)\s*$", re.MULTILINE)


def _interval_tiers(text: str) -> list[dict]:
    """The interval tiers of a Praat TextGrid, long or short text format (parsed by praatio)."""
    from praatio.utilities.errors import PraatioException
    from praatio.utilities.textgrid_io import parseTextgridStr

    if not _TEXTGRID_HEADER.match(text):
        raise ValueError("not a text TextGrid (save it from Praat as a text file)")
    if negative := [t for t in _NEGATIVE_TIME.findall(text) if float(t) < 0]:
        raise ValueError(f"negative time {negative[0]}")
    try:
        tiers = parseTextgridStr(text, includeEmptyIntervals=False)["tiers"]
    except PraatioException as exc:
        raise ValueError(str(exc)) from exc
    intervals = [t for t in tiers if t["class"] == "IntervalTier"]
    if not intervals:
        raise ValueError("no interval tier")
    return intervals


def _words_tier(tiers: list[dict]) -> dict:
    """The first tier named words (MFA: "<speaker> - words"), else the first tier."""
    named = [t for t in tiers if re.search(r"\bwords?$", t["name"].strip().lower())]
    return (named or tiers)[0]


def _read_textgrid(text: str) -> list[Word]:
    """Praat TextGrid: the `words` tier, else the first interval tier."""
    words = []
    for start, end, label in _words_tier(_interval_tiers(text))["entries"]:
        word = _word(label, start, end)
        if word:
            words.append(word)
    return words


def _read_csv(text: str) -> list[Word]:
    """CSV/TSV with a header naming word (or text/label), start and end; or 3 columns without one."""
    first = text.split("\n", 1)[0]
    delimiter = next((d for d in "\t,;" if d in first), ",")
    rows = [r for r in csv.reader(io.StringIO(text), delimiter=delimiter) if any(c.strip() for c in r)]
    if not rows:
        raise ValueError("the file is empty")
    header = [c.strip().lower() for c in rows[0]]
    names = {"word": ("word", "text", "label", "token"), "start": ("start", "begin", "onset", "start_time"),
             "end": ("end", "stop", "offset", "end_time")}
    columns = {key: next((header.index(a) for a in alias if a in header), None)
               for key, alias in names.items()}
    if all(v is not None for v in columns.values()):
        order, rows = (columns["word"], columns["start"], columns["end"]), rows[1:]
    else:
        if any(len(r) != 3 for r in rows):
            raise ValueError("rows without a word,start,end header must have exactly 3 columns")

        def numeric(cell: str) -> bool:
            try:
                float(cell)
                return True
            except ValueError:
                return False

        row = rows[0]
        text_cols = [i for i, c in enumerate(row) if not numeric(c)]
        if len(text_cols) != 1:
            raise ValueError(f"cannot tell the word column from the times in row {row}")
        word_col = text_cols[0]
        start_col, end_col = [i for i in range(3) if i != word_col]
        order = (word_col, start_col, end_col)
    words = []
    for n, row in enumerate(rows, 1):
        if len(row) <= max(order):
            raise ValueError(f"row {n} has too few columns")
        word = _word(row[order[0]], row[order[1]].strip(), row[order[2]].strip())
        if word:
            words.append(word)
    return words


def _validate(words: list[Word], path: Path, duration: float | None) -> None:
    def fail(problem: str) -> FacegenError:
        return FacegenError(f"alignment {path}: {problem}: fix the file or align again")

    if not words:
        raise fail("it contains no timed words")
    previous = None
    for w in words:
        if w.start < 0 or w.end < 0:
            raise fail(f"word {w.text!r} has a negative time ({w.start:g}-{w.end:g} s)")
        if w.end < w.start:
            raise fail(f"word {w.text!r} ends before it starts ({w.start:g}-{w.end:g} s)")
        if previous and (w.start < previous.start or w.start < previous.end - 0.01):
            raise fail(f"times are not in order: {w.text!r} at {w.start:g} s starts before "
                       f"{previous.text!r} ({previous.start:g}-{previous.end:g} s) ends")
        previous = w
    if duration is not None and words[-1].end > duration + TOLERANCE:
        raise fail(f"word {words[-1].text!r} ends at {words[-1].end:g} s, after the audio's end at "
                   f"{duration:g} s (is it the alignment of another recording?)")
    if duration is not None:
        check_word_rate(len(words), duration, f"alignment {path}")


def alignment_json(words: list[Word], phones: list[tuple[str, float, float]] | None = None) -> dict:
    """Our plain JSON alignment: {"words": [{"word", "start", "end"}]}
    (+ "phones": [{"phone", "start", "end"}])."""
    payload: dict = {"words": [{"word": w.text, "start": round(w.start, 6), "end": round(w.end, 6)}
                               for w in words]}
    if phones is not None:
        payload["phones"] = [{"phone": p, "start": round(a, 6), "end": round(b, 6)} for p, a, b in phones]
    return payload


def write_alignment(words: list[Word], path: str | os.PathLike, duration: float | None = None,
                    phones: list[tuple[str, float, float]] | None = None) -> Path:
    """Write words (and phones) as our plain JSON (`alignment_json`), a TextGrid or a CSV (words only).

    The format follows the suffix (.json, .TextGrid, .csv). A TextGrid gets a `words` interval tier
    (and a `phones` tier) with empty intervals for pauses, spanning 0 to `duration` (default: the last end).
    """
    path = Path(path)
    fmt = alignment_format(path, phones is not None)
    if fmt.name == "TextGrid":
        tiers = {"words": [(w.text, w.start, w.end) for w in words]}
        if phones is not None:
            tiers["phones"] = list(phones)
        content = _textgrid(tiers, duration)
    elif fmt.name == "CSV":
        buffer = io.StringIO()
        writer = csv.writer(buffer, lineterminator="\n")
        writer.writerow(["word", "start", "end"])
        writer.writerows([w.text, f"{w.start:.6f}", f"{w.end:.6f}"] for w in words)
        content = buffer.getvalue()
    else:
        content = json.dumps(alignment_json(words, phones), indent=1, ensure_ascii=False) + "\n"
    with atomic_path(path) as tmp:
        tmp.write_text(content, encoding="utf-8")
    return path


def _textgrid(tiers: dict[str, list[tuple[str, float, float]]], duration: float | None) -> str:
    """Long-format TextGrid text, one interval tier per entry of `tiers` (label, start, end), with empty
    intervals for pauses and times to the microsecond (praatio's writer prints them as repr or integers,
    e.g. "xmax = 2", so ours is kept)."""
    end = max([duration or 0.0] + [b for items in tiers.values() for _, _, b in items])
    lines = ['File type = "ooTextFile"', 'Object class = "TextGrid"', "", "xmin = 0", f"xmax = {end:.6f}",
             "tiers? <exists>", f"size = {len(tiers)}", "item []:"]
    for n, (name, items) in enumerate(tiers.items(), 1):
        intervals: list[tuple[float, float, str]] = []
        t = 0.0
        for label, a, b in items:
            if a > t + 1e-9:
                intervals.append((t, a, ""))
            intervals.append((max(a, t), b, label))
            t = b
        if end > t + 1e-9 or not intervals:
            intervals.append((t, end, ""))
        lines += [f"    item [{n}]:", '        class = "IntervalTier"', f'        name = "{name}"',
                  "        xmin = 0", f"        xmax = {end:.6f}",
                  f"        intervals: size = {len(intervals)}"]
        for k, (a, b, label) in enumerate(intervals, 1):
            quoted = label.replace('"', '""')
            lines += [f"        intervals [{k}]:", f"            xmin = {a:.6f}",
                      f"            xmax = {b:.6f}", f'            text = "{quoted}"']
    return "\n".join(lines) + "\n"
