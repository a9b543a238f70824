"""Hostile inputs and what they leave behind, shared by tests/test_safe_inputs.py and
benchmarks/bench_safe_inputs.py: templates.pkl memory bombs, a command's peak memory measured as a new
process, and a process's family read from /proc."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

BOMBS = {  # pickles of a few dozen bytes whose arrays would take gigabytes
    "numpy.ndarray((1e9,), 'f4')": b"\x80\x02}X\x02\x00\x00\x00F1cnumpy\nndarray\nJ\x00\xca\x9a;\x85X\x02"
                                   b"\x00\x00\x00f4\x86Rs.",
    "_reconstruct, shape 1e9": b"\x80\x02}X\x02\x00\x00\x00F1cnumpy._core.multiarray\n_reconstruct\ncnumpy\n"
                               b"ndarray\nJ\x00\xca\x9a;\x85X\x01\x00\x00\x00b\x87Rs.",
    "array state, shape 1e9": b"\x80\x03}X\x02\x00\x00\x00F1cnumpy._core.multiarray\n_reconstruct\ncnumpy\n"
                              b"ndarray\nK\x00\x85C\x01b\x87R(K\x01J\x00\xca\x9a;\x85cnumpy\ndtype\nX\x02\x00"
                              b"\x00\x00f4\x89\x88\x87R\x89C\x00tbs.",
    "object array state, shape 1e9": b"\x80\x03}X\x02\x00\x00\x00F1cnumpy._core.multiarray\n_reconstruct\n"
                                     b"cnumpy\nndarray\nK\x00\x85C\x01b\x87R(K\x01J\x00\xca\x9a;\x85cnumpy\n"
                                     b"dtype\nX\x02\x00\x00\x00O8\x89\x88\x87R\x89]tbs.",
    "_frombuffer, shape 1e9": b"\x80\x03}X\x02\x00\x00\x00F1cnumpy._core.numeric\n_frombuffer\n(C\x00cnumpy\n"
                              b"dtype\nX\x02\x00\x00\x00f4\x89\x88\x87RJ\x00\xca\x9a;\x85X\x01\x00\x00\x00C"
                              b"tRs.",
    "memo index 2^28": b"\x80\x02Nr\xf0\xff\xff\x0f.",  # the C unpickler's memo table: 4.3 GB, zeroed
}
REFUSALS = {  # what the refusal of each says
    "numpy.ndarray((1e9,), 'f4')": "calls numpy.ndarray directly",
    "_reconstruct, shape 1e9": "out of nothing",
    "array state, shape 1e9": "more than the file holds",
    "object array state, shape 1e9": "makes a dtype of 'O8'",
    "_frombuffer, shape 1e9": "more than the file holds",
    "memo index 2^28": "holds a NoneType",
}

# runs a command and prints its peak RSS (os.wait4: that process's own), as a child of a process small enough
# that the command's fork does not count the caller's memory (Linux keeps the peak across exec)
_MEASURE = """
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


def run_measured(args: list[str], timeout: float = 120.0) -> tuple[int, str, float, float]:
    """`args` as a new process, killed after `timeout` s: (exit code, stderr, wall s, peak RSS in MB)."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", _MEASURE, str(timeout), *args], capture_output=True,
                          text=True, cwd=REPO, env=dict(os.environ, HF_HUB_OFFLINE="1"), timeout=timeout + 60,
                          check=False)
    return done.returncode, done.stderr, time.perf_counter() - start, float(done.stdout)


def descendants(pid: int) -> dict[int, str]:
    """{pid: its start time} of every live descendant of `pid` (/proc)."""
    children: dict[int, list[int]] = {}
    started: dict[int, str] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()  # state, parent, ... start time (20th)
        except (OSError, IndexError):  # gone meanwhile
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
    """Whether process `pid`, started at `start` (not a new one with its id), still runs."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return False
    return fields[0] not in "ZX" and fields[19] == start
