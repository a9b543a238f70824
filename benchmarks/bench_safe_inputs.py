"""Benchmark: hostile inputs refused in bounded time and memory, and no process left behind (issue 22).

Targets: a templates.pkl memory bomb (a few dozen bytes naming a 1e9-element array) refused in < 1 s with
< 300 MB peak; every special-file case (a FIFO without a writer, /dev/zero, /dev/urandom as a transcript,
an alignment file, a manifest, a manifest row's transcript, alignment or audio) one line in < 2 s and
< 300 MB; a SIGKILL of `facegen batch --jobs 2` leaves no process of its family after 5 s.

Every case runs as a new process; its wall time and peak RSS (os.wait4: that process's own) are printed as
a table, each against its target.

    python benchmarks/bench_safe_inputs.py [--no-kill]
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from run import make_clip  # benchmarks/run.py (this folder is on sys.path when run as a script)

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from hostile import BOMBS, REPO, alive, descendants, run_measured  # tests/hostile.py: the tests' cases


def cases(folder: Path, wav: Path, fifo: Path) -> dict[str, tuple[list[str], float]]:
    """{name: (command, wall-time target in s)}."""
    facegen = [sys.executable, "-m", "facegen"]
    found: dict[str, tuple[list[str], float]] = {}
    for name, data in BOMBS.items():
        path = folder / f"bomb{len(found)}.pkl"
        path.write_bytes(data)
        code = ("import sys\nfrom facegen.datasets.templates import read_templates_pkl\n"
                "from facegen.errors import FacegenError\n"
                f"try:\n    read_templates_pkl({str(path)!r})\nexcept FacegenError as exc:\n"
                "    sys.exit(f'facegen: {exc}')")
        found[f"pkl: {name} ({len(data)} B)"] = ([sys.executable, "-c", code], 1.0)
    for special in (str(fifo), "/dev/zero", "/dev/urandom"):
        kind = "FIFO" if special == str(fifo) else special
        found[f"animate --text-file {kind}"] = (
            [*facegen, "animate", str(wav), "--text-file", special, "-o", str(folder / "t.npy")], 2.0)
        found[f"animate --alignment {kind}"] = (
            [*facegen, "animate", str(wav), "--alignment", special, "-o", str(folder / "a.npy")], 2.0)
        found[f"align --text-file {kind}"] = ([*facegen, "align", str(wav), "--text-file", special], 2.0)
        found[f"batch MANIFEST={kind}"] = ([*facegen, "batch", special, "-o", str(folder / "o")], 2.0)
        for column in ("text_file", "alignment", "audio"):
            manifest = folder / f"{column}-{kind.strip('/').replace('/', '-')}.csv"
            if column == "audio":
                manifest.write_text(f"audio,output\n{special},a.npy\n")
            else:
                manifest.write_text(f"audio,{column},output\n{wav},{special},a.npy\n")
            found[f"batch, a row's {column} = {kind}"] = (
                [*facegen, "batch", str(manifest), "-o", str(folder / f"out-{manifest.stem}")], 2.0)
    return found


def kill_batch(folder: Path, wav: Path) -> tuple[int, float, int]:
    """SIGKILL `facegen batch --jobs 2` (default model) while its workers run: (processes it had, seconds
    until the last one ended, processes left after 5 s)."""
    manifest = folder / "many.csv"
    manifest.write_text("audio,output\n" + "".join(f"{wav},{n}.usdc\n" for n in range(200)))
    proc = subprocess.Popen([sys.executable, "-m", "facegen", "batch", str(manifest), "-o", str(folder / "k"),
                             "--jobs", "2", "-q"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            cwd=REPO, env=dict(os.environ, HF_HUB_OFFLINE="1"))
    while sum(len(descendants(c)) for c in descendants(proc.pid)) < 2:
        if proc.poll() is not None:
            raise SystemExit("the batch ended before its workers started")
        time.sleep(0.1)
    time.sleep(2.0)  # at work
    family = descendants(proc.pid)
    proc.send_signal(signal.SIGKILL)
    killed = time.perf_counter()
    proc.wait()
    while any(alive(p, s) for p, s in family.items()) and time.perf_counter() - killed < 5:
        time.sleep(0.05)
    seconds = time.perf_counter() - killed
    left = [p for p, s in family.items() if alive(p, s)]
    for pid in left:
        os.kill(pid, signal.SIGKILL)
    return len(family), seconds, len(left)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--no-kill", action="store_true", help="skip the SIGKILL case (it loads the model)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        wav, _, _ = make_clip(folder, 3.0, "clip")
        fifo = folder / "pipe"
        os.mkfifo(fifo)
        print(f"{'case':52} {'exit':>4} {'lines':>5} {'wall s':>7} {'peak MB':>8}  target")
        for name, (command, target) in cases(folder, wav, fifo).items():
            code, err, wall, peak = run_measured(command)
            ok = wall < target and peak < 300 and code in (1, 2) and len(err.strip().splitlines()) <= 1
            print(f"{name:52} {code:>4} {len(err.strip().splitlines()):>5} {wall:>7.2f} {peak:>8.0f}  "
                  f"< {target:g} s, < 300 MB: {'ok' if ok else 'MISSED'}", flush=True)
        if not args.no_kill:
            n, seconds, left = kill_batch(folder, wav)
            print(f"SIGKILL of batch --jobs 2: {n} processes, the last gone {seconds:.2f} s after, {left} "
                  f"left after 5 s: {'ok' if left == 0 else 'MISSED'}")


if __name__ == "__main__":
    main()
