"""Every process facegen starts, started one way: worker pools (`process_pool`: forkserver or spawn, public
multiprocessing APIs only), the forked aligner (`start_process`), and external programs (`run_tool`,
`start_tool`: ffmpeg from imageio-ffmpeg, node, flite, festival; a missing one is a FacegenError saying what
to install). Thread counts are facegen.runtime's `threads`.
"""

from __future__ import annotations

import functools
import os
import sys
from collections.abc import Callable, Sequence
from typing import Self

from facegen.errors import FacegenError

# --------------------------------------------------------------------------------------------------
# processes: the one way facegen starts worker processes


def start_process(target: Callable, args: tuple = (), *, start: str = "fork", name: str | None = None):
    """A started daemon multiprocessing.Process running target(*args) (the forked alignment started ahead),
    or None where `start` is not available; its pipe: multiprocessing.Pipe. It ends when this process ends,
    even by SIGKILL (`end_with`)."""
    import multiprocessing

    if start not in multiprocessing.get_all_start_methods():
        return None
    process = multiprocessing.get_context(start).Process(target=_owned, args=(lifeline(), target, args),
                                                         daemon=True, name=name)
    process.start()
    return process


def _owned(line, target: Callable, args: tuple) -> None:
    reader, writer = line
    writer.close()  # a forked child's copy: only its parent may hold the write end
    end_with(reader)
    target(*args)


_lifelines: dict[int, tuple] = {}  # process id -> its lifeline (reader, writer)
_held = []  # the lifeline this process ends with, open as long as it runs


def lifeline() -> tuple:
    """This process's lifeline, (reader, writer) of a pipe (multiprocessing.Pipe) whose write end only this
    process holds, open as long as it runs: a process given the reader ends with this one (`end_with`)."""
    import multiprocessing

    if os.getpid() not in _lifelines:
        _lifelines[os.getpid()] = multiprocessing.Pipe(duplex=False)
    return _lifelines[os.getpid()]


def end_with(reader) -> None:
    """End this process when the write end of the lifeline `reader` closes, i.e. when the process that made
    it ends, however it ends (SIGKILL too). Without this, a pool's workers outlive a killed parent, waiting
    for work for ever (each holds both ends of its task queue), and a forkserver lives as long as its workers.

    On Linux the kernel sends this process SIGKILL at that moment: the pipe, opened again through /proc (a
    passed fd shares its signal owner with every other process given it), is O_ASYNC with SIGKILL as its
    signal; it needs no thread, no lock, no time slice of its own. Its writes in progress leave their marked
    temporaries, which the next write into that folder removes (atomic.remove_stale_temporaries). Elsewhere a
    daemon thread waits for the pipe's end and sends SIGTERM (the handler unwinds the atomic writes), then
    SIGKILL."""
    import signal

    _held.append(reader)
    try:
        import fcntl
    except ImportError:  # Windows
        fcntl = None
    own = f"/proc/self/fd/{reader.fileno()}"
    if fcntl is not None and hasattr(fcntl, "F_SETSIG") and os.path.exists(own):
        import select

        fd = os.open(own, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
        _held.append(fd)
        fcntl.fcntl(fd, fcntl.F_SETOWN, os.getpid())
        fcntl.fcntl(fd, fcntl.F_SETSIG, signal.SIGKILL)
        fcntl.fcntl(fd, fcntl.F_SETFL, fcntl.fcntl(fd, fcntl.F_GETFL) | os.O_ASYNC)
        if select.select([fd], [], [], 0)[0]:  # nothing is ever written: readable is closed, before the above
            os.kill(os.getpid(), signal.SIGKILL)
        return
    import threading

    threading.Thread(target=_await_end, args=(reader,), daemon=True, name="facegen-end-with").start()


def _await_end(reader, grace: float = 2.0) -> None:
    import signal
    import time

    try:
        reader.recv_bytes()
    except (EOFError, OSError):
        pass
    os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(grace)
    os.kill(os.getpid(), getattr(signal, "SIGKILL", signal.SIGTERM))


class ProcessPool:
    """Worker processes behind a concurrent.futures executor (`submit`), made by process_pool.

    `stop()` ends the workers now; `close()` waits for the work and ends a forkserver pool's server: left
    alone, it would exit with this process through the teardown of what it preloaded (torch, USD: 0.5-0.8 s
    while whoever reads our output pipes waits); killed, it holds nothing, and the next pool starts a new
    one. Public APIs only: processes are recorded as made; the server's id is the workers' parent's."""

    def __init__(self, workers: int, start: str, initializer: Callable | None, initargs: tuple,
                 preload: Sequence[str], max_tasks_per_child: int | None) -> None:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        if start == "forkserver" and not sys.platform.startswith("linux"):
            start = "spawn"  # macOS, Windows: spawn, as their Python does by default
        context = multiprocessing.get_context(start)
        if start == "forkserver":  # the server exits at once when its last worker has (forkserver_exit)
            context.set_forkserver_preload([*preload, "facegen.forkserver_exit"])
        self.start = start
        self._context = _Recording(context)
        self._server = context.RawValue("i", 0) if start == "forkserver" else None
        self.executor = ProcessPoolExecutor(max_workers=workers, mp_context=self._context,
                                            initializer=_start_worker,
                                            initargs=(self._server, lifeline()[0], initializer, initargs),
                                            max_tasks_per_child=max_tasks_per_child)

    def submit(self, fn: Callable, /, *args, **kwargs):
        return self.executor.submit(fn, *args, **kwargs)

    def stop(self, grace: float = 5.0) -> None:
        """SIGTERM the workers (each unwinds its atomic writes), SIGKILL those alive after `grace` s."""
        processes = list(self._context.processes)
        for process in processes:
            if process.is_alive():
                process.terminate()
        for process in processes:
            process.join(grace)
            if process.is_alive():
                process.kill()

    def close(self) -> None:
        """Wait for the running work (cancelling what has not started), then end the forkserver."""
        self.executor.shutdown(wait=True, cancel_futures=True)
        if self._server is not None and self._server.value > 0:
            _end_child(self._server.value)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def process_pool(workers: int, *, start: str = "spawn", initializer: Callable | None = None,
                 initargs: tuple = (), preload: Sequence[str] = (),
                 max_tasks_per_child: int | None = None) -> ProcessPool:
    """The one process-pool factory of facegen: `workers` processes, each running initializer(*initargs)
    first. start="forkserver" (Linux; spawn elsewhere): forked from a server that imported `preload` once
    (torch, USD, the aligner's decoders); "spawn": fresh interpreters (`max_tasks_per_child=1`: a fresh
    one per task, for state no library resets, such as libespeak-ng's). The workers end when this process
    ends, even by SIGKILL (`end_with`); a forkserver ends with its last worker."""
    if start not in ("forkserver", "spawn"):
        raise ValueError(f"unknown start method {start!r} for a process pool: forkserver or spawn")
    return ProcessPool(workers, start, initializer, initargs, preload, max_tasks_per_child)


class _Recording:
    """A multiprocessing context that records the processes made through it (ProcessPool.stop's list)."""

    def __init__(self, context) -> None:
        self._context, self.processes = context, []

    def __getattr__(self, name: str):
        return getattr(self._context, name)

    def Process(self, *args, **kwargs):
        process = self._context.Process(*args, **kwargs)
        self.processes.append(process)
        return process


def _start_worker(server, reader, initializer: Callable | None, initargs: tuple) -> None:
    """In a new pool worker: end with the pool's owner (`end_with` its lifeline's `reader`), note the
    forkserver's id (this worker's parent), then run the initializer."""
    end_with(reader)
    if server is not None:
        server.value = os.getppid()
    if initializer is not None:
        initializer(*initargs)


def _end_child(pid: int) -> None:
    """Kill our child `pid` (a forkserver) and wait until it is dead, unreaped: multiprocessing reaps it
    when it next needs a server. Not our child: nothing."""
    import signal

    if not hasattr(os, "waitid"):
        return
    try:
        if os.waitid(os.P_PID, pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is not None:
            return  # dead already
        os.kill(pid, signal.SIGKILL)
        os.waitid(os.P_PID, pid, os.WEXITED | os.WNOWAIT)
    except OSError:  # ChildProcessError: not our child
        pass


# --------------------------------------------------------------------------------------------------
# external programs: ffmpeg (shipped by imageio-ffmpeg), node, flite, festival

TOOLS = {  # what to do when a program is missing (a caller may say more precisely: run_tool's `install`)
    "ffmpeg": "reinstall imageio-ffmpeg (pip install --force-reinstall imageio-ffmpeg), which ships it",
    "node": "install Node.js >= 18",
    "flite": "run `apt-get install flite` as root, or `make voices`",
    "festival": "run `apt-get install festival` as root, or `make voices`",
}


def tool_path(name: str, install: str | None = None) -> str:
    """The executable of the external program `name` (a key of TOOLS), looked up once per PATH; a
    FacegenError saying what to install when it is missing. ffmpeg is the binary imageio-ffmpeg ships."""
    return _locate(name, os.environ.get("PATH", ""), install or TOOLS[name])


@functools.lru_cache(maxsize=16)
def _locate(name: str, _path: str, install: str) -> str:
    if name == "ffmpeg":
        import imageio_ffmpeg

        try:
            return imageio_ffmpeg.get_ffmpeg_exe()
        except RuntimeError as exc:  # no binary for this platform
            raise FacegenError(f"no ffmpeg binary found ({exc}): {install}") from exc
    import shutil

    found = shutil.which(name)
    if found is None:
        raise FacegenError(f"{name} is not installed (no `{name}` on PATH): {install}")
    return found


def run_tool(name: str, args: Sequence[str | os.PathLike], *, input: bytes | str | None = None,
             text: bool = False, timeout: float | None = None, cwd: str | os.PathLike | None = None,
             install: str | None = None):
    """Run the external program `name` to its end: its CompletedProcess (output captured, stdin `input`,
    the exit code the caller's to judge). Missing or not startable: a FacegenError saying what to install;
    a timeout: subprocess.TimeoutExpired."""
    import subprocess

    command = [tool_path(name, install), *map(str, args)]
    stdin = subprocess.DEVNULL if input is None else None
    try:
        return subprocess.run(command, input=input, stdin=stdin, capture_output=True, text=text,
                              errors="replace" if text else None, timeout=timeout, cwd=cwd, check=False)
    except OSError as exc:
        raise FacegenError(f"cannot run {name} ({exc}): {install or TOOLS[name]}") from exc


def start_tool(name: str, args: Sequence[str | os.PathLike], **popen):
    """The external program `name` started (subprocess.Popen(..., **popen)), for a caller streaming to it."""
    import subprocess

    command = [tool_path(name), *map(str, args)]
    try:
        return subprocess.Popen(command, **popen)
    except OSError as exc:
        raise FacegenError(f"cannot run {name} ({exc}): {TOOLS[name]}") from exc
