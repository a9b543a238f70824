"""Benchmark: `facegen batch` over 20 clips of speech on 2 cores, in real-time factor (seconds of audio per
second of wall time, the whole command timed from outside: start-up, model loads, alignment, writing and
validation included).

Target (issue 13): >= 15x real time with `--jobs 2` over 20 sentences. The clips are made at run time with
facegen.synth.voices (Flite, Festival and espeak-ng voices in turn; whichever are installed), one sentence of
the synthetic corpus each, with its transcript in the manifest (forced alignment, as for recorded lines).
Prints each configuration's wall seconds and real-time factor; `--compare 1` also runs `--jobs 1` (one worker,
as `facegen batch` ran before) side by side, alternating, so that a busy machine slows both alike; `--before
TREE` runs another source tree's `facegen batch` (e.g. a git worktree of the previous release) side by side
the same way. Each run writes into an empty folder, as a CI runner's first run does, and its outputs (about 35
MB of points per clip in .usdc) are deleted before the next run is timed: replacing them instead (`--force`
over the last run) adds the file system's work of freeing them, 0.5-1 s for 20 clips on the development
machine.

    python benchmarks/bench_batch.py [--clips 20] [--jobs 2] [--formats usdc] [--runs 1] [--compare 1]
                                     [--before TREE]
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def make_clips(folder: Path, count: int) -> float:
    """`count` sentences spoken by the installed voices in turn, as WAVs with a manifest; returns the total
    seconds of audio."""
    import csv

    from facegen.audio import write_wav
    from facegen.synth.sentences import generated_sentences
    from facegen.synth.voices import available_voices, synthesize

    voices = available_voices()
    by_engine = {e: [v for v in voices if v.engine == e] for e in ("flite", "festival", "espeak")}
    order = [v for group in zip(*[g for g in by_engine.values() if g], strict=False) for v in group]
    order += [v for v in voices if v not in order]
    sentences = [s for s in generated_sentences(200).values() if 10 <= len(s.split()) <= 16][:count]
    total = 0.0
    with open(folder / "lines.csv", "w", newline="") as f:
        out = csv.writer(f)
        out.writerow(["audio", "text", "output"])
        for i, text in enumerate(sentences):
            voice = order[i % len(order)]
            utt = synthesize(text, voice)
            write_wav(utt.audio, utt.sample_rate, folder / f"line{i:02d}.wav")
            total += utt.duration
            out.writerow([f"line{i:02d}.wav", text, f"line{i:02d}.usdc"])
            print(f"  line{i:02d}.wav  {utt.duration:4.1f} s  {voice.name:28s} {text}", flush=True)
    return total


def run_batch(folder: Path, jobs: int, formats: str, tree: Path = REPO) -> float:
    """Wall seconds of one `facegen batch` of `tree`'s code into an empty folder (a new process: everything
    included); the outputs are deleted afterwards."""
    out = folder / "out"
    shutil.rmtree(out, ignore_errors=True)
    cmd = [sys.executable, "-m", "facegen", "batch", str(folder / "lines.csv"), "-o", str(out), "--jobs",
           str(jobs),
           "--formats", formats, "-q"]
    env = dict(os.environ, PYTHONPATH=str(tree))
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=tree, check=False)
    seconds = time.perf_counter() - t0
    shutil.rmtree(out, ignore_errors=True)
    shown = "" if tree == REPO else f" ({tree})"
    print(f"  --jobs {jobs}{shown}: {seconds:.1f} s   {proc.stdout.strip()}", flush=True)
    if proc.returncode != 0:
        print(proc.stderr[-2000:], file=sys.stderr)
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clips", type=int, default=20)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--formats", default="usdc")
    parser.add_argument("--runs", type=int, default=1)
    parser.add_argument("--compare", type=int, default=None, help="also run --jobs N (e.g. 1) side by side")
    parser.add_argument("--before", type=Path, help="also run this source tree's facegen batch side by side")
    parser.add_argument("--keep", help="a folder to keep the clips and outputs in (default: a temporary one)")
    args = parser.parse_args()

    folder = Path(args.keep or tempfile.mkdtemp(prefix="facegen-bench-batch-"))
    folder.mkdir(parents=True, exist_ok=True)
    try:
        print(f"making {args.clips} clips in {folder}", flush=True)
        audio = make_clips(folder, args.clips)
        print(f"{audio:.1f} s of speech; load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores",
              flush=True)
        configs = [(args.jobs, REPO)] + ([(args.compare, REPO)] if args.compare else [])
        configs += [(args.jobs, args.before.resolve())] if args.before else []
        times: dict[tuple[int, Path], list[float]] = {c: [] for c in configs}
        for _ in range(args.runs):
            for jobs, tree in configs:
                times[jobs, tree].append(run_batch(folder, jobs, args.formats, tree))
        for (jobs, tree), runs in times.items():
            med = statistics.median(runs)
            shown = "" if tree == REPO else f" ({tree})"
            print(f"--jobs {jobs}{shown}: median {med:.1f} s over {len(runs)} run(s) = {audio / med:.1f}x "
                  f"real time (target >= 15x on 2 cores)")
        for other in configs[1:]:
            ratio = statistics.median(times[other]) / statistics.median(times[configs[0]])
            print(f"--jobs {args.jobs} is {ratio:.2f}x faster than --jobs {other[0]}"
                  + ("" if other[1] == REPO else f" of {other[1]}"))
        print(f"load average after: {os.getloadavg()[0]:.2f}")
    finally:
        if not args.keep:
            shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
