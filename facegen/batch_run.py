"""The library entry of `facegen batch`: read the manifest, refuse a bad plan before any work, skip the items
unchanged since the last run, run the rest on an engine (local worker processes or Ray), record each finished
item in the run state as it comes, and write the reports.

    outcome = run_manifest("lines.csv", "out/", jobs=2, formats=["usdc", "glb"])
    outcome.ok, outcome.summary, outcome.results   # report.json / report.xml are in out/
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from facegen.batch import Job, JobResult, read_manifest
from facegen.batch_plan import RunState, check_plan, file_hash, item_key
from facegen.batch_report import summary_line, write_reports
from facegen.blinks import DEFAULT_RATE, check_blink_rate, check_seed
from facegen.engines import ENGINES, check_ray, run_local, run_ray
from facegen.errors import FacegenError
from facegen.exchange import format_of, format_of_extension
from facegen.runtime import NOTES, Reporter, cores

SAVE_EVERY = 5.0  # seconds between saves of the run state while items finish


@dataclass
class BatchOutcome:
    results: list[JobResult]  # one per manifest row, in manifest order
    seconds: float
    summary: str
    report_json: Path
    report_xml: Path

    @property
    def ok(self) -> bool:
        return all(r.status in ("passed", "skipped") for r in self.results)


def parse_formats(value: str | Sequence[str] | None) -> list[str] | None:
    """"usdc,glb,json" (or a list) -> [".usdc", ".glb", ".json"]; an unknown format is a FacegenError."""
    if value is None:
        return None
    names = value.split(",") if isinstance(value, str) else list(value)
    exts = ["." + n.strip().lower().lstrip(".") for n in names if n.strip()]
    if not exts:
        raise FacegenError("the list of formats is empty: give extensions such as usdc,glb,json",
                           param="formats")
    for ext in exts:
        format_of_extension(ext)
    if len(set(exts)) < len(exts):
        raise FacegenError(f"the formats {','.join(names)} name a format twice: give each once",
                           param="formats")
    return exts


def run_manifest(manifest: str | os.PathLike, out_dir: str | os.PathLike, *, jobs: int | None = None,
                 formats: str | Sequence[str] | None = None, force: bool = False, engine: str = "local",
                 ray_address: str | None = None, model: str | os.PathLike | None = None,
                 text_model: str | None = None, device: str = "auto", batch_size: int = 16,
                 default_ext: str = ".usdc", fps: float | None = None, usd_mode: str | None = None,
                 on_mismatch: str = "error", blink_rate: float = DEFAULT_RATE, seed: int = 0,
                 emotion: str | None = None, head_motion: float = 1.0, strength=None, language: str = "en",
                 lip_seal: bool = True,
                 reporter: Reporter = NOTES, on_result: Callable[[JobResult], None] | None = None,
                 on_plan: Callable[[int, int], None] | None = None) -> BatchOutcome:
    """Animate every row of `manifest` into `out_dir` (see the module docstring).

    `jobs`: worker processes (local) or Ray actors (default: this machine's cores; Ray: the cluster's CPUs);
    `formats`: write each item in these formats from one inference (default: each row's output);
    `force`: redo unchanged items too; `fps`: every item's frame rate (None: the model's); `usd_mode`:
    "points" or "blendshapes" for every USD target (None: the writer's default, points); `on_mismatch`:
    "error" refuses a line whose transcript does not match its speech, "warn" writes it and flags it in
    the reports (each item's "match" holds its score either way: facegen.transcript_match); `blink_rate`
    and `seed`: every item's blinks (facegen.blinks); `emotion`: every item's (facegen.expression), where
    its row has no 'emotion' of its own; `head_motion`: how much the heads move (facegen.head); `lip_seal`:
    the lips shut on p, b and m (facegen.lip_seal); `strength`:
    every item's region scales (facegen.strength), where its row has no 'strength' of its own; `language`:
    every item's transcript language (facegen.languages), where its row has no 'language' of its own.
    `reporter`'s notes say, once per run and before any item runs, each control asked for that an output
    format cannot carry (facegen.exchange.controls: e.g. --fps 30 into .npy).
    `on_plan(total, to_run)` is called once the plan stands, `on_result` with every item's result (skipped
    ones first). User errors (a malformed manifest, a refused plan, bad
    options, an unreachable Ray cluster) are FacegenErrors raised before any item runs.
    """
    started = time.time()
    if jobs is not None and jobs < 1:
        raise FacegenError(f"the number of jobs must be at least 1, got {jobs}", param="jobs")
    if engine not in ENGINES:
        raise FacegenError(f"unknown engine {engine!r}: use {' or '.join(ENGINES)}", param="engine")
    if ray_address is not None and engine != "ray":
        raise FacegenError("a Ray address applies to the ray engine only", param=("ray_address", "engine"))
    from facegen.animation import check_fps
    from facegen.transcript_match import ON_MISMATCH

    check_fps(fps)
    blink_rate, seed = check_blink_rate(blink_rate), check_seed(seed)
    from facegen.expression import parse_emotion

    emotion = parse_emotion(emotion)
    from facegen.head import check_amount

    head_motion = check_amount(head_motion)
    from facegen.strength import parse_strength

    strength = parse_strength(strength)
    from facegen.languages import check_language

    language = check_language(language).code
    if on_mismatch not in ON_MISMATCH:
        raise FacegenError(f"unknown mismatch choice {on_mismatch!r}: use one of {', '.join(ON_MISMATCH)}",
                           param="on_mismatch")
    if usd_mode not in (None, "points", "blendshapes"):
        raise FacegenError(f"unknown USD mode {usd_mode!r}: use points or blendshapes", param="usd_mode")
    exts = parse_formats(formats)
    format_of_extension(default_ext)
    out = Path(os.path.abspath(out_dir))
    all_jobs = read_manifest(manifest, outdir=out, default_ext=default_ext, formats=exts)
    for job in all_jobs:  # workers may run anywhere (Ray): absolute inputs
        job.fps = fps
        job.on_mismatch = on_mismatch
        job.blink_rate, job.seed = blink_rate, seed
        job.emotion = job.emotion if job.emotion is not None else emotion
        job.head_motion, job.lip_seal = head_motion, bool(lip_seal)
        job.strength = job.strength if job.strength is not None else strength
        job.language = job.language or language
        job.options = {"mode": usd_mode} if usd_mode else {}
        job.audio = Path(os.path.abspath(job.audio))
        job.alignment = Path(os.path.abspath(job.alignment)) if job.alignment is not None else None
    check_plan(all_jobs, out)
    model_path = Path(model) if model is not None else None
    _check_rig(all_jobs, model_path)
    if engine == "ray":
        check_ray(ray_address)
    out.mkdir(parents=True, exist_ok=True)

    options = {"model": _model_hash(model_path), "text_model": text_model}
    if fps is not None or usd_mode is not None:  # (absent when unset: an earlier run's items stay unchanged)
        options |= {"fps": fps, "usd_mode": usd_mode}
    if (blink_rate, seed) != (DEFAULT_RATE, 0):
        options |= {"blinks": [blink_rate, seed]}
    if head_motion != 1.0:
        options |= {"head_motion": head_motion}
    if not lip_seal:
        options |= {"lip_seal": False}
    for line in dropped_controls(all_jobs, model_path):  # once per run, before any item runs
        reporter.note(line)
    state = RunState.load(out)
    results: dict[int, JobResult] = {}
    keys: dict[int, str] = {}
    to_run: list[Job] = []
    early: list[JobResult] = []
    for i, job in enumerate(all_jobs):
        try:
            keys[i] = item_key(job, out, options)
        except FacegenError as exc:
            early.append(JobResult(job, error=str(exc)))
            continue
        if not force and state.unchanged(job, keys[i]):
            early.append(JobResult(job, skipped=True))
        else:
            to_run.append(job)
    if on_plan is not None:
        on_plan(len(all_jobs), len(to_run))
    # results may come from other processes
    index = {(job.line, job.output): i for i, job in enumerate(all_jobs)}
    last_save = time.monotonic()

    def finished(result: JobResult) -> None:
        nonlocal last_save
        i = index[(result.job.line, result.job.output)]
        result.job = all_jobs[i]
        results[i] = result
        if i in keys:
            state.record(result, keys[i])
        if time.monotonic() - last_save > SAVE_EVERY:
            state.save()
            last_save = time.monotonic()
        if on_result is not None:
            on_result(result)

    for result in early:
        finished(result)
    t0 = time.perf_counter()
    try:
        if to_run:
            common = {"model": str(model_path) if model_path else None, "device": device,
                      "text_model": text_model, "batch_size": batch_size, "on_result": finished}
            if engine == "ray":
                run_ray(to_run, workers=jobs, address=ray_address, **common)
            else:
                run_local(to_run, workers=min(jobs or cores(), len(to_run)), **common)
    finally:
        if results:
            state.save()
    seconds = time.perf_counter() - t0
    ordered = [results[i] for i in range(len(all_jobs))]
    run = {"manifest": str(manifest), "out": str(out), "engine": engine, "jobs": jobs or None,
           "formats": exts, "force": force, "started": started, "seconds": round(seconds, 3),
           "model": str(model_path) if model_path else "default", "model_sha256": options["model"],
           "audio_seconds": round(sum(r.audio_seconds for r in ordered if not r.skipped), 3),
           "worker_cpu_seconds": round(sum(r.cpu_seconds for r in ordered), 3)}
    report_json, report_xml = write_reports(ordered, out, run)
    return BatchOutcome(ordered, seconds, summary_line(ordered, seconds, out), report_json, report_xml)


def _model_hash(model: Path | None) -> str:
    from facegen.bundle import default_bundle_path

    path = model if model is not None else default_bundle_path()
    try:
        return file_hash(path)
    except OSError as exc:
        raise FacegenError(f"cannot read the model bundle {path} ({exc.strerror}): pass the path of a "
                           ".safetensors bundle", param="model") from exc


def dropped_controls(jobs: list[Job], model: Path | None) -> list[str]:
    """The warnings of facegen.exchange.controls for every job's targets, each once (a batch's outputs are
    called NAME in them); no head motion to carry when the model's face has no head pivot."""
    from facegen.bundle import read_template
    from facegen.exchange.controls import dropped
    from facegen.head import has_pivot

    turns = has_pivot(read_template(model).regions)  # the face alone: no torch
    lines = []
    for job in jobs:
        asked = {"fps": job.fps, "head_motion": job.head_motion if turns else 0.0,
                 "blink_rate": job.blink_rate, "seed": job.seed, "emotion": job.emotion,
                 "strength": job.strength}
        for target in job.targets:
            lines += dropped(Path("NAME" + target.suffix), asked)
    return list(dict.fromkeys(lines))


def _check_rig(jobs: list[Job], model: Path | None) -> None:
    """ARKit outputs (.json, .csv) need the rig's regions on the model's template: checked before any work."""
    if not any(format_of(t).arkit for job in jobs for t in job.targets):
        return
    from facegen.bundle import load_bundle
    from facegen.exchange.morph_targets import check_rig

    check_rig("arkit", load_bundle(model).template)
