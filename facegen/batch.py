"""Many clips at once: manifests (CSV/JSON), the model and text backend loaded once, decoder BiLSTMs run over
packed batches of clips, one result per clip (a failing clip never stops the others)."""

from __future__ import annotations

import json
import os
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from facegen.bundle import Bundle, load_bundle
from facegen.errors import FacegenError
from facegen.exchange import format_module, write_animation
from facegen.inference import batch_decoder_states, frame_stream
from facegen.pipeline import finish_animation, prepare_clip
from facegen.runtime import Say, select_device, silent


@dataclass
class Job:
    """One clip to animate: the audio, where its words come from, the speaker, the output file."""

    audio: Path
    output: Path
    text: str | None = None
    alignment: Path | None = None
    speaker: str | None = None
    no_text: bool = False


@dataclass
class JobResult:
    job: Job
    files: list[Path] = field(default_factory=list)
    error: str | None = None
    frames: int = 0
    seconds: float = 0.0

    @property
    def ok(self) -> bool:
        return self.error is None


MANIFEST_COLUMNS = ("audio", "text", "text_file", "alignment", "speaker", "output")


def read_manifest(path: str | os.PathLike, outdir: str | os.PathLike | None = None,
                  default_ext: str = ".usdc") -> list[Job]:
    """Jobs from a CSV (header: audio, text | text_file | alignment, speaker, output) or a JSON manifest
    (a list of objects with those keys, or {"jobs": [...]}).

    Relative audio/text_file/alignment paths are relative to the manifest's folder; relative outputs to
    `outdir` (default: the manifest's folder). A missing output is the audio's name with `default_ext`.
    A row with neither text nor alignment has its words recognised (as `facegen animate` without --text).
    """
    import csv

    path = Path(path)
    try:
        raw = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise FacegenError(f"cannot read manifest {path} ({exc}): pass a UTF-8 CSV or JSON file") from exc
    if raw.lstrip().startswith(("[", "{")):
        try:
            data = json.loads(raw)
        except json.JSONDecodeError as exc:
            raise FacegenError(f"manifest {path} is not valid JSON ({exc}): fix it") from exc
        rows = data.get("jobs") if isinstance(data, dict) else data
        if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
            raise FacegenError(f'manifest {path} must be a list of objects or {{"jobs": [...]}}')
    else:
        rows = list(csv.DictReader(raw.splitlines()))
    base = path.parent
    out_base = Path(outdir) if outdir is not None else base
    jobs = []
    for n, row in enumerate(rows, 1):
        row = {str(k).strip().lower(): (str(v).strip() if v is not None else "") for k, v in row.items() if k}
        unknown = sorted(set(row) - set(MANIFEST_COLUMNS))
        if unknown:
            raise FacegenError(f"manifest {path}: unknown column(s) {', '.join(unknown)}: use "
                               f"{', '.join(MANIFEST_COLUMNS)}")
        if not row.get("audio"):
            raise FacegenError(f"manifest {path}, row {n}: no audio file given")
        audio = base / row["audio"]
        text = row.get("text") or None
        if row.get("text_file"):
            try:
                text = (base / row["text_file"]).read_text(encoding="utf-8")
            except (OSError, UnicodeDecodeError) as exc:
                raise FacegenError(f"manifest {path}, row {n}: cannot read {row['text_file']} ({exc})") from exc
        alignment = base / row["alignment"] if row.get("alignment") else None
        if text and alignment:
            raise FacegenError(f"manifest {path}, row {n}: give text or alignment, not both")
        output = row.get("output") or Path(row["audio"]).with_suffix(default_ext).name
        try:
            format_module(output)
        except FacegenError as exc:
            raise FacegenError(f"manifest {path}, row {n}: {exc}") from None
        jobs.append(Job(audio=audio, output=out_base / output, text=text, alignment=alignment,
                        speaker=row.get("speaker") or None))
    if not jobs:
        raise FacegenError(f"manifest {path} lists no clips")
    return jobs


def animate_many(jobs: Iterable[Job], *, bundle=None, device: str = "auto", text_model: str | None = None,
                 batch_size: int = 16, window: int = 64, say: Say = silent,
                 warn: Say = silent) -> Iterator[tuple[Job, object]]:
    """Animate many clips with the model and text backend loaded once: yields (job, Animation) or
    (job, FacegenError) for every job, in the input order within windows of `window` jobs.

    Within a window, clips are sorted by length and run through the decoder BiLSTMs `batch_size` at a
    time (packed: each clip's result equals its own single run). The frames of each Animation are a
    FrameStream (computed when the writer reads them).
    """
    if not isinstance(bundle, Bundle):
        bundle = load_bundle(bundle)
    dev = select_device(device)
    pending: list[Job] = []

    def run(window_jobs: list[Job]) -> Iterator[tuple[Job, object]]:
        prepared: dict[int, object] = {}
        for i, job in enumerate(window_jobs):
            try:
                prepared[i] = prepare_clip(job.audio, bundle=bundle, text=job.text, alignment=job.alignment,
                                           no_text=job.no_text, speaker=job.speaker, text_model=text_model,
                                           warn=warn)
            except FacegenError as exc:
                prepared[i] = exc
        ready = sorted((i for i, c in prepared.items() if not isinstance(c, FacegenError)),
                       key=lambda i: prepared[i].num_frames)
        for b in range(0, len(ready), batch_size):
            ids = ready[b:b + batch_size]
            clips = [prepared[i] for i in ids]
            states = batch_decoder_states(bundle, [(c.mel, c.text_features, c.speaker, c.phones) for c in clips],
                                          device=dev)
            for i, clip, st in zip(ids, clips, states, strict=True):
                prepared[i] = finish_animation(bundle, clip, frame_stream(bundle, st, clip.mesh.vertices))
        for i, job in enumerate(window_jobs):
            yield job, prepared[i]

    for job in jobs:
        pending.append(job)
        if len(pending) >= window:
            yield from run(pending)
            pending = []
    if pending:
        yield from run(pending)


def run_batch(jobs: Sequence[Job], *, bundle=None, device: str = "auto", text_model: str | None = None,
              batch_size: int = 16, say: Say = silent, warn: Say = silent) -> list[JobResult]:
    """Animate every job and write its output (format from the extension); a clip that fails is
    reported in its JobResult and the others go on. Returns one JobResult per job, in order."""
    results = []
    start = time.perf_counter()
    for n, (job, anim) in enumerate(animate_many(jobs, bundle=bundle, device=device, text_model=text_model,
                                                 batch_size=batch_size, warn=warn), 1):
        t0 = time.perf_counter()
        if isinstance(anim, FacegenError):
            results.append(JobResult(job, error=str(anim)))
        else:
            try:
                job.output.parent.mkdir(parents=True, exist_ok=True)
                files = write_animation(anim, job.output, audio_source=job.audio)
                results.append(JobResult(job, files=files, frames=anim.num_frames,
                                         seconds=time.perf_counter() - t0))
            except FacegenError as exc:
                results.append(JobResult(job, error=str(exc)))
        r = results[-1]
        say(f"[{n}/{len(jobs)}] {job.output}: " + (f"{r.frames} frames" if r.ok else f"error: {r.error}")
            + f" ({time.perf_counter() - start:.1f} s)")
    return results
