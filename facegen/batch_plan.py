"""What a `facegen batch` run may do and what it can skip: the checks that refuse a plan before any work
(outputs escaping the output folder, two rows writing one file, rows sharing an audio sidecar, an output
overwriting an input or a report), the content key of each item (its input bytes, options and model), and
the run state in OUT/.facegen-batch.json that records which items are done.

An item is skipped when its key equals the recorded one and every file it wrote is still there with the size
and modification time recorded (so an output edited or deleted since is made again).
"""

from __future__ import annotations

import hashlib
import json
import os
import unicodedata
from dataclasses import dataclass, field
from pathlib import Path

from facegen import __version__
from facegen.atomic import atomic_path
from facegen.batch import Job, JobResult
from facegen.errors import FacegenError
from facegen.exchange.wav import sidecar_path
from facegen.input_files import open_input, read_input

STATE_NAME = ".facegen-batch.json"
REPORT_NAMES = ("report.json", "report.xml")
STATE_VERSION = 1
STATE_BYTES = 256 << 20  # a run state larger than this is not ours: everything runs


def _folded(path: str | os.PathLike) -> str:
    """A path as case-insensitive file systems (macOS, Windows) compare names: Unicode's canonical caseless
    form, NFD(casefold(NFD(path))), so that `Lines.csv` is `lines.csv` and an "é" of one code point is the "é"
    of two. Used on every file system: a plan refused on macOS is refused on Linux too."""
    return unicodedata.normalize("NFD", unicodedata.normalize("NFD", os.fspath(path)).casefold())


def _entry(path: str | os.PathLike) -> Path:
    """The directory entry that writing `path` replaces: its folder with every symbolic link (and "..")
    resolved, and its name. Outputs are written as temporaries renamed onto the name, so a link at the name
    itself is replaced, not followed."""
    path = Path(path)
    return Path(os.path.realpath(path.parent), path.name)


def _note(a: str | os.PathLike, b: str | os.PathLike) -> str:
    """What to add when two paths that are one file differ as written (only in case or Unicode form)."""
    if os.fspath(a) == os.fspath(b):
        return ""
    return f" ({a} and {b} are one file where names are compared without case, as on macOS and Windows)"


def check_plan(jobs: list[Job], out_dir: str | os.PathLike) -> None:
    """Refuse, before any work, a plan that would lose or misplace a clip (a FacegenError naming the
    lines): an output that leaves `out_dir` once symbolic links are followed, that is one of the run's inputs
    (the manifest, a row's audio, alignment or transcript file, also when one is a link to it), the batch's
    own reports or state, or another row's output or audio sidecar. Names are compared case-folded and
    Unicode-normalised (`_folded`)."""
    out = Path(os.path.realpath(out_dir))
    reserved = {_folded(out / name): name for name in (*REPORT_NAMES, STATE_NAME)}
    for name in (*REPORT_NAMES, STATE_NAME):
        if (out / name).is_dir():
            raise FacegenError(f"{out_dir} has a folder {name}, where the batch writes its {name}: remove or "
                               "rename that folder, or choose another output folder")
    inputs: dict[str, tuple[int, str, Path]] = {}  # folded path -> (line, what it is, the entry)
    own_audio: set[tuple[str, int]] = set()  # (folded path, line): a row's sidecar may be its own audio
    for job in jobs:
        sources = (("audio", job.audio), ("alignment", job.alignment), ("transcript file", job.text_file),
                   ("manifest", job.manifest))
        for what, source in sources:
            if source is not None:  # the name, and the file it links to
                for path in (_entry(source), Path(os.path.realpath(source))):
                    inputs.setdefault(_folded(path), (0 if what == "manifest" else job.line, what, path))
                    if what == "audio":
                        own_audio.add((_folded(path), job.line))
    written: dict[str, tuple[int, Path]] = {}
    sidecars: dict[str, tuple[int, Path]] = {}
    for job in jobs:
        where = f"manifest line {job.line}"
        for target in job.targets:
            path = _entry(target)
            if not path.is_relative_to(out):
                if Path(os.path.abspath(target)).is_relative_to(os.path.abspath(out_dir)):
                    raise FacegenError(f"{where}: output {target} leads outside the output folder {out_dir}, "
                                       f"to {path}, through a symbolic link: write inside it, or remove the "
                                       "link")
                raise FacegenError(f"{where}: output {target} is outside the output folder {out_dir}: give a "
                                   "relative path inside it (no '..', not absolute)")
            key = _folded(path)
            if key in reserved:
                raise FacegenError(f"{where}: output {target} is the batch's own {reserved[key]}"
                                   f"{_note(path, out / reserved[key])}: rename the output")
            if key in written:
                line, other = written[key]
                raise FacegenError(f"{where}: output {target} is also the output of line {line}"
                                   f"{_note(path, other)}: give every row its own output")
            if key in inputs:
                line, what, source = inputs[key]
                whose = "the manifest" if what == "manifest" else f"an input of line {line} (its {what})"
                raise FacegenError(f"{where}: output {target} is {whose}{_note(path, source)}: writing it "
                                   "would destroy that input; choose another output name")
            written[key] = (job.line, path)
            wav = sidecar_path(path)
            line, other = sidecars.setdefault(_folded(wav), (job.line, wav))
            if line != job.line:
                raise FacegenError(f"{where}: output {target} shares its audio sidecar "
                                   f"{sidecar_path(target).name} with line {line}{_note(wav, other)} (same "
                                   "folder and name): give the rows different names")
            if _folded(wav) in inputs and (_folded(wav), job.line) not in own_audio:  # its own: not rewritten
                line, what, source = inputs[_folded(wav)]
                whose = "the manifest" if what == "manifest" else f"the {what} of line {line}"
                raise FacegenError(f"{where}: the audio sidecar of {target} would overwrite {whose}"
                                   f"{_note(wav, source)}: choose another output name")


def file_hash(path: str | os.PathLike) -> str:
    """The SHA-256 of a regular file's bytes (read in blocks); anything else (a FIFO, a device, a folder) is
    an OSError at once (input_files.open_input)."""
    digest = hashlib.sha256()
    with open_input(path) as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def item_key(job: Job, out_dir: str | os.PathLike, options: dict) -> str:
    """The content key of a job: its audio and transcript/alignment bytes, speaker, outputs and `options`
    (the model's hash, the text model, anything else that changes the result) and facegen's version.
    An input that cannot be read is a FacegenError (that item's error), as is a row that cannot run
    (`Job.problem`, e.g. its transcript file is a FIFO): it never goes to a worker."""
    if job.problem:
        raise FacegenError(job.problem)
    try:
        audio = file_hash(job.audio)
        words = file_hash(job.alignment) if job.alignment is not None else None
    except OSError as exc:
        name = exc.filename or job.audio
        raise FacegenError(f"cannot read {name} ({exc.strerror}): fix the path in the manifest") from exc
    content = {"facegen": __version__, "audio": audio, "alignment": words, "no_text": job.no_text,
               "text": hashlib.sha256(job.text.encode()).hexdigest() if job.text is not None else None,
               "speaker": job.speaker, "outputs": [os.path.relpath(t, out_dir) for t in job.targets],
               "options": options, **({"emotion": job.emotion.as_dict()} if job.emotion is not None else {}),
               **({"strength": job.strength} if job.strength is not None else {}),
               **({"language": job.language} if job.language not in (None, "en") else {})}
    return hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest()


@dataclass
class RunState:
    """The items done in an output folder: output (relative) -> {"key", "files": {file: [size, mtime_ns]}}."""

    out_dir: Path
    items: dict[str, dict] = field(default_factory=dict)

    @property
    def path(self) -> Path:
        return self.out_dir / STATE_NAME

    @classmethod
    def load(cls, out_dir: str | os.PathLike) -> RunState:
        """The state recorded in `out_dir` (empty when there is none or it is unreadable: everything runs)."""
        state = cls(Path(out_dir))
        try:
            data = json.loads(read_input(state.path, what="run state", limit=STATE_BYTES, too_big="-"))
        except (FacegenError, ValueError, RecursionError):  # also a FIFO or a device put there
            return state
        if isinstance(data, dict) and data.get("version") == STATE_VERSION and isinstance(data.get("items"),
                                                                                          dict):
            state.items = data["items"]
        return state

    def name(self, job: Job) -> str:
        return os.path.relpath(job.output, self.out_dir)

    def unchanged(self, job: Job, key: str) -> bool:
        """True when `job` was done with this `key` and its files are as it left them."""
        entry = self.items.get(self.name(job))
        if not isinstance(entry, dict) or entry.get("key") != key or not isinstance(entry.get("files"), dict):
            return False
        return all(_stamp(self.out_dir / f) == stamp for f, stamp in entry["files"].items())

    def record(self, result: JobResult, key: str) -> None:
        """Note a finished item: a passed one is done, a skipped one stays done; any other is forgotten (it
        runs again next time)."""
        name = self.name(result.job)
        if result.status == "skipped":
            return
        if result.status != "passed":
            self.items.pop(name, None)
            return
        files = {os.path.relpath(f, self.out_dir): _stamp(f) for f in result.files}
        self.items[name] = {"key": key, "files": files}

    def save(self) -> None:
        with atomic_path(self.path) as tmp:
            tmp.write_text(json.dumps({"version": STATE_VERSION, "items": self.items}, indent=0),
                           encoding="utf-8")


def _stamp(path: str | os.PathLike) -> list[int] | None:
    try:
        st = os.stat(path)
    except OSError:
        return None
    return [st.st_size, st.st_mtime_ns]
