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
from dataclasses import dataclass, field
from pathlib import Path

from facegen import __version__
from facegen.atomic import atomic_path
from facegen.batch import Job, JobResult
from facegen.errors import FacegenError
from facegen.exchange.wav import sidecar_path

STATE_NAME = ".facegen-batch.json"
REPORT_NAMES = ("report.json", "report.xml")
STATE_VERSION = 1


def _key(path: Path) -> str:
    return os.path.normcase(os.path.abspath(path))


def check_plan(jobs: list[Job], out_dir: str | os.PathLike) -> None:
    """Refuse, before any work, a plan that would lose or misplace a clip (a FacegenError naming the
    lines)."""
    out = Path(os.path.abspath(out_dir))
    reserved = {_key(out / name): name for name in (*REPORT_NAMES, STATE_NAME)}
    inputs: dict[str, int] = {}
    for job in jobs:
        for source in (job.audio, job.alignment):
            if source is not None:
                inputs.setdefault(_key(source), job.line)
    written: dict[str, int] = {}
    sidecars: dict[str, int] = {}
    for job in jobs:
        where = f"manifest line {job.line}"
        for target in job.targets:
            path = Path(os.path.abspath(target))
            if not path.is_relative_to(out):
                raise FacegenError(f"{where}: output {target} is outside the output folder {out_dir}: give a "
                                   "relative path inside it (no '..', not absolute)")
            key = _key(path)
            if key in reserved:
                raise FacegenError(f"{where}: output {target} is the batch's own {reserved[key]}: rename the "
                                   "output")
            if key in written:
                raise FacegenError(f"{where}: output {target} is also the output of line {written[key]}: "
                                   "give every row its own output")
            if key in inputs:
                raise FacegenError(f"{where}: output {target} is an input of line {inputs[key]}: writing it "
                                   "would destroy that input; choose another output name")
            written[key] = job.line
            wav = _key(sidecar_path(path))
            if sidecars.setdefault(wav, job.line) != job.line:
                raise FacegenError(f"{where}: output {target} shares its audio sidecar "
                                   f"{sidecar_path(target).name} with line {sidecars[wav]} (same folder and "
                                   "name): give the rows different names")
            if wav in inputs and inputs[wav] != job.line:
                raise FacegenError(f"{where}: the audio sidecar of {target} would overwrite the audio of "
                                   f"line {inputs[wav]}: choose another output name")


def file_hash(path: str | os.PathLike) -> str:
    """The SHA-256 of a file's bytes (read in blocks)."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def item_key(job: Job, out_dir: str | os.PathLike, options: dict) -> str:
    """The content key of a job: its audio and transcript/alignment bytes, speaker, outputs and `options`
    (the model's hash, the text model, anything else that changes the result) and facegen's version.
    An input that cannot be read is a FacegenError (that item's error)."""
    try:
        audio = file_hash(job.audio)
        words = file_hash(job.alignment) if job.alignment is not None else None
    except OSError as exc:
        name = exc.filename or job.audio
        raise FacegenError(f"cannot read {name} ({exc.strerror}): fix the path in the manifest") from exc
    content = {"facegen": __version__, "audio": audio, "alignment": words, "no_text": job.no_text,
               "text": hashlib.sha256(job.text.encode()).hexdigest() if job.text is not None else None,
               "speaker": job.speaker, "outputs": [os.path.relpath(t, out_dir) for t in job.targets],
               "options": options}
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
            data = json.loads(state.path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
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
        if not isinstance(entry, dict) or entry.get("key") != key:
            return False
        return all(_stamp(self.out_dir / f) == stamp for f, stamp in entry.get("files", {}).items())

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
