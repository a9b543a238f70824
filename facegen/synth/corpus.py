"""The synthetic speech-and-motion corpus (`facegen data synth OUT`), in the BIWI community layout.

14 speakers with BIWI's names (F1–F8, M1–M6) say the 48 sentences of facegen.synth.sentences (e01–e40
like BIWI's 40, e41–e48 with held-out emotional words). Each speaker has

* a voice: an espeak-ng language (en-us, en, en-gb-x-rp, en-us-nyc, en-029, en-gb-scotland), a variant
  (female variants for F*, male for M*), a pitch (0–100) and a rate (135–155 words per minute, chosen so
  the sentences last 4.7 s on average, BIWI's mean) — see SPEAKERS;
* a face shape: facegen.face.procedural.speaker_face(index) and a motion style
  SpeakerStyle.for_speaker(index), where index is the speaker's place in SPEAKERS (F1 = 0 … M6 = 13).

Per sequence {subj}_e{NN}: the synthesiser's audio (wav/, 16-bit PCM at espeak's 22,050 Hz), the motion
(vertices_npy/, float32 [T, 3V] at `fps`, T = facegen.audio.num_frames(duration, fps) = round(duration·fps)),
the transcript (text/) and the synthesiser's own word timings (alignments/{name}.json — so training need
not force-align). Motion: Rig(speaker_face).pose(motion_curves(phones, words, T, fps, style, rng)) with
rng = numpy.random.default_rng([seed, speaker index, sentence]) (the blinks). The root also holds
BIWI.ply (make_face(): the neutral default face, the template of trained bundles) with its regions
(lips → regions/lve.txt, upper_face → regions/fdd.txt, the rig's others by name), templates.pkl (each
speaker's neutral face), sentences.txt ("e01 text" lines) and synth.json, the manifest.

The manifest records the generation parameters (corpus version, seed, fps, digests of the sentences
and voices) and every finished sequence. A run into a folder made with the same parameters skips the
finished sequences (so an interrupted run resumes); a folder made with other parameters is refused.

Determinism: the same parameters give byte-identical sequence files. libespeak-ng keeps waveform state
between calls (pitch flutter, gain control) that no API resets, so every speaker is generated in a fresh
process (processes.process_pool: spawned, never forked) that synthesises that speaker's sentences in
order from e01 up to the last one asked for — also those it does not write (synthesis takes ~0.1 s).
Parallelism is per speaker.

Selections: `speakers` and `sentences` (all 14 × e01–e48 by default), or `preset="paper"`: the training
speakers (F2 F3 F4 M3 M4 M5) e01–e48 and the test-B speakers e37–e48 — 384 sequences, 12.7 GB,
generated in ~1.5 min with 2 workers. With facegen.datasets.splits.Splits the defaults give
train/val/test-a/test-b; the unseen-emotion-word test is Splits(test_sentences=range(41, 49)) (test-a:
training speakers, test-b: unseen speakers).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import time
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from facegen.atomic import atomic_path
from facegen.datasets.splits import parse_numbers, parse_subjects, sequence_name
from facegen.errors import FacegenError
from facegen.processes import process_pool
from facegen.runtime import SILENT, Reporter, threads
from facegen.synth.sentences import SENTENCES

CORPUS_VERSION = 1  # bump when the face, rig, voices or sentences change what is generated
MANIFEST = "synth.json"
TRAIN_SPEAKERS = ("F2", "F3", "F4", "M3", "M4", "M5")
TEST_SPEAKERS = ("F1", "F5", "F6", "F7", "F8", "M1", "M2", "M6")
PRESETS = ("paper",)
MEAN_SECONDS = 4.7  # for the disk estimate


@dataclass(frozen=True)
class Voice:
    """One synthetic speaker's espeak-ng voice."""

    language: str  # espeak voice name
    variant: str  # espeak variant (voices/!v)
    pitch: int  # 0-100
    rate: int  # words per minute


SPEAKERS: dict[str, Voice] = {
    "F1": Voice("en-us", "f1", 55, 148),
    "F2": Voice("en", "f2", 50, 140),
    "F3": Voice("en-us", "f3", 45, 152),
    "F4": Voice("en-gb-x-rp", "f4", 60, 138),
    "F5": Voice("en-029", "f5", 48, 145),
    "F6": Voice("en", "belinda", 40, 155),
    "F7": Voice("en-us", "steph", 52, 135),
    "F8": Voice("en-gb-scotland", "linda", 58, 150),
    "M1": Voice("en-us", "m1", 45, 150),
    "M2": Voice("en", "m2", 55, 142),
    "M3": Voice("en-us-nyc", "m3", 50, 155),
    "M4": Voice("en-gb-x-rp", "m4", 40, 136),
    "M5": Voice("en-us", "m6", 60, 148),
    "M6": Voice("en-gb-scotland", "m7", 50, 144),
}


def speaker_index(name: str) -> int:
    """The index of a speaker (its face shape and motion style): its place in SPEAKERS."""
    if name not in SPEAKERS:
        raise FacegenError(f"unknown synthetic speaker {name!r}: choose from {' '.join(SPEAKERS)}")
    return list(SPEAKERS).index(name)


# ------------------------------------------------------------------------------------------ selection
def selection(speakers: str | Iterable[str] | None = None, sentences: str | Iterable[int] | None = None,
              preset: str | None = None) -> dict[str, tuple[int, ...]]:
    """{speaker: sentence numbers} to generate: `speakers` × `sentences` (default all 14 × e01–e48),
    or a preset ("paper": training speakers e01–e48, test-B speakers e37–e48)."""
    if preset is not None:
        if preset not in PRESETS:
            raise FacegenError(f"unknown preset {preset!r}: choose one of {', '.join(PRESETS)}")
        if speakers is not None or sentences is not None:
            raise FacegenError("a preset chooses the speakers and sentences itself: drop the speakers and "
                               "sentences, or the preset", param=("speakers", "sentences", "preset"))
        every = tuple(SENTENCES)
        return {**{s: every for s in TRAIN_SPEAKERS}, **{s: tuple(n for n in every if n >= 37)
                                                          for s in TEST_SPEAKERS}}
    names = parse_subjects(speakers) if speakers is not None else tuple(SPEAKERS)
    numbers = parse_numbers(sentences) if sentences is not None else tuple(SENTENCES)
    for name in names:
        speaker_index(name)
    bad = [n for n in numbers if n not in SENTENCES]
    if bad:
        raise FacegenError(f"no sentence e{bad[0]:02d} in the synthetic corpus: "
                           f"choose from 1-{max(SENTENCES)}")
    if not names or not numbers:
        raise FacegenError("nothing to generate: give at least one speaker and one sentence")
    return {name: numbers for name in names}


# ------------------------------------------------------------------------------------------ one sequence
def sequence_rng(seed: int, speaker: str, sentence: int) -> np.random.Generator:
    """The random generator of one sequence (its blinks): independent of what else is generated."""
    return np.random.default_rng([seed, speaker_index(speaker), sentence])


def speak(speaker: str, sentence: int):
    """The speech of one sentence by one speaker (facegen.espeak.Speech)."""
    from facegen.espeak import synthesize

    v = SPEAKERS[speaker]
    return synthesize(SENTENCES[sentence], v.language, v.pitch, v.rate, v.variant)


def motion(speech, rig, style, rng: np.random.Generator, fps: float = 25.0) -> np.ndarray:
    """Ground-truth vertices [T, V, 3] float32 for `speech`, T = round(duration · fps)."""
    from facegen.audio import num_frames
    from facegen.synth.curves import motion_curves

    T = num_frames(speech.duration, fps)
    return rig.pose(motion_curves(speech.phones, speech.words, T, fps, style, rng))


def speaker_rig(speaker: str):
    """(Rig on the speaker's face, the speaker's SpeakerStyle)."""
    from facegen.face.procedural import speaker_face
    from facegen.face.rig import Rig
    from facegen.synth.curves import SpeakerStyle

    i = speaker_index(speaker)
    return Rig(speaker_face(i)), SpeakerStyle.for_speaker(i)


# ------------------------------------------------------------------------------------------ the corpus
@dataclass
class CorpusReport:
    out: Path
    generated: list[str] = field(default_factory=list)
    present: list[str] = field(default_factory=list)  # skipped: already generated with the same parameters
    seconds: float = 0.0
    durations: dict[str, float] = field(default_factory=dict)  # audio seconds of the generated sequences

    def summary(self) -> str:
        mean = float(np.mean(list(self.durations.values()))) if self.durations else 0.0
        text = (f"generated {len(self.generated)} sequences in {self.seconds:.0f} s into {self.out}"
                f" (mean duration {mean:.2f} s)")
        if self.present:
            text += f"; {len(self.present)} were already there"
        return text


def parameters(seed: int, fps: float) -> dict:
    """What determines the generated files (compared with the manifest before resuming)."""
    def digest(obj) -> str:
        return hashlib.sha256(json.dumps(obj, sort_keys=True).encode()).hexdigest()[:16]

    return {"version": CORPUS_VERSION, "seed": int(seed), "fps": float(fps),
            "sentences": digest({str(k): v for k, v in SENTENCES.items()}),
            "voices": digest({k: asdict(v) for k, v in SPEAKERS.items()})}


def _read_corpus_manifest(out: Path) -> dict | None:
    path = Path(out) / MANIFEST
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise FacegenError(f"{path} is unreadable ({exc}): delete it to regenerate the corpus") from exc
    if not isinstance(data, dict) or not all(isinstance(data.get(k), dict) for k in ("params", "sequences")):
        raise FacegenError(f"{path} is not a synthetic-corpus manifest: delete it to regenerate the corpus")
    return data


def _write_corpus_manifest(out: Path, manifest: dict) -> None:
    with atomic_path(out / MANIFEST) as tmp:
        tmp.write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n")


def _files(out: Path, name: str) -> list[Path]:
    return [out / "wav" / f"{name}.wav", out / "vertices_npy" / f"{name}.npy", out / "text" / f"{name}.txt",
            out / "alignments" / f"{name}.json"]


def synthesize_corpus(out: str | os.PathLike, speakers: str | Iterable[str] | None = None,
                      sentences: str | Iterable[int] | None = None, *, preset: str | None = None,
                      fps: float = 25.0, seed: int = 0, workers: int = 1,
                      reporter: Reporter = SILENT) -> CorpusReport:
    """Generate the synthetic corpus (or the part asked for) into `out` in the BIWI community layout.

    `speakers` ("F2,F3" or names) and `sentences` ("1-40" or numbers) select what to generate (default:
    all 14 speakers × e01–e48); `preset="paper"` instead generates the training speakers' e01–e48 and
    the test-B speakers' e37–e48. Sequences already in the folder's manifest (same parameters) are
    skipped. `workers` processes generate speakers in parallel (a bar when `reporter` draws bars). Returns
    what was done.
    """
    if not 0 < fps <= 1000:  # also refuses nan
        raise FacegenError(f"fps {fps} must be a positive number up to 1000, e.g. 25")
    if workers < 1:
        raise FacegenError(f"workers {workers} must be at least 1")
    started = time.monotonic()
    wanted = selection(speakers, sentences, preset)
    out = Path(out)
    params = parameters(seed, fps)
    manifest = _read_corpus_manifest(out) if out.is_dir() else None
    if manifest is not None and manifest["params"] != params:
        raise FacegenError(f"{out} holds a synthetic corpus made with other parameters "
                           f"({_difference(manifest['params'], params)}): choose another folder or delete it")
    manifest = manifest or {"generator": "facegen.synth.corpus", "params": params, "sequences": {}}
    report = CorpusReport(out=out)
    todo: dict[str, tuple[int, ...]] = {}
    for speaker, numbers in wanted.items():
        missing = []
        for n in numbers:
            name = sequence_name(speaker, n)
            if name in manifest["sequences"] and all(p.is_file() for p in _files(out, name)):
                report.present.append(name)
            else:
                missing.append(n)
        if missing:
            todo[speaker] = tuple(missing)
    total = sum(len(v) for v in todo.values())

    from facegen.datasets.biwi import DatasetWriter
    from facegen.datasets.templates import read_templates_pkl

    writer = DatasetWriter(out)
    _check_space(out, total, fps)
    _write_static(out, writer, wanted, read_templates_pkl)
    _write_corpus_manifest(out, manifest)
    if total:
        _run(out, todo, seed, fps, workers, reporter, manifest, report)
    report.seconds = time.monotonic() - started
    return report


def _difference(old: dict, new: dict) -> str:
    keys = [k for k in sorted(set(old) | set(new)) if old.get(k) != new.get(k)]
    return ", ".join(f"{k} {old.get(k)} instead of {new.get(k)}" for k in keys)


def _check_space(out: Path, sequences: int, fps: float) -> None:
    from facegen.face.procedural import NUM_VERTICES

    need = sequences * MEAN_SECONDS * fps * NUM_VERTICES * 12 * 1.1
    free = shutil.disk_usage(out).free
    if need > free:
        raise FacegenError(f"the {sequences} sequences need about {need / 1e9:.1f} GB but {out} has "
                           f"{free / 1e9:.1f} GB free: free space, or choose fewer speakers or sentences",
                           param=("speakers", "sentences"))


def _write_static(out: Path, writer, wanted: dict[str, tuple[int, ...]], read_templates_pkl) -> None:
    """BIWI.ply with regions, templates.pkl (merged with the speakers already there), sentences.txt."""
    from facegen.face.procedural import make_face, speaker_face

    if not (out / "BIWI.ply").is_file():
        writer.write_mesh(make_face())
    pkl = out / "templates.pkl"
    templates = read_templates_pkl(pkl) if pkl.is_file() else {}
    missing = [s for s in wanted if s not in templates]
    if missing:
        for s in missing:
            templates[s] = speaker_face(speaker_index(s)).vertices
        writer.write_templates(dict(sorted(templates.items())))
    with atomic_path(out / "sentences.txt") as tmp:
        tmp.write_text("".join(f"e{n:02d} {text}\n" for n, text in SENTENCES.items()), encoding="utf-8")


def _run(out: Path, todo: dict[str, tuple[int, ...]], seed: int, fps: float, workers: int,
         reporter: Reporter, manifest: dict, report: CorpusReport) -> None:
    """Generate `todo` with one fresh worker process per speaker (`workers` at a time: a spawn pool, a new
    process per task); record each finished sequence in the manifest as the worker reports it."""
    import multiprocessing
    import queue

    total = sum(len(v) for v in todo.values())
    order = sorted(todo, key=lambda s: -len(todo[s]))  # longest jobs first
    bar = reporter.bar(total=total, desc="synth", unit="seq")
    messages = multiprocessing.get_context("spawn").Queue()  # (name, info) of each sequence written

    def record(name: str, info: dict) -> None:
        manifest["sequences"][name] = info
        _write_corpus_manifest(out, manifest)
        report.generated.append(name)
        report.durations[name] = info["duration"]
        bar.update(1)

    # BLAS sums differ with the thread count: one thread in every worker, independent of `workers` (the
    # workers inherit the environment, so their libraries start with one thread)
    pool_size = min(workers, len(order))
    try:
        with threads(1, ("env",)), process_pool(pool_size, start="spawn", max_tasks_per_child=1,
                                                initializer=_start_speaker_worker,
                                                initargs=(messages,)) as pool:
            futures = {pool.submit(_speaker_job, str(out), s, todo[s], seed, fps): s for s in order}
            try:
                received = 0
                while received < total:
                    try:
                        record(*messages.get(timeout=0.2))
                        received += 1
                    except queue.Empty:
                        for future in (f for f in futures if f.done()):
                            _check_speaker(future, futures[future])
            except BaseException:
                for future in futures:
                    future.cancel()
                pool.stop()
                raise
    finally:
        bar.close()
        messages.close()


def _check_speaker(future, speaker: str) -> None:
    """Raise the error of a speaker's finished job, if any: a FacegenError as it is, anything else (a
    worker that died) as a FacegenError naming the speaker."""
    error = future.exception()
    if isinstance(error, FacegenError):
        raise error
    if error is not None:
        raise FacegenError(f"generating speaker {speaker} failed ({error or type(error).__name__}); "
                           "rerun to resume") from error


_messages = None  # in a speaker's worker process: the queue of the sequences it has written


def _start_speaker_worker(messages) -> None:
    """A speaker's worker starts: the queue to report to; its stderr (libespeak-ng's messages) silenced."""
    global _messages
    _messages = messages
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 2)
    os.close(devnull)


def _speaker_job(out: str, speaker: str, numbers: tuple[int, ...], seed: int, fps: float) -> None:
    """Synthesise e01 … max(numbers) in order and write the sequences in `numbers`, reporting each written
    one to the parent. Run in a fresh process (libespeak-ng's state), see _run."""
    from facegen.datasets.biwi import DatasetWriter

    writer = DatasetWriter(out)
    rig, style = speaker_rig(speaker)
    wanted = set(numbers)
    for n in sorted(SENTENCES):
        if n > max(numbers):
            break
        speech = speak(speaker, n)  # every sentence, in order: libespeak-ng's state carries over
        if n not in wanted:
            continue
        vertices = motion(speech, rig, style, sequence_rng(seed, speaker, n), fps)
        name = sequence_name(speaker, n)
        writer.write_sequence(name, vertices, audio=speech.audio, sample_rate=speech.sample_rate,
                              transcript=SENTENCES[n], words=speech.words)
        info = {"frames": len(vertices), "duration": round(speech.duration, 6),
                "sample_rate": int(speech.sample_rate)}
        _messages.put((name, info))
