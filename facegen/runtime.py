"""What every stage shares at run time: the message callback type, progress bars, the torch device, stage
profiles, signals; thread counts (`threads`) and the cache folder (`cache_dir`). The processes facegen starts
(worker pools, external programs) are facegen.processes'.

FACEGEN_PROFILE=1 prints each stage's seconds (and the process's peak memory) as JSON on stderr when the
process exits; stages are timed with `with PROFILE.stage("name"):`. Progress bars (`progress_bar`, the one
home of tqdm) draw only on a terminal: in a log they are one summary line at most.
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Self

from facegen.errors import FacegenError

DEVICES = ("auto", "cpu", "cuda")

Say = Callable[[str], None]  # where progress and notes go: print, a list's append, a progress bar


def silent(_: str) -> None:
    """A Say that says nothing."""


# --------------------------------------------------------------------------------------------------
# profiling: FACEGEN_PROFILE=1 prints each stage's seconds as JSON on stderr when the process exits


class _Profile:
    """Stage timings of this process, enabled by the FACEGEN_PROFILE environment variable."""

    def __init__(self) -> None:
        self.enabled = os.environ.get("FACEGEN_PROFILE", "") not in ("", "0")
        self.stages: dict[str, float] = {}
        self.marks: dict[str, float] = {}
        self._registered = False

    def mark(self, name: str) -> None:
        """Record the wall-clock time (time.time()) of an event, e.g. "animate_start"."""
        if self.enabled:
            self.marks[name] = time.time()
            self._register()

    def add(self, name: str, seconds: float) -> None:
        if self.enabled:
            self.stages[name] = self.stages.get(name, 0.0) + seconds
            self._register()

    def stage(self, name: str):
        return _Stage(self, name)

    def _register(self) -> None:
        if not self._registered:
            import atexit

            atexit.register(self.report)
            self._registered = True

    def report(self) -> None:
        end = time.time()
        stages = dict(self.stages)
        if "animate_end" in self.marks:  # the CLI writes the asset after animate() returns
            stages["writing"] = end - self.marks["animate_end"]
        payload = {"facegen_profile": {k: round(v, 4) for k, v in stages.items()},
                   "marks": self.marks, "exit": end,
                   "heavy_modules": sorted(m for m in HEAVY_MODULES if m in sys.modules)}
        peak = peak_rss_mb()
        if peak is not None:
            payload["max_rss_mb"] = round(peak, 1)
        sys.stderr.write(json.dumps(payload) + "\n")
        sys.stderr.flush()


class _Stage:
    def __init__(self, profile: _Profile, name: str) -> None:
        self.profile, self.name = profile, name

    def __enter__(self) -> None:
        self.start = time.perf_counter()

    def __exit__(self, *exc) -> None:
        self.profile.add(self.name, time.perf_counter() - self.start)


PROFILE = _Profile()
HEAVY_MODULES = ("librosa", "numba", "transformers", "pxr", "scipy", "matplotlib", "trimesh")


def peak_rss_mb() -> float | None:
    """This process's peak resident memory in MB: VmHWM on Linux (its own, unlike ru_maxrss, which keeps
    the parent's peak across fork + exec), else ru_maxrss; None where neither exists."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    try:
        import resource
    except ImportError:  # Windows
        return None
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2**20 if sys.platform == "darwin" else peak / 1024  # bytes on macOS, KiB elsewhere


def release_memory() -> None:
    """Hand the C heap's free pages back to the system (glibc's malloc_trim). Arrays above glibc's mmap
    threshold go back when freed, but the many blocks of a long clip's features and network pieces (2-30 MB
    each, which that threshold grows to take from the heap) leave free pages the heap keeps: about 300 MB
    after the network of a 2-hour clip. Nothing where the C library has no malloc_trim (macOS, musl)."""
    try:
        import ctypes

        ctypes.CDLL(None).malloc_trim(0)
    except (OSError, AttributeError):
        pass


def cores() -> int:
    """The CPU cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # macOS, Windows
        return os.cpu_count() or 1


def select_device(device: str = "auto"):
    """The torch device for `device`: "cpu", "cuda" (or "cuda:N") or "auto" (cuda when torch sees a GPU).

    "auto" without a GPU quietly runs on the CPU (the normal case); an explicit "cuda" without one is a
    FacegenError (the CLI exits 2). The first call imports torch (about a second): profiled as "torch_import".
    """
    with PROFILE.stage("torch_import"):
        import torch

    name = str(device).strip().lower()
    if name not in DEVICES and not name.startswith("cuda:"):
        raise FacegenError(f"unknown device {device!r}: choose auto, cpu or cuda", param="device")
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name.startswith("cuda") and not torch.cuda.is_available():
        raise FacegenError(f"device {name} was asked for but torch sees no CUDA GPU: use cpu or auto",
                           param="device")
    return torch.device(name)


def inference_device(device: str = "auto"):
    """Where inference runs: "cpu" (facegen.numpy_network: torch is not imported) or a CUDA torch.device.

    "auto" is the CPU without asking torch when no NVIDIA driver is loaded (Linux: no /proc/driver/nvidia;
    macOS has no CUDA), else a CUDA GPU when torch sees one; "cuda" without a GPU is select_device's error."""
    name = str(device).strip().lower()
    if name == "cpu" or (name == "auto" and not _gpu_possible()):
        return "cpu"
    chosen = select_device(name)
    return "cpu" if chosen.type == "cpu" else chosen


def _gpu_possible() -> bool:
    """Whether a CUDA GPU may be present, known without importing torch."""
    if sys.platform == "darwin":
        return False
    if sys.platform.startswith("linux"):
        return Path("/proc/driver/nvidia").exists()
    return True


# --------------------------------------------------------------------------------------------------
# progress bars: tqdm on a terminal, one summary line in a log


def stderr_is_terminal() -> bool:
    """Whether stderr is an interactive terminal (False for pipes, files, CI logs, closed streams)."""
    try:
        return sys.stderr is not None and sys.stderr.isatty()
    except (AttributeError, ValueError):  # replaced by an object without isatty, or closed
        return False


def progress_bar(iterable: Iterable | None = None, *, total: int | None = None, desc: str, unit: str = "it",
                 enabled: bool = True, leave: bool = True):
    """The one progress bar of facegen, on stderr: iterate it, or `update(n)` it and `close()` it (or use it
    as a context manager); `set_postfix(**values)` shows running figures.

    On a terminal it is a tqdm bar. Anywhere else (a pipe, a file, a CI log) nothing is drawn: a bar with
    `leave=True` writes one line when it closes ("facegen: import: 20 seq in 3.1 s"), one with
    `leave=False` (its command reports the result itself) writes nothing. `enabled=False` (--quiet): nothing.
    """
    if enabled and stderr_is_terminal():
        from tqdm import tqdm

        return tqdm(iterable, total=total, desc=desc, unit=unit, leave=leave, file=sys.stderr,
                    dynamic_ncols=True)
    return _LogProgress(iterable, desc, unit, say_stderr if enabled and leave else silent)


class _LogProgress:
    """The progress bar's stand-in off a terminal: counts, and says one summary line when closed."""

    def __init__(self, iterable, desc: str, unit: str, say: Say) -> None:
        self.iterable, self.desc, self.unit, self.say = iterable, desc, unit, say
        self.n, self.postfix, self.start, self.closed = 0, "", time.perf_counter(), False

    def __iter__(self):
        try:
            for item in self.iterable:
                yield item
                self.n += 1
        finally:
            self.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def update(self, n: int = 1) -> None:
        self.n += n

    def set_postfix(self, **values) -> None:
        self.postfix = ", ".join(f"{k}={v}" for k, v in values.items())

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            extra = f", {self.postfix}" if self.postfix else ""
            self.say(f"{self.desc}: {self.n} {self.unit} in {time.perf_counter() - self.start:.1f} s{extra}")


def say_stderr(message: str) -> None:
    """The default Say for progress: "facegen: message" on stderr."""
    print(f"facegen: {message}", file=sys.stderr)


def warn_stderr(message: str) -> None:
    """The default Say for warnings: one line on stderr."""
    print(f"facegen: warning: {message}", file=sys.stderr)


@dataclass(frozen=True)
class Reporter:
    """Where a run tells its user what it does — the one type every reporting library function takes (no
    quiet flags, progress booleans or loose callbacks): `progress` for stage messages (silenced by --quiet),
    `note` for what the user should always see (a warning, a skipped item), `bars` whether bars are drawn."""

    progress: Say = silent
    note: Say = silent
    bars: bool = False

    @classmethod
    def stderr(cls, quiet: bool = False) -> Reporter:
        """The command line's: "facegen: ..." progress lines and bars on stderr unless `quiet`; notes
        always."""
        return cls(silent if quiet else say_stderr, warn_stderr, not quiet)

    def bar(self, iterable: Iterable | None = None, *, total: int | None = None, desc: str, unit: str = "it",
            leave: bool = True):
        """A progress bar (runtime.progress_bar) drawn when this reporter draws bars."""
        return progress_bar(iterable, total=total, desc=desc, unit=unit, enabled=self.bars, leave=leave)

    def noting(self, note: Say) -> Reporter:
        """The same reporter with notes going to `note`."""
        return replace(self, note=note)


SILENT = Reporter()  # says nothing: the library's default
NOTES = Reporter(note=warn_stderr)  # notes on stderr, no progress: the default where a note must not be lost
BARS = Reporter(bars=True)  # progress bars only: the default of a long library job (render)
STDERR = Reporter.stderr()  # the command line's without --quiet: the default of train, evaluate and plots


class Terminated(BaseException):
    """SIGTERM or SIGHUP, raised where the process is: it unwinds like Ctrl-C (`except Exception` lets it by),
    so every `atomic_path` removes its temporary file and no partial output remains. Not a KeyboardInterrupt:
    click answers those with a blank line (closing a terminal's ^C), which a signal has not earned.

    Python runs the handler between two bytecodes only, so a stage that stays in C for long (a search over a
    whole clip, a torch op over its frames) would keep it waiting: long clips are processed in pieces and
    blocks that come back to Python every fraction of a second (tests/test_long_audio.py)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


def stop_on_signals() -> None:
    """Turn SIGTERM and SIGHUP into Terminated (Python already turns SIGINT into KeyboardInterrupt)."""
    import signal

    def raise_terminated(signum, _frame):
        raise Terminated(signum)

    for name in ("SIGTERM", "SIGHUP"):
        if hasattr(signal, name):
            try:
                signal.signal(getattr(signal, name), raise_terminated)
            except ValueError:  # not the main thread (facegen.cli.main called from a thread): the default
                return


# --------------------------------------------------------------------------------------------------
# threads: how many each compute pool of this process may use

THREAD_POOLS = ("torch", "blas", "openmp", "usd")  # threads(n)'s default: the pools loaded in this process
THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")  # the "env" pool


def set_threads(n: int, pools: Iterable[str] = THREAD_POOLS) -> Callable[[], None]:
    """Limit the named thread pools of this process to `n` threads from now on; returns what undoes it.

    "torch": torch's intra-op threads; "blas", "openmp": the libraries loaded now (threadpoolctl); "usd":
    pxr.Work; "env": what loads later here or in processes started from here (THREAD_ENV, where the user has
    not set it). torch and pxr are not imported for this. Numba needs nothing: no facegen kernel is parallel.
    """
    pools = tuple(pools)
    unknown = sorted(set(pools) - {*THREAD_POOLS, "env"})
    if unknown:
        raise ValueError(f"unknown thread pools {unknown}: choose from {(*THREAD_POOLS, 'env')}")
    n = max(1, int(n))
    undo: list[Callable[[], object]] = []
    if "torch" in pools and "torch" in sys.modules:
        torch = sys.modules["torch"]
        torch_before = torch.get_num_threads()
        if torch_before != n:
            torch.set_num_threads(n)
        undo.append(lambda: torch.get_num_threads() != torch_before and torch.set_num_threads(torch_before))
    apis = [api for api in ("blas", "openmp") if api in pools]
    if apis:
        from threadpoolctl import threadpool_limits

        limits = threadpool_limits(n, user_api=apis[0] if len(apis) == 1 else None)
        undo.append(limits.restore_original_limits)
    if "usd" in pools and "pxr" in sys.modules:
        from pxr import Work

        usd_before = Work.GetConcurrencyLimit()
        Work.SetConcurrencyLimit(n)
        undo.append(lambda: Work.SetConcurrencyLimit(usd_before))
    if "env" in pools:
        added = [name for name in THREAD_ENV if name not in os.environ]
        os.environ.update(dict.fromkeys(added, str(n)))
        undo.append(lambda: [os.environ.pop(name, None) for name in added])

    def restore() -> None:
        for step in reversed(undo):
            step()

    return restore


@contextlib.contextmanager
def threads(n: int | None, pools: Iterable[str] = THREAD_POOLS) -> Iterator[None]:
    """At most `n` threads in the named pools (see set_threads) inside the block, as before after it;
    `n` None changes nothing. The one place facegen sets thread counts."""
    restore = set_threads(n, pools) if n else None
    try:
        yield
    finally:
        if restore is not None:
            restore()


# --------------------------------------------------------------------------------------------------
# the cache folder


def cache_dir(*parts: str) -> Path:
    """facegen's cache folder, $XDG_CACHE_HOME/facegen (~/.cache/facegen), or its sub-folder `parts`."""
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base.joinpath("facegen", *parts)
