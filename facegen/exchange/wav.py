"""The audio sidecar: the clip's sound written as a WAV file beside an animation file.

`out.usda` gets `out.wav` (PCM 16-bit, mono, at the animation's sample rate). The main file and its
sidecar are written together: one facegen.atomic.Transaction, so a failed write leaves neither.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from facegen.atomic import Transaction
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

    The sidecar WAV is written first to its own temporary file; both files are one Transaction, renamed into
    place only when the caller's block succeeds (and the transaction open around it, if any, commits). On
    failure neither file is left behind. When `source` (the input audio file) is the sidecar itself
    (`clip.wav` animated to `clip.usda`), it is kept as it is and referenced instead of being overwritten.
    """
    target = Path(target)
    wav = sidecar_path(target) if audio is not None else None
    if wav == target:
        raise FacegenError(f"output {target} would be overwritten by its own audio sidecar: use another name")
    with Transaction() as transaction:
        tmp = transaction.file(target)
        if wav is not None and not is_same_file(source, wav):
            with Transaction() as sidecar:  # a failure names the sidecar
                write_wav(audio, sample_rate, sidecar.file(wav))
        yield tmp, wav
