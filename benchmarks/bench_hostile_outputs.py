"""Benchmark: tampered ARKit weight files through `facegen validate` and the Blender helper (issue 22).

Targets: every case of tests/test_hostile_outputs.py (a weight as text, trackPath at /dev/zero, a FIFO, a
number or a 2-hour 48 kHz stereo WAV of 1.4 GB, a CSV timecode 1e400, JSON nested 100,000 deep, 1,000,000
frames, 600 MB; the helper's --fps inf/nan/0/-5, --save into a missing folder or onto a folder) ends as it
must (validate: exit 1 and the FAIL line, or exit 2; the helper: one line, exit 2) in < 2 s with < 300 MB
peak. Then, with no target but to show the memory stays bounded, the largest files facegen reads: 4 hours
at 25 fps (360,000 frames, 5-decimal weights, ~150 MB) validated and read by the helper's reader.

Every case runs as a new process under GNU time (`/usr/bin/time -f "%e %M"`): its wall time and peak RSS
are printed as a table. The 1.4 GB WAV is sparse (its samples are zeros the file system makes up): validate
reads its header and one block of it, so a WAV on a cold disk costs the same.

    python benchmarks/bench_hostile_outputs.py [--no-bound]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_hostile_outputs import BLENDER_PYTHON, FPS, REPO, build_cases, outcome, write_rows

TIME_S, PEAK_MB = 2.0, 300.0
GNU_TIME = "/usr/bin/time"


def measured(command: list[str], folder: Path, timeout: float) -> tuple[subprocess.CompletedProcess, float,
                                                                         float]:
    """`command` run under GNU time: (its result, wall s, peak RSS in MB)."""
    figures = folder / "time.txt"
    done = subprocess.run([GNU_TIME, "-f", "%e %M", "-o", str(figures), *command], capture_output=True,
                          text=True, timeout=timeout, cwd=REPO, check=False)
    seconds, kilobytes = figures.read_text().split()[-2:]
    return done, float(seconds), float(kilobytes) / 1024


def bound_cases(folder: Path) -> list[tuple[str, list[str]]]:
    """The largest file facegen reads, 4 hours at 25 fps, validated and read by the helper's reader."""
    frames = 4 * 3600 * FPS
    row = ",".join(f"{0.1 + 0.01 * (i % 50):.5f}" for i in range(52))
    path = write_rows(folder / "four_hours.json", frames, row=row, head=f'"numFrames": {frames}, ')
    read = ("import sys; sys.path.insert(0, 'facegen/blender'); import facegen_arkit; "
            f"clip = facegen_arkit.read_weights({str(path)!r}); print(clip['weights'].shape)")
    helper = [str(BLENDER_PYTHON) if BLENDER_PYTHON.is_file() else sys.executable, "-c", read]
    return [(f"validate 4 h JSON ({path.stat().st_size / 1e6:.0f} MB)",
             [sys.executable, "-m", "facegen", "validate", str(path), "--no-audio-required"]),
            ("helper reads 4 h JSON", helper)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--no-bound", action="store_true", help="skip the 4-hour files")
    args = parser.parse_args()
    rows, failed = [], 0
    with tempfile.TemporaryDirectory(prefix="facegen_bench_hostile_") as tmp:
        folder = Path(tmp)
        for case in build_cases(folder):
            if case.tool == "blender" and not BLENDER_PYTHON.is_file():
                rows.append((case.name, None, None, "skipped: no .venv-blender"))
                continue
            done, seconds, peak = measured(case.command(), folder, 120)
            wrong = outcome(case, done)
            ok = wrong is None and seconds < TIME_S and peak < PEAK_MB
            failed += not ok
            rows.append((case.name, seconds, peak, "ok" if ok else (wrong or "over target")))
        if not args.no_bound:
            for name, command in bound_cases(folder):
                done, seconds, peak = measured(command, folder, 600)
                said = (done.stdout.strip().splitlines() or [""])[0]
                rows.append((name, seconds, peak, f"exit {done.returncode} (no target): {said[:60]}"
                             + done.stderr[-200:]))
    print(f"{'case':40s} {'wall s':>7s} {'peak MB':>8s}  result (targets: < {TIME_S:g} s, < {PEAK_MB:g} MB)")
    for name, seconds, peak, result in rows:
        figures = f"{seconds:7.2f} {peak:8.0f}" if seconds is not None else f"{'-':>7s} {'-':>8s}"
        print(f"{name:40s} {figures}  {result}")
    print(json.dumps({"cases": len(rows), "off_target": failed}))
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
