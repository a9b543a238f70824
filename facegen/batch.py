"""Many clips in one process: manifests (CSV, JSON, JSON lines) read into Jobs with their line numbers, the
model and text backend loaded once, decoder BiLSTMs run over packed batches of clips, each clip written in
one or more formats and validated; one result per clip (a failing clip never stops the others).

What a whole `facegen batch` run adds around this (refusals before work, skipping unchanged items, worker
processes or Ray, reports) is in batch_plan.py, engines.py, batch_report.py and batch_run.py. Reading a
manifest imports no torch: planning and skipping stay quick.
"""

from __future__ import annotations

import csv
import io
import json
import os
import re
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from facegen.align_ahead import Aligned
from facegen.animator import BATCH_SIZE, Animator
from facegen.blinks import DEFAULT_RATE
from facegen.errors import FacegenError
from facegen.exchange import format_of, format_of_extension, write_animation
from facegen.expression import Emotion, parse_emotion
from facegen.input_files import MANIFEST_BYTES, TRANSCRIPT_BYTES, read_input_text
from facegen.languages import check_language
from facegen.runtime import SILENT, Reporter
from facegen.strength import parse_strength


@dataclass
class Job:
    """One clip to animate: the audio, where its words come from, the speaker, the output file(s).

    `outputs` (when given) are the files to write from the one inference, `output` first; `line` is the
    manifest line the job comes from (0: not from a manifest); `problem` is why the row cannot run (e.g. an
    unreadable transcript file), reported as its error without stopping the others; `aligned` is the forced
    alignment of `text` when it was done already (align_ahead.Aligned: engines.run_local's main process aligns
    waiting items while its workers start), else the worker aligns. `text_file` (where `text` was read from)
    and `manifest` are inputs too: no output may replace them (batch_plan.check_plan)."""

    audio: Path
    output: Path
    text: str | None = None
    alignment: Path | None = None
    speaker: str | None = None
    no_text: bool = False
    line: int = 0
    outputs: tuple[Path, ...] = ()
    problem: str | None = None
    aligned: Aligned | None = None
    text_file: Path | None = None
    manifest: Path | None = None
    fps: float | None = None  # the output frame rate (None: the model's)
    on_mismatch: str = "error"  # a transcript not matching its speech: refused, or animated and flagged
    blink_rate: float = DEFAULT_RATE  # blinks per minute (facegen.blinks)
    seed: int = 0  # of the random layers
    emotion: Emotion | None = None  # the row's 'emotion', else the run's (facegen.expression)
    head_motion: float = 1.0  # facegen.head
    lip_seal: bool = True  # facegen.lip_seal
    strength: dict | None = None  # the row's 'strength', else the run's (facegen.strength)
    language: str | None = None  # the row's 'language', else the run's (facegen.languages)
    options: dict = field(default_factory=dict)  # write options, for each target whose format takes them

    @property
    def targets(self) -> tuple[Path, ...]:
        """Every file this job writes (besides audio sidecars), `output` first."""
        return self.outputs or (self.output,)


@dataclass
class JobResult:
    """What became of one job: the files written, or its one-line error; each file's validation
    ({"file", "ok", "failures", "warnings"}); `skipped` when it was unchanged since the last run."""

    job: Job
    files: list[Path] = field(default_factory=list)
    error: str | None = None
    frames: int = 0
    seconds: float = 0.0
    cpu_seconds: float = 0.0  # this process's CPU time for the job (all its threads)
    audio_seconds: float = 0.0
    validation: list[dict] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    skipped: bool = False
    match: dict | None = None  # how well the transcript matches the speech (transcript_match.Match.as_dict)

    @property
    def flagged(self) -> bool:
        """Written although its transcript may not match the speech (on_mismatch "warn")."""
        return self.error is None and self.match is not None and self.match.get("problem") is not None

    @property
    def ok(self) -> bool:
        return self.error is None and all(v["ok"] for v in self.validation)

    @property
    def status(self) -> str:
        """"skipped", "passed", "failed" (written, but a validation check failed) or "error" (not written)."""
        if self.error is not None:
            return "error"
        if self.skipped:
            return "skipped"
        return "passed" if self.ok else "failed"


MANIFEST_COLUMNS = ("audio", "text", "text_file", "alignment", "speaker", "output", "emotion", "strength",
                    "language")
PATH_COLUMNS = ("audio", "text_file", "alignment", "output")
MAX_SPEAKER_CHARS = 100  # a speaker's name or index
ROW_DEPTH = 3  # brackets a JSON manifest nests: {"jobs": [{row}]}


def one_line(exc: BaseException) -> str:
    """An exception as one line: its message (a FacegenError's own), or its type and message."""
    text = str(exc) if isinstance(exc, FacegenError) else f"{type(exc).__name__}: {exc}"
    return " ".join(text.split()) or type(exc).__name__


def read_manifest(path: str | os.PathLike, outdir: str | os.PathLike | None = None,
                  default_ext: str = ".usdc", formats: Sequence[str] | None = None) -> list[Job]:
    """Jobs from a manifest: a CSV (header: audio, text | text_file | alignment, speaker, output), a JSON list
    of objects with those keys (or {"jobs": [...]}), or JSON lines (one object per line).

    Relative audio/text_file/alignment paths are relative to the manifest's folder; relative outputs to
    `outdir` (default: the manifest's folder). A missing output is the audio's name with `default_ext`.
    With `formats` (extensions such as ".usdc", ".glb"), each job writes its output's stem in every one of
    them. A row with neither text nor alignment has its words recognised (as `facegen animate` without
    --text). A malformed manifest is a FacegenError naming the line; a transcript file that cannot be read
    makes only its row fail (`Job.problem`). The manifest and the transcript files are read as
    facegen.input_files reads: regular files of a bounded size (no FIFO, device or folder).
    """
    path = Path(path)
    raw = read_input_text(path, what="manifest", limit=MANIFEST_BYTES, fix="pass a UTF-8 CSV or JSON file",
                          too_big="split it into several manifests", encoding="utf-8-sig")
    try:
        rows = _json_rows(raw, path) if raw.lstrip().startswith(("[", "{")) else _csv_rows(raw, path)
    except RecursionError as exc:
        raise FacegenError(f"manifest {path}, line {_too_deep(raw)}: objects or lists nested too deeply: a "
                           "row is one object of strings and numbers") from exc
    for ext in formats or ():
        format_of_extension(ext)
    base = path.parent
    out_base = Path(outdir) if outdir is not None else base
    jobs = [_job(row, line, path, base, out_base, default_ext, formats) for line, row in rows]
    if not jobs:
        raise FacegenError(f"manifest {path} lists no clips: add rows (audio, text or alignment, output)")
    return jobs


def _csv_rows(raw: str, path: Path) -> list[tuple[int, dict]]:
    reader = csv.reader(io.StringIO(raw))
    rows: list[tuple[int, dict]] = []
    try:
        header = next(reader, None)
        if not header or not any(h.strip() for h in header):
            raise FacegenError(f"manifest {path}, line 1: no header row: start with a line such as "
                               "'audio,text,output'")
        names = [h.strip().lower() for h in header]
        _check_columns(names, path, reader.line_num)
        for fields in reader:
            if not any(f.strip() for f in fields):
                continue
            if len(fields) != len(names):
                raise FacegenError(f"manifest {path}, line {reader.line_num}: {len(fields)} fields where the "
                                   f"header has {len(names)}: quote fields that contain commas")
            rows.append((reader.line_num, dict(zip(names, fields, strict=True))))
    except csv.Error as exc:
        raise FacegenError(f"manifest {path}, line {reader.line_num}: not valid CSV ({exc}): fix that "
                           "line") from exc
    return rows


def _check_columns(names: list[str], path: Path, line: int) -> None:
    unknown = sorted(set(names) - set(MANIFEST_COLUMNS))
    if unknown:
        raise FacegenError(f"manifest {path}, line {line}: unknown column(s) {', '.join(unknown)}: use "
                           f"{', '.join(MANIFEST_COLUMNS)}")
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise FacegenError(f"manifest {path}, line {line}: column {', '.join(repeated)} given twice: keep "
                           "one")


class _Object(dict):
    """A JSON object as its pairs in file order (`pairs`: a key given twice stays twice, for the check)."""

    def __init__(self, pairs: list[tuple[str, object]]) -> None:
        super().__init__(pairs)
        self.pairs = pairs


# integers stay text (a row's values are text anyway): a 5,000-digit number is not converted, so no limit hit
_DECODER = json.JSONDecoder(parse_int=str, object_pairs_hook=_Object)


def _too_deep(raw: str) -> int:
    """The line of the first bracket a JSON manifest nests deeper than a manifest's rows (1: none found)."""
    depth = 0
    for token in re.finditer(r'"(?:[^"\\]|\\.)*"|[\[\]{}]', raw):
        if token[0] in "[{":
            depth += 1
            if depth > ROW_DEPTH:
                return _line_of(raw, token.start())
        elif token[0] in "]}":
            depth -= 1
    return 1


def _json_rows(raw: str, path: Path) -> list[tuple[int, dict]]:
    """(line, object) for a JSON list, {"jobs": [...]} or JSON lines."""
    decoder = _DECODER
    try:
        data = decoder.decode(raw)
    except json.JSONDecodeError as exc:
        first = raw.lstrip().splitlines()[0] if raw.strip() else ""
        if exc.msg == "Extra data" and first.startswith("{"):
            return _json_lines(raw, path)
        raise FacegenError(f"manifest {path}, line {exc.lineno}: not valid JSON ({exc.msg}): fix it") from exc
    if isinstance(data, dict) and "jobs" not in data:  # one object: JSON lines with one row
        return _json_lines(raw, path)
    start = raw.index("[") if isinstance(data, list) else _jobs_array(raw, path, decoder)
    rows = []
    pos = start + 1
    while True:
        pos = _skip(raw, pos, ",")
        if raw[pos] == "]":
            break
        item, end = decoder.raw_decode(raw, pos)
        rows.append((_line_of(raw, pos), _object(item, path, _line_of(raw, pos))))
        pos = end
    return rows


def _jobs_array(raw: str, path: Path, decoder: json.JSONDecoder) -> int:
    """The offset of the "jobs" list of a manifest object (its value checked to be a list)."""
    pos = _skip(raw, raw.index("{") + 1, ",")
    while raw[pos] != "}":
        key, pos = decoder.raw_decode(raw, pos)
        pos = _skip(raw, pos, ":")
        if key == "jobs" and raw[pos] == "[":
            return pos
        _, pos = decoder.raw_decode(raw, pos)
        pos = _skip(raw, pos, ",")
    raise FacegenError(f'manifest {path}: a JSON manifest must be a list of objects or {{"jobs": [...]}}')


def _json_lines(raw: str, path: Path) -> list[tuple[int, dict]]:
    rows = []
    for n, text in enumerate(raw.splitlines(), 1):
        if not text.strip():
            continue
        try:
            item = _DECODER.decode(text)
        except json.JSONDecodeError as exc:
            raise FacegenError(f"manifest {path}, line {n}: not valid JSON ({exc.msg}): one object per "
                               "line") from exc
        rows.append((n, _object(item, path, n)))
    return rows


def _skip(raw: str, pos: int, separators: str) -> int:
    while raw[pos].isspace() or raw[pos] in separators:
        pos += 1
    return pos


def _line_of(raw: str, pos: int) -> int:
    return raw.count("\n", 0, pos) + 1


def _object(item, path: Path, line: int) -> dict:
    if not isinstance(item, dict):
        raise FacegenError(f"manifest {path}, line {line}: expected an object with audio, text, output, ... "
                           f"but found {type(item).__name__}")
    pairs = item.pairs if isinstance(item, _Object) else list(item.items())
    for key, value in pairs:
        if isinstance(value, (dict, list)):
            raise FacegenError(f"manifest {path}, line {line}: {key} must be a string or number")
    names = [str(key).strip().lower() for key, _ in pairs]
    _check_columns(names, path, line)  # "audio" and "Audio" are one column given twice
    return {name: "" if value is None else str(value) for name, (_, value) in zip(names, pairs, strict=True)}


def _job(row: dict, line: int, path: Path, base: Path, out_base: Path, default_ext: str,
         formats: Sequence[str] | None) -> Job:
    row = {k: v.strip() for k, v in row.items()}
    where = f"manifest {path}, line {line}"
    if not row.get("audio"):
        raise FacegenError(f"{where}: no audio file given")
    for column in PATH_COLUMNS:
        if "\0" in row.get(column, ""):
            raise FacegenError(f"{where}: the {column} path contains a NUL byte, which no file name can: fix "
                               "that field")
    speaker = row.get("speaker") or None
    if speaker is not None and len(speaker) > MAX_SPEAKER_CHARS:
        size = f"a {len(speaker)}-digit number" if speaker.isdigit() else f"{len(speaker)} characters long"
        raise FacegenError(f"{where}: the speaker {speaker[:12]}... is {size}: give a speaker's name or "
                           "index")
    try:
        emotion = parse_emotion(row.get("emotion") or None)
        strength = parse_strength(row.get("strength") or None)
        language = check_language(row["language"]).code if row.get("language") else None
    except FacegenError as exc:
        raise FacegenError(f"{where}: {exc}") from None
    given = [k for k in ("text", "text_file", "alignment") if row.get(k)]
    if len(given) > 1:
        raise FacegenError(f"{where}: give one of text, text_file or alignment, not {' and '.join(given)}")
    text, problem = row.get("text") or None, None
    text_file = base / row["text_file"] if row.get("text_file") else None
    if text_file is not None:
        try:
            text = read_input_text(text_file, what="transcript file", limit=TRANSCRIPT_BYTES,
                                   name=row["text_file"], fix="fix the path or the file",
                                   too_big="split the recording and its transcript into parts")
        except FacegenError as exc:
            problem = str(exc)
    try:
        output = row.get("output") or Path(row["audio"]).with_suffix(default_ext).name
    except ValueError:  # "/": no name to give the output
        raise FacegenError(f"{where}: the audio path {row['audio']} names no file: fix that field") from None
    try:
        format_of(output)
    except FacegenError as exc:
        raise FacegenError(f"{where}: {exc}") from None
    out = out_base / output
    outputs = tuple(out.with_suffix(ext) for ext in formats) if formats else ()
    return Job(audio=base / row["audio"], output=outputs[0] if outputs else out, text=text,
               alignment=base / row["alignment"] if row.get("alignment") else None,
               speaker=speaker, line=line, outputs=outputs, problem=problem, text_file=text_file,
               manifest=path, emotion=emotion, strength=strength, language=language)


def animate_many(jobs: Iterable[Job], *, animator: Animator | None = None, batch_size: int = BATCH_SIZE,
                 window: int = 64, reporter: Reporter = SILENT) -> Iterator[tuple[Job, object]]:
    """Animate many clips with one Animator (the built-in model on the CPU or GPU if None): yields
    (job, Animation) or (job, FacegenError) for every job, in the input order within windows of `window` jobs.

    Within a window, the clips run through the decoder BiLSTMs `batch_size` at a time (Animator.run: packed,
    each clip's result equals its own single run). The frames of each Animation are a FrameStream (computed
    when the writer reads them). Notes (e.g. "no transcript given") go to `reporter.note`.
    """
    for job, anim, _, _ in _animate_timed(jobs, animator=animator or Animator(), batch_size=batch_size,
                                          window=window, reporter=reporter):
        yield job, anim


def _animate_timed(jobs: Iterable[Job], *, animator: Animator, batch_size: int, window: int,
                   reporter: Reporter) -> Iterator[tuple[Job, object, float, list[str]]]:
    """animate_many's (job, Animation or FacegenError) with the (wall, CPU) seconds spent on each job's
    preparation and its share of the network, and the notes said while preparing it (also passed to
    `reporter.note`)."""
    pending: list[Job] = []

    def run(window_jobs: list[Job]) -> Iterator[tuple[Job, object, float, list[str]]]:
        prepared: dict[int, object] = {}
        seconds: dict[int, np.ndarray] = {}
        notes: dict[int, list[str]] = {}
        for i, job in enumerate(window_jobs):
            t0 = _clocks()
            said = notes[i] = []

            def note(msg: str, said: list[str] = said) -> None:
                said.append(msg)
                reporter.note(msg)

            try:
                if job.problem:
                    raise FacegenError(job.problem)
                prepared[i] = animator.prepare(job.audio, text=job.text, alignment=job.alignment,
                                               no_text=job.no_text, speaker=job.speaker, fps=job.fps,
                                               reporter=SILENT.noting(note), aligned=job.aligned,
                                               on_mismatch=job.on_mismatch, blink_rate=job.blink_rate,
                                               seed=job.seed, emotion=job.emotion,
                                               head_motion=job.head_motion, strength=job.strength,
                                               language=job.language, lip_seal=job.lip_seal)
            except FacegenError as exc:
                prepared[i] = exc
            except Exception as exc:  # noqa: BLE001 - one bad row never stops the others: it is that row's error
                prepared[i] = FacegenError(one_line(exc))
            seconds[i] = _clocks() - t0
            if job.aligned is not None:  # aligned in another process: its time is this job's too
                seconds[i] += [job.aligned.seconds, job.aligned.cpu_seconds]
        ready = sorted((i for i, c in prepared.items() if not isinstance(c, FacegenError)),
                       key=lambda i: prepared[i].num_frames)
        for b in range(0, len(ready), batch_size):
            ids = ready[b:b + batch_size]
            t0 = _clocks()
            for i, anim in zip(ids, animator.run([prepared[i] for i in ids], batch_size=batch_size),
                               strict=True):
                prepared[i] = anim
                seconds[i] += (_clocks() - t0) / len(ids)
        for i, job in enumerate(window_jobs):
            yield job, prepared[i], seconds[i], notes[i]

    for job in jobs:
        pending.append(job)
        if len(pending) >= window:
            yield from run(pending)
            pending = []
    if pending:
        yield from run(pending)


def run_batch(jobs: Sequence[Job], *, animator: Animator | None = None, batch_size: int = BATCH_SIZE,
              validate: bool = True, reporter: Reporter = SILENT) -> list[JobResult]:
    """Animate every job and write each of its targets (format from the extension) from one inference, then
    (`validate`) check each file as `facegen validate` does. A clip that fails is reported in its JobResult
    and the others go on; a line per clip goes to `reporter.progress`, notes (e.g. "no transcript given") to
    `reporter.note` and into the result. Returns one JobResult per job, in order."""
    results = []
    start = time.perf_counter()
    timed = _animate_timed(jobs, animator=animator or Animator(), batch_size=batch_size, window=64,
                           reporter=reporter)
    for n, (job, anim, prep, notes) in enumerate(timed, 1):
        t0 = _clocks()
        result = JobResult(job, notes=notes)
        if isinstance(anim, FacegenError):
            result.error = one_line(anim)
            result.match = (anim.details or {}).get("transcript_match")
        else:
            result.match = anim.metadata.get("transcript_match")
            result.frames, result.audio_seconds = anim.num_frames, len(anim.audio) / anim.sample_rate
            try:
                for target in job.targets:
                    target.parent.mkdir(parents=True, exist_ok=True)
                    options = {k: v for k, v in job.options.items() if k in format_of(target).options}
                    written = write_animation(anim, target, audio_source=job.audio, **options)
                    result.files += [f for f in written if f not in result.files]
                if validate:
                    result.validation = [_validation(t, anim) for t in job.targets]
            except Exception as exc:  # noqa: BLE001 - an OS error (name too long, disk full...) is this row's only
                result.error = one_line(exc)
        result.seconds, result.cpu_seconds = (prep + _clocks() - t0).tolist()
        results.append(result)
        reporter.progress(f"[{n}/{len(jobs)}] {job.output}: "
                          + (f"{result.frames} frames" if result.ok else
                             f"{result.status}: {result.error or _failed(result)}")
                          + f" ({time.perf_counter() - start:.1f} s)")
    return results


def _clocks() -> np.ndarray:
    """(wall, CPU) seconds now."""
    return np.array([time.perf_counter(), time.process_time()])


def _validation(path: Path, anim) -> dict:
    """`facegen validate`'s verdict on a written file, against the clip's template and frame rate."""
    from facegen.validate import validate

    report = validate(path, template=anim.mesh, fps=anim.fps)
    return {"file": str(path), "ok": report.ok, "failures": [f"{c.name}: {c.detail}"
                                                             for c in report.failures],
            "warnings": [f"{c.name}: {c.detail}" for c in report.warnings]}


def _failed(result: JobResult) -> str:
    return "; ".join(f"{Path(v['file']).name}: {', '.join(v['failures'])}" for v in result.validation
                     if not v["ok"])
