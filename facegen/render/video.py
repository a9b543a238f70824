"""Video files: rgb24 frames piped to ffmpeg as H.264 MP4 with the clip's audio, frames rendered ahead.

ffmpeg (processes.start_tool) writes the frames as H.264 yuv420p at the clip's fps; the audio (trimmed or
padded to the clip's duration) is muxed in as AAC, and the caller wraps the output in facegen.atomic's
atomic_path: an error or Ctrl-C leaves no partial file. Frames render on a few threads (the numba kernels
release the GIL) a few frames ahead of the encoder.
"""

from __future__ import annotations

import os
import subprocess
import tempfile
from collections import deque
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from fractions import Fraction
from pathlib import Path

import numpy as np

from facegen.atomic import check_writable
from facegen.audio import write_wav
from facegen.errors import FacegenError
from facegen.processes import start_tool
from facegen.runtime import Reporter

VIDEO_SUFFIXES = (".mp4", ".mov", ".mkv")
FRAME_WINDOW = 4  # frames rendered ahead of the encoder


def _rate(fps: float) -> str:
    return str(Fraction(fps).limit_denominator(100000))


def clip_audio(audio: np.ndarray | None, sample_rate: int, frames: int, fps: float) -> np.ndarray | None:
    """The audio trimmed or zero-padded to exactly `frames` frames' duration; None when there is none."""
    if audio is None or len(audio) == 0:
        return None
    n = round(frames / fps * sample_rate)
    audio = np.asarray(audio, np.float32)[:n]
    return np.pad(audio, (0, n - len(audio))) if len(audio) < n else audio


def encode(
    frames: Iterator[np.ndarray],
    count: int,
    width: int,
    height: int,
    fps: float,
    audio: np.ndarray | None,
    sample_rate: int,
    path: Path,
    reporter: Reporter,
) -> None:
    """Pipe `count` rgb24 frames (an iterator of arrays) to ffmpeg and mux the audio; write `path`."""
    with tempfile.TemporaryDirectory(prefix="facegen-render-") as tmp:
        cmd = [
            "-hide_banner",
            "-nostats",
            "-loglevel",
            "error",
            "-y",
            "-f",
            "rawvideo",
            "-pix_fmt",
            "rgb24",
            "-s",
            f"{width}x{height}",
            "-framerate",
            _rate(fps),
            "-i",
            "pipe:0",
        ]
        if audio is not None:
            wav = Path(tmp) / "audio.wav"
            write_wav(audio, sample_rate, wav, subtype="FLOAT")
            cmd += [
                "-i",
                str(wav),
                "-map",
                "0:v:0",
                "-map",
                "1:a:0",
                "-c:a",
                "aac",
                "-b:a",
                "160k",
                "-ar",
                "48000",
            ]
        cmd += [
            "-c:v",
            "libx264",
            "-preset",
            "veryfast",
            "-crf",
            "18",
            "-pix_fmt",
            "yuv420p",
            "-movflags",
            "+faststart",
            str(path),
        ]
        # ffmpeg's messages go to a file, not a pipe, so it can never block on them
        with (
            open(Path(tmp) / "ffmpeg.log", "w+b") as log,
            reporter.bar(total=count, unit="frame", desc="render", leave=False) as bar,
        ):
            # own session: a terminal's Ctrl-C reaches only us; we stop ffmpeg ourselves
            proc = start_tool("ffmpeg", cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=log,
                              start_new_session=True)
            try:
                for frame in frames:
                    proc.stdin.write(frame.data)
                    bar.update(1)
                proc.stdin.close()
                code = proc.wait()
            except BrokenPipeError:
                code = proc.wait()
            except BaseException:
                proc.kill()
                proc.wait()
                raise
            if code != 0:
                log.seek(0)
                lines = log.read().decode(errors="replace").strip().splitlines()
                detail = lines[-1] if lines else f"exit code {code}"
                raise FacegenError(f"ffmpeg could not write {path.name}: {detail}; check disk space and -o")


def frames_in_order(
    render_one: Callable[[int], np.ndarray], count: int, threads: int
) -> Iterator[np.ndarray]:
    """Render frames 0..count-1 on `threads` threads, yielding them in order (a few frames ahead)."""
    if threads <= 1:
        for t in range(count):
            yield render_one(t)
        return
    with ThreadPoolExecutor(max_workers=threads, thread_name_prefix="facegen-render") as pool:
        pending: deque = deque()
        try:
            for t in range(count):
                pending.append(pool.submit(render_one, t))
                if len(pending) > FRAME_WINDOW:
                    yield pending.popleft().result()
            while pending:
                yield pending.popleft().result()
        finally:
            for future in pending:
                future.cancel()


def check_output(path: str | os.PathLike) -> Path:
    """A video file name facegen can write (.mp4/.mov/.mkv in a writable folder), before any work."""
    path = Path(path)
    if path.suffix.lower() not in VIDEO_SUFFIXES:
        raise FacegenError(
            f"cannot write a video to {path.name!r}: use a {', '.join(VIDEO_SUFFIXES)} file name "
            "(e.g. preview.mp4)"
        )
    check_writable(path)
    return path
