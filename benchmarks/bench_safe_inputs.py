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

REPO = Path(__file__).resolve().parents[1]
BOMBS = {  # as tests/test_safe_inputs.py
    "pkl: numpy.ndarray((1e9,), 'f4')": b"\x80\x02}X\x02\x00\x00\x00F1cnumpy\nndarray\nJ\x00\xca\x9a;\x85X"
                                        b"\x02\x00\x00\x00f4\x86Rs.",
    "pkl: _reconstruct, shape 1e9": b"\x80\x02}X\x02\x00\x00\x00F1cnumpy._core.multiarray\n_reconstruct\n"
                                    b"cnumpy\nndarray\nJ\x00\xca\x9a;\x85X\x01\x00\x00\x00b\x87Rs.",
    "pkl: array state, shape 1e9": b"\x80\x03}X\x02\x00\x00\x00F1cnumpy._core.multiarray\n_reconstruct\n"
                                   b"cnumpy\nndarray\nK\x00\x85C\x01b\x87R(K\x01J\x00\xca\x9a;\x85cnumpy\ndtype\n"
                                   b"X\x02\x00\x00\x00f4\x89\x88\x87R\x89C\x00tbs.",
    "pkl: _frombuffer, shape 1e9": b"\x80\x03}X\x02\x00\x00\x00F1cnumpy._core.numeric\n_frombuffer\n(C\x00"
                                   b"cnumpy\ndtype\nX\x02\x00\x00\x00f4\x89\x88\x87RJ\x00\xca\x9a;\x85X\x01\x00"
                                   b"\x00\x00CtRs.",
    "pkl: memo index 2^28": b"\x80\x02Nr\xf0\xff\xff\x0f.",
}


# the command as a child of a small process (its fork does not count this one's memory), its own peak RSS
MEASURE = """
import os, subprocess, sys, time
proc = subprocess.Popen(sys.argv[2:], stdout=subprocess.DEVNULL)
end = time.monotonic() + float(sys.argv[1])
while not (done := os.wait4(proc.pid, os.WNOHANG))[0]:
    if time.monotonic() > end:
        proc.kill()
    time.sleep(0.01)
print(done[2].ru_maxrss / 1024)
sys.exit(os.waitstatus_to_exitcode(done[1]) % 256)
"""


def run(args: list[str], timeout: float = 120.0) -> tuple[int, str, float, float]:
    """(exit code, stderr, wall s, peak RSS MB) of `args` as a new process, killed after `timeout` s."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", MEASURE, str(timeout), *args], capture_output=True,
                          text=True, cwd=REPO, env=dict(os.environ, HF_HUB_OFFLINE="1"), timeout=timeout + 60,
                          check=False)
    return done.returncode, done.stderr, time.perf_counter() - start, float(done.stdout)


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
        found[f"{name} ({len(data)} B)"] = ([sys.executable, "-c", code], 1.0)
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


def descendants(pid: int) -> dict[int, str]:
    """{pid: start time} of the live descendants of `pid` (/proc)."""
    children: dict[int, list[int]] = {}
    started: dict[int, str] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        if fields[0] not in "ZX":
            children.setdefault(int(fields[1]), []).append(int(stat.parent.name))
            started[int(stat.parent.name)] = fields[19]
    found, todo = {}, [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            found[child] = started[child]
            todo.append(child)
    return found


def alive(pid: int, start: str) -> bool:
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return False
    return fields[0] not in "ZX" and fields[19] == start


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
            code, err, wall, peak = run(command)
            ok = wall < target and peak < 300 and code in (1, 2) and len(err.strip().splitlines()) <= 1
            print(f"{name:52} {code:>4} {len(err.strip().splitlines()):>5} {wall:>7.2f} {peak:>8.0f}  "
                  f"< {target:g} s, < 300 MB: {'ok' if ok else 'MISSED'}", flush=True)
        if not args.no_kill:
            n, seconds, left = kill_batch(folder, wav)
            print(f"SIGKILL of batch --jobs 2: {n} processes, the last gone {seconds:.2f} s after, {left} "
                  f"left after 5 s: {'ok' if left == 0 else 'MISSED'}")


if __name__ == "__main__":
    main()
