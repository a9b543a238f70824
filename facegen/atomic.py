"""Write outputs atomically: a temporary file in the target folder, renamed on success."""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

from facegen.errors import FacegenError


def check_writable(target: str | os.PathLike) -> None:
    """Fail early, before any work, when `target` cannot be written."""
    target = Path(target)
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        raise FacegenError(f"output folder {folder} does not exist: create it or choose another -o path")
    if not os.access(folder, os.W_OK):
        raise FacegenError(f"output folder {folder} is not writable: choose another -o path")
    if target.is_dir():
        raise FacegenError(f"output {target} is a folder: give a file name such as {target / 'out.usda'}")


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike) -> Iterator[Path]:
    """Yield an unused temporary path beside `target` (same suffix); rename it to `target` on success.

    On any exception (or Ctrl-C) the temporary file is removed, so no partial output remains.
    """
    target = Path(target)
    check_writable(target)
    folder = target.parent if str(target.parent) else Path(".")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=target.suffix, dir=folder)
    except OSError as exc:
        raise FacegenError(f"cannot write in {folder} ({exc.strerror}): choose another -o path") from exc
    os.close(fd)
    tmp_path = Path(tmp)
    tmp_path.unlink()  # writers (pxr, soundfile, ...) create the file themselves
    try:
        yield tmp_path
        os.replace(tmp_path, target)
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise
