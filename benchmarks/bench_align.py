"""Benchmark: forced alignment of about a minute of speech, facegen.align against the code of a baseline
commit side by side in one process (`git show REF:facegen/align.py` imported as a second module).

Target (issue 13): at least 3x faster than the baseline on 60 s of speech, word timings within 20 ms of
the baseline's. The baseline's own spread is shown beside it ("again": the largest difference and the words
> 20 ms between its timed call and one more call on the same clip: it keeps pocketsphinx's noise estimate
from one call to the next). Clips are built at run time (cached under the temp folder, never in the repo):
sentences of the synthetic corpus said by several espeak-ng, Flite and Festival voices with pauses of 0.3-0.9
s between them, and examples/excellent_room.wav repeated with pauses. Where the synthesiser gives word
timings, both aligners' word onsets are also compared with them.

    python benchmarks/bench_align.py [--runs 3] [--baseline REF] [--seconds 60]
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
CACHE = Path(tempfile.gettempdir()) / "facegen-bench-align"
RATE = 16000
CLIPS = {
    "espeak": ["espeak:en-us+f1", "espeak:en+m2", "espeak:en-gb-x-rp+f4", "espeak:en-us+m6"],
    "flite": ["flite:slt", "flite:rms", "flite:awb"],
    "festival": ["festival:kal_diphone", "festival:ked_diphone", "festival:cmu_us_slt_arctic_hts"],
    "excellent_room": [],
}


def build_clip(name: str, seconds: float) -> tuple[np.ndarray, str, list[tuple[str, float, float]] | None]:
    """(16 kHz audio, transcript, synthesiser word timings or None) of about `seconds` of speech."""
    import soundfile as sf

    from facegen.audio import load_audio, resample
    from facegen.synth.sentences import SENTENCES
    from facegen.synth.voices import synthesize

    rng = np.random.default_rng(len(name))
    parts, texts, truth, total, k = [np.zeros(RATE // 2, np.float32)], [], [], 0.5, 0
    while total < seconds:
        if name == "excellent_room":
            audio, rate = load_audio(REPO / "examples" / "excellent_room.wav")
            text, words = (REPO / "examples" / "excellent_room.txt").read_text().strip(), None
        else:
            text = SENTENCES[1 + k % len(SENTENCES)]
            utt = synthesize(text, CLIPS[name][k % len(CLIPS[name])])
            audio, rate, words = utt.audio, utt.sample_rate, utt.words
        audio = resample(np.asarray(audio, np.float32), rate, RATE) if rate != RATE else np.asarray(audio,
                                                                                                    np.float32)
        audio = audio * (0.6 / (np.max(np.abs(audio)) + 1e-9))
        truth = None if words is None or truth is None else truth + [(w, total + a, total + b)
                                                                     for w, a, b in words]
        pause = np.zeros(int(rng.uniform(0.3, 0.9) * RATE), np.float32)
        parts += [audio, pause]
        texts.append(text)
        total += (len(audio) + len(pause)) / RATE
        k += 1
    clip = np.concatenate(parts)
    CACHE.mkdir(exist_ok=True)
    sf.write(CACHE / f"{name}-{seconds:g}.wav", clip, RATE)
    return clip, " ".join(texts), truth


def baseline_module(ref: str):
    """facegen/align.py of commit `ref`, imported as the module `align_baseline`."""
    source = subprocess.run(["git", "show", f"{ref}:facegen/align.py"], cwd=REPO, check=True,
                            capture_output=True, text=True).stdout
    path = CACHE / "align_baseline.py"
    CACHE.mkdir(exist_ok=True)
    path.write_text(source)
    spec = importlib.util.spec_from_file_location("align_baseline", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def timed(module, audio: np.ndarray, text: str, runs: int) -> tuple[float, float, list]:
    """Median wall and CPU seconds of `runs` calls of module.align, and its words."""
    walls, cpus = [], []
    for _ in range(runs):
        wall, cpu = time.perf_counter(), time.process_time()
        result = module.align(audio, RATE, text)
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    return statistics.median(walls), statistics.median(cpus), result


def differences(words, others) -> np.ndarray:
    """Per word, the larger of its start and end differences in ms (whole: times are rounded to 1 ms)."""
    return np.round([max(abs(a.start - b.start), abs(a.end - b.end)) * 1000
                     for a, b in zip(words, others, strict=True)])


def onset_error(words, truth) -> float | None:
    if truth is None or [w.text.lower() for w in words] != [t.lower().strip(".,?!") for t, _, _ in truth]:
        return None
    return float(np.median([abs(w.start - t[1]) for w, t in zip(words, truth, strict=True)])) * 1000


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--baseline", default="0850ec4", help="commit whose facegen/align.py is the baseline")
    args = parser.parse_args(argv)

    from facegen import align as new

    old = baseline_module(args.baseline)
    for module, kinds in ((old, ("align",)), (new, ("align", "cmn"))):
        for kind in kinds:
            module._decoder(kind)  # loading the model is not alignment
    worst, speedups, words, moved = 0.0, [], 0, 0
    print(f"{'clip':15s} {'s':>5s} {'base s':>7s} {'new s':>6s} {'x':>5s} {'base cpu':>8s} {'new cpu':>7s} "
          f"{'max diff':>8s} {'>20ms':>5s} {'words':>5s} {'again':>9s}  onset error vs synthesiser "
          "(base/new)")
    for name in CLIPS:
        audio, text, truth = build_clip(name, args.seconds)
        old_wall, old_cpu, old_words = timed(old, audio, text, args.runs)
        new_wall, new_cpu, new_words = timed(new, audio, text, args.runs)
        diffs = differences(old_words, new_words)
        again = differences(old_words, old.align(audio, RATE, text))  # the baseline's own spread
        worst = max(worst, float(diffs.max()))
        words += len(diffs)
        speedups.append(old_wall / new_wall)
        errors = [onset_error(w, truth) for w in (old_words, new_words)]
        shown = "/".join("-" if e is None else f"{e:.0f} ms" for e in errors)
        print(f"{name:15s} {len(audio) / RATE:5.1f} {old_wall:7.2f} {new_wall:6.2f} "
              f"{old_wall / new_wall:5.2f} {old_cpu:8.2f} {new_cpu:7.2f} {diffs.max():6.0f}ms "
              f"{int(np.sum(diffs > 20)):5d} {len(diffs):5d} {again.max():4.0f}ms "
              f"{int(np.sum(again > 20)):2d}  {shown}")
        moved += int(np.sum(diffs > 20))
        for a, b, d in zip(old_words, new_words, diffs, strict=True):
            if d > 20:
                print(f"    {a.text!r}: baseline {a.start:.2f}-{a.end:.2f}, new {b.start:.2f}-{b.end:.2f}")
    print(f"median speed-up {statistics.median(speedups):.2f}x (target >= 3x); largest word timing "
          f"difference {worst:.0f} ms, {moved} of {words} words > 20 ms (target <= 20 ms)")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    raise SystemExit(main())
