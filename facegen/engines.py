"""Where a batch's items run: worker processes on this machine, or Ray tasks on a cluster.

Both engines run the same code on the same chunks of Jobs: a worker loads the model bundle and text model
once (`Worker`), then animates, writes and validates chunk after chunk (`facegen.batch.run_batch`), so the
two give the same files. The local engine is a process pool whose initializer builds the worker (one thread
per pool per core it owns); the Ray engine runs one actor per worker on an existing cluster (`--ray-address`)
or on a local instance it starts, writing to the same output paths (on a cluster: a shared file system
mounted at the same path on every node). Ray is an optional extra: `pip install 'facegen[ray]'`.
"""

from __future__ import annotations

import socket
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, wait
from concurrent.futures.process import BrokenProcessPool

from facegen.align_ahead import align_file
from facegen.batch import Job, JobResult, run_batch
from facegen.errors import FacegenError
from facegen.exchange.formats import USD_LIBRARIES
from facegen.processes import ProcessPool, process_pool
from facegen.runtime import cores, set_threads

ENGINES = ("local", "ray")
# What the local engine's worker processes import before they are forked (once, not in every worker): USD,
# pocketsphinx and the aligner's decoders (worker_preload), the network and the text model's code (numpy:
# torch is imported only by a worker on a CUDA device) and the pipeline around them.
# Nothing here may start threads (USD starts its on first use, not on import).
PRELOAD = [*USD_LIBRARIES, "pocketsphinx", "safetensors.numpy", "tokenizers", "facegen.engines",
           "facegen.animator", "facegen.worker_preload", "facegen.inference", "facegen.numpy_network",
           "facegen.minilm", "facegen.text", "facegen.exchange.usd", "facegen.validate"]
OnResult = Callable[[JobResult], None]


class Worker:
    """An Animator with the model and text model loaded once, and the chunks run with it."""

    def __init__(self, model: str | None, device: str, text_model: str | None, threads: int) -> None:
        limit_threads(threads)
        from facegen.animator import Animator

        self.animator = Animator(model, text_model=text_model, device=device)
        if self.animator.bundle.config.uses_text:
            self.animator.text_backend()  # loaded once for every clip of this process

    def run(self, jobs: Sequence[Job], batch_size: int) -> list[JobResult]:
        return run_batch(jobs, animator=self.animator, batch_size=batch_size)


def limit_threads(threads: int) -> None:
    """At most `threads` threads in each pool this process computes with: the BLAS and OpenMP pools, USD's,
    and torch's if it is imported by then (runtime.set_threads; a worker on the CPU runs the network in numpy
    and never imports torch; one on a CUDA device imports it later and computes on the GPU). With a worker
    per core, a second thread only spins: 20 clips in one process took the same wall time with one thread per
    pool and 21 % less CPU (14.0 -> 11.0 s), which the other worker gets."""
    from pxr import Work  # noqa: F401 - imported now, so that its pool is limited too

    set_threads(threads)


_worker: Worker | None = None  # the local engine's worker of this process (set by the pool's initializer)


def _init_local(model: str | None, device: str, text_model: str | None, threads: int) -> None:
    import signal

    global _worker
    _worker = Worker(model, device, text_model, threads)
    signal.signal(signal.SIGTERM, _exit)  # from ProcessPool.stop: unwind the atomic writes, no traceback


def _exit(signum: int, _frame) -> None:
    raise SystemExit(128 + signum)


def _run_local(jobs: Sequence[Job], batch_size: int) -> list[JobResult]:
    return _worker.run(jobs, batch_size)


def chunks(jobs: Sequence[Job], workers: int, batch_size: int) -> list[list[Job]]:
    """Jobs in chunks small enough to keep every worker busy (about 4 per worker) and at most `batch_size`
    long (the clips of a chunk go through the network together)."""
    size = max(1, min(batch_size, len(jobs) // (4 * workers)))
    return [list(jobs[i:i + size]) for i in range(0, len(jobs), size)]


def run_local(jobs: Sequence[Job], *, workers: int, model: str | None, device: str, text_model: str | None,
              batch_size: int, on_result: OnResult) -> None:
    """Run `jobs` in `workers` processes (in this process when 1), each loading the model once; every result
    goes to `on_result` as it comes. A worker process that dies makes its unfinished items errors (a new
    run redoes only them).

    The chunks go to the workers as they become free; meanwhile this process force-aligns the items of the
    last waiting chunks (align_ahead.align_file, the same words and phones a worker would find). It starts at
    once, while the workers import their modules and load the model: a core that would idle for the first
    second aligns instead (20 clips on 2 cores: see docs/scale.md)."""
    threads = max(1, cores() // workers)
    if workers == 1:
        worker = Worker(model, device, text_model, threads)
        for chunk in chunks(jobs, 1, batch_size):
            for result in worker.run(chunk, batch_size):
                on_result(result)
        return
    pool = process_pool(workers, start="forkserver", preload=PRELOAD, initializer=_init_local,
                        initargs=(model, device, text_model, threads))
    queue = chunks(jobs, workers, batch_size)
    to_align = _alignable(queue, model)
    pending: dict = {}
    # The first submissions start the workers, which waits until the forkserver has imported PRELOAD: they are
    # made from a thread, and this one aligns meanwhile. `sent`: the chunks of `queue` submitted so far.
    sent = min(workers + 1, len(queue))
    failed: list[BaseException] = []
    starter = threading.Thread(target=_submit, args=(pool, queue[:sent], batch_size, pending, failed),
                               daemon=True)
    starter.start()
    try:
        while starter.is_alive() and _align_next(to_align, sent):
            pass
        starter.join()
        if failed:
            raise failed[0]
        while sent < len(queue) or pending:
            while sent < len(queue) and len(pending) <= workers:  # every worker busy, one chunk ready
                _submit(pool, [queue[sent]], batch_size, pending)
                sent += 1
            aligned = _align_next(to_align, sent)
            done, _ = wait(pending, timeout=0 if aligned else None, return_when=FIRST_COMPLETED)
            for future in done:
                chunk = pending.pop(future)
                try:
                    results = future.result()
                except BrokenProcessPool as exc:
                    why = f"a worker process died ({exc or 'killed'}): rerun the batch to redo this item"
                    results = [JobResult(job, error=why) for job in chunk]
                for result in results:
                    on_result(result)
    except BaseException:  # Ctrl-C, SIGTERM, an error in on_result: stop the workers now, not after a chunk
        starter.join()  # its workers too
        pool.stop()
        raise
    finally:
        pool.close()


def _submit(pool: ProcessPool, chunks_: list[list[Job]], batch_size: int, pending: dict,
            failed: list[BaseException] | None = None) -> None:
    """Submit each chunk to the pool, into `pending` (future -> chunk); an error goes to `failed` if given."""
    try:
        for chunk in chunks_:
            pending[pool.submit(_run_local, chunk, batch_size)] = chunk
    except BaseException as exc:
        if failed is None:
            raise
        failed.append(exc)


def _align_next(to_align: list[tuple[int, Job, bool]], sent: int) -> bool:
    """Force-align the last job of `to_align` whose chunk (its index in the queue) has not been submitted yet
    (the chunks before `sent` have gone to the workers, which align their own); False when there is none."""
    while to_align and to_align[-1][0] < sent:
        to_align.pop()
    if not to_align:
        return False
    _, job, phones = to_align.pop()
    job.aligned = align_file(job.audio, job.text, phones, job.language)
    return True


def _alignable(queue: list[list[Job]], model: str | None) -> list[tuple[int, Job, bool]]:
    """(chunk index, job, whether the model needs its phones too) for the jobs this process can force-align,
    in queue order (taken from the end): those whose words come from forced alignment, when the model uses
    them."""
    from facegen.bundle import forced_alignment_of
    from facegen.word_timing import force_aligned

    needs = forced_alignment_of(model)
    if needs is None:
        return []
    return [(i, job, needs == "phones") for i, chunk in enumerate(queue) for job in chunk
            if force_aligned(job.text, job.alignment, job.no_text) and not job.problem]


class _RayWorker(Worker):
    """A Ray actor: one Worker per actor process."""


def run_ray(jobs: Sequence[Job], *, workers: int | None, address: str | None, model: str | None, device: str,
            text_model: str | None, batch_size: int, on_result: OnResult) -> None:
    """Run `jobs` as Ray actor tasks: on the cluster at `address` (host:port, ray://host:port or auto), else
    on the Ray instance this process already joined, else on a local instance started here (127.0.0.1, one CPU
    per worker). `workers`: actors to start (default: the cluster's CPUs). Every path must be the same on
    every node (a shared file system)."""
    ray = _import_ray()
    started = _connect(ray, address, workers)
    try:
        n = workers or max(1, int(ray.cluster_resources().get("CPU", 1)))
        actor = ray.remote(num_cpus=1)(_RayWorker)
        idle = [actor.remote(model, device, text_model, 1) for _ in range(min(n, len(jobs)))]
        queue = chunks(jobs, len(idle), batch_size)
        running: dict = {}  # task -> (actor, chunk)
        while queue or running:
            while idle and queue:
                worker, chunk = idle.pop(), queue.pop(0)
                running[worker.run.remote(chunk, batch_size)] = (worker, chunk)
            if not running:  # every actor died: what is left cannot run
                queue, failed = [], [job for chunk in queue for job in chunk]
                results = [JobResult(job, error="no Ray worker is left: rerun the batch") for job in failed]
            else:
                (task,), _ = ray.wait(list(running), num_returns=1)
                worker, chunk = running.pop(task)
                try:
                    results = ray.get(task)
                    idle.append(worker)
                except ray.exceptions.RayError as exc:  # the actor died (or its node): only this chunk fails
                    why = " ".join(str(exc).split())[:200]
                    error = f"the Ray worker failed ({why}): rerun the batch to redo this item"
                    results = [JobResult(job, error=error) for job in chunk]
            for result in results:
                on_result(result)
    finally:
        if started:
            ray.shutdown()


def check_ray(address: str | None) -> None:
    """Refuse, before any work, the ray engine without Ray installed or with an address that does not
    answer."""
    _import_ray()
    if address is not None:
        check_address(address)


def _import_ray():
    try:
        import ray
    except ImportError as exc:
        raise FacegenError("the ray engine needs Ray, which is not installed: pip install 'facegen[ray]', "
                           "or use the local engine", param="engine") from exc
    return ray


def check_address(address: str, timeout: float = 5.0) -> None:
    """Refuse a Ray address whose host:port does not answer (before Ray's own long retries)."""
    if address == "auto":
        return
    hostport = address.split("://", 1)[-1].rstrip("/")
    host, _, port = hostport.rpartition(":")
    if not host or not port.isdigit():
        raise FacegenError(f"the Ray address {address!r} is not host:port, e.g. 10.0.0.5:6379 or "
                           "ray://10.0.0.5:10001", param="ray_address")
    try:
        grpc = _answers_grpc(host.strip("[]"), int(port), timeout)
    except OSError as exc:
        raise FacegenError(f"cannot reach the Ray cluster at {address} ({exc.strerror or exc}): start it "
                           "with `ray start --head` or fix the address", param="ray_address") from exc
    if not grpc:  # something listens there, but not Ray: ray.init would retry for minutes
        raise FacegenError(f"{address} answers, but not as a Ray cluster (no gRPC server there): give the "
                           "address `ray start --head` printed", param="ray_address")


# an HTTP/2 client's opening (its preface and an empty SETTINGS frame): every gRPC server (Ray's GCS, the Ray
# Client server) answers with a SETTINGS frame of its own at once; a silent port or an HTTP/1 server does not
_HTTP2_OPENING = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])
_SETTINGS = 4  # the HTTP/2 frame type


def _answers_grpc(host: str, port: int, timeout: float) -> bool:
    """Whether host:port speaks HTTP/2 as gRPC servers do (its first frame is SETTINGS), within `timeout`."""
    with socket.create_connection((host, port), timeout=timeout) as conn:
        conn.settimeout(timeout)
        conn.sendall(_HTTP2_OPENING)
        head = b""
        try:
            while len(head) < 9:
                chunk = conn.recv(9 - len(head))
                if not chunk:
                    break
                head += chunk
        except TimeoutError:
            return False
    return len(head) == 9 and head[3] == _SETTINGS


def _connect(ray, address: str | None, workers: int | None) -> bool:
    """Join the cluster (True when this call started a local instance that must be shut down after)."""
    import logging

    quiet = {"logging_level": logging.ERROR, "log_to_driver": False, "configure_logging": True}
    if address is None and ray.is_initialized():
        return False
    if address is None:
        ray.init(num_cpus=workers or cores(), include_dashboard=False, _node_ip_address="127.0.0.1", **quiet)
        return True
    check_address(address)
    try:
        ray.init(address=address, **quiet)
    except (ConnectionError, RuntimeError, ValueError) as exc:
        raise FacegenError(f"cannot join the Ray cluster at {address} ({' '.join(str(exc).split())[:200]}): "
                           "check the address and that the cluster's Ray version matches",
                           param="ray_address") from exc
    return True
