"""Benchmark: `facegen animate clip.wav --text-file clip.txt -o out.usdc` on a 5 s clip, as a new process.

Target (2 CPU cores, idle): <= 2.5 s wall. Runs the command N times in new processes with FACEGEN_PROFILE=1
and prints the median / min / max wall time and the median of each stage (start-up = process start to
`animate()`: Python, click, numpy, and torch where it is imported at start; the profile's stages; exit = from
the profile's report at exit to the parent seeing the process end: the interpreter's teardown, if any; other =
the rest). With `--before TREE` (e.g. a git worktree of main) the same command runs from that source tree too,
the two in turn (A B A B ...), and each pair's ratio is printed: on a shared machine, quote ratios and
medians.

    python benchmarks/bench_start.py [--runs 5] [--before /path/to/main] [--seconds 5]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from run import make_clip  # benchmarks/run.py (this folder is on sys.path when run as a script)

REPO = Path(__file__).resolve().parents[1]


def run_once(tree: Path, wav: Path, txt: Path, out: Path) -> dict:
    """One `python -m facegen animate` from the source tree `tree`: wall seconds and its stages."""
    env = {**os.environ, "PYTHONPATH": str(tree), "FACEGEN_PROFILE": "1", "HF_HUB_OFFLINE": "1"}
    start = time.time()
    proc = subprocess.run([sys.executable, "-m", "facegen", "animate", str(wav), "--text-file", str(txt),
                           "-o", str(out)], capture_output=True, text=True, env=env, cwd=tree, timeout=600,
                          check=False)  # cwd: with -m, the current folder comes first on sys.path
    wall = time.time() - start
    if proc.returncode != 0:
        raise SystemExit(f"facegen animate failed ({proc.returncode}) from {tree}:\n{proc.stderr[-2000:]}")
    profile = next(json.loads(line) for line in reversed(proc.stderr.splitlines())
                   if line.startswith('{"facegen_profile"'))
    stages = {"start-up": profile["marks"]["animate_start"] - start, **profile["facegen_profile"]}
    stages["exit"] = start + wall - profile["exit"]
    # those overlap
    stages["other"] = wall - sum(v for k, v in stages.items() if not k.endswith("_in_parallel"))
    said = [line for line in proc.stderr.splitlines() if not line.startswith("{")]
    # 430 MB a minute of points: left behind, the dirty pages of a dozen runs make the kernel throttle the
    # later runs' writing
    for written in {out, out.with_suffix(".wav")} - {wav}:
        written.unlink(missing_ok=True)
    return {"wall": wall, "stages": stages, "heavy": profile.get("heavy_modules", []), "said": said}


def summary(name: str, runs: list[dict]) -> list[str]:
    walls = [r["wall"] for r in runs]
    head = f"{name}: wall median {statistics.median(walls):.2f} s, min {min(walls):.2f}, max {max(walls):.2f}"
    lines = [f"{head} ({len(runs)} runs)"]
    names = list(dict.fromkeys(k for r in runs for k in r["stages"]))
    lines.append("  stages (median s): " + ", ".join(
        f"{k} {statistics.median(r['stages'].get(k, 0.0) for r in runs):.3f}" for k in names))
    lines.append(f"  heavy modules imported: {', '.join(runs[0]['heavy']) or 'none'}")
    lines.append(f"  stderr besides the profile: {' | '.join(runs[0]['said']) or 'nothing'}")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5, help="counted runs per tree (after one warm-up each)")
    parser.add_argument("--before", type=Path, help="another source tree to run side by side (e.g. main)")
    parser.add_argument("--seconds", type=float, default=5.0, help="length of the synthesised clip")
    args = parser.parse_args(argv)

    trees = {"this tree": REPO} | ({"before": args.before.resolve()} if args.before else {})
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="facegen-bench-start-") as tmp:
        wav, txt, seconds = make_clip(Path(tmp), args.seconds, "clip")
        for name, tree in trees.items():  # warm-up: the page cache, numba's and Python's bytecode caches
            run_once(tree, wav, txt, Path(tmp) / f"warm-{name.replace(' ', '_')}.usdc")
        results: dict[str, list[dict]] = {name: [] for name in trees}
        for i in range(args.runs):
            for name, tree in trees.items():
                results[name].append(run_once(tree, wav, txt,
                                              Path(tmp) / f"out{i}-{name.replace(' ', '_')}.usdc"))
    load_after = os.getloadavg()

    print(f"facegen animate, {seconds:.2f} s clip -> .usdc, new processes; {os.cpu_count()} CPUs, load "
          f"average {load_before[0]:.2f} before, {load_after[0]:.2f} after (busy when above ~0.5)")
    for name, runs in results.items():
        print("\n".join(summary(f"{name} ({trees[name]})", runs)))
    if args.before:
        ratios = [b["wall"] / a["wall"] for a, b in zip(results["this tree"], results["before"], strict=True)]
        print(f"before / this tree, pair by pair: median {statistics.median(ratios):.2f}x, "
              f"min {min(ratios):.2f}x, max {max(ratios):.2f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
