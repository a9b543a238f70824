"""The audio sidecar: the clip's sound written as a WAV file beside an animation file.

`out.usda` gets `out.wav` (PCM 16-bit, mono, at the animation's sample rate). The main file and its
sidecar are written together: both through temporary files, so a failed write leaves neither.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from facegen.atomic import atomic_path
from facegen.audio import write_wav
from facegen.errors import FacegenError


def sidecar_path(path: str | os.PathLike) -> Path:
    """The WAV file that goes with an animation file: same folder, same stem, `.wav`."""
    return Path(path).with_suffix(".wav")


def is_same_file(a: str | os.PathLike | None, b: str | os.PathLike) -> bool:
    """True when both paths exist and name the same file."""
    try:
        return a is not None and os.path.samefile(a, b)
    except OSError:
        return False


@contextlib.contextmanager
def atomic_with_sidecar(
    target: str | os.PathLike,
    audio: np.ndarray | None,
    sample_rate: int,
    source: str | os.PathLike | None = None,
) -> Iterator[tuple[Path, Path | None]]:
    """Yield (temporary main path, final sidecar path or None) for writing `target` with its audio.

    The sidecar WAV is written first to its own temporary file; both files are renamed into place
    only when the caller's block succeeds. On failure neither file is left behind. When `source` (the
    input audio file) is the sidecar itself (`clip.wav` animated to `clip.usda`), it is kept as it is
    and referenced instead of being overwritten.
    """
    target = Path(target)
    if audio is None:
        with atomic_path(target) as tmp:
            yield tmp, None
        return
    wav = sidecar_path(target)
    if wav == target:
        raise FacegenError(f"output {target} would be overwritten by its own audio sidecar: use another name")
    if is_same_file(source, wav):
        with atomic_path(target) as tmp:
            yield tmp, wav
        return
    placed = False
    try:
        with atomic_path(target) as tmp:
            with atomic_path(wav) as tmp_wav:
                write_wav(audio, sample_rate, tmp_wav)
                yield tmp, wav
            placed = True  # the sidecar is in place; the main file is renamed next
    except BaseException:
        if placed:
            wav.unlink(missing_ok=True)
        raise
