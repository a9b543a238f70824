"""Write outputs atomically: a temporary file in the target folder, renamed on success.

Temporary names carry a mark no user file has — `.<stem>.facegen-tmp-<host>-<pid>-<random><suffix>` — so that
a run writing into a folder can remove what a killed run (SIGKILL, power loss) left there: files with our mark,
this host's id and the pid of a process that no longer exists (`remove_stale_temporaries`). Other hosts'
temporaries on a shared folder are left alone. A failure while writing removes the temporary file; a full disk
is reported as one line (`no space left ...`), whatever the library that was writing said.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import re
import shutil
import socket
import tempfile
from collections.abc import Iterator
from pathlib import Path

from facegen.errors import FacegenError

TEMP_MARK = "facegen-tmp"
HOST = hashlib.sha256(socket.gethostname().encode()).hexdigest()[:6]
_STALE = re.compile(rf"{TEMP_MARK}-{HOST}-(\d+)-")
_cleaned: set[str] = set()
FULL_ERRNOS = (errno.ENOSPC, errno.EDQUOT)
LOW_SPACE = 1 << 20  # bytes: a folder with less free space than this is taken as full after a failed write


def check_writable(target: str | os.PathLike) -> None:
    """Fail early, before any work, when `target` cannot be written."""
    target = Path(target)
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        raise FacegenError(f"output folder {folder} does not exist: create it or choose another -o path")
    if not os.access(folder, os.W_OK):
        raise FacegenError(f"output folder {folder} is not writable: choose another -o path")
    limit = _name_max(folder)
    if len(os.fsencode(target.name)) > limit:
        raise FacegenError(f"output name {target.name[:40]}... is {len(os.fsencode(target.name))} bytes long; this "
                           f"file system allows {limit}: choose a shorter -o name")
    if target.is_dir():
        raise FacegenError(f"{target} is a folder, so facegen cannot write that file there: rename or remove the "
                           "folder, or choose another -o name")


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _name_max(folder: Path) -> int:
    try:
        return os.pathconf(folder, "PC_NAME_MAX")
    except (OSError, ValueError, AttributeError):
        return 255


def temp_prefix(target: str | os.PathLike) -> str:
    """The prefix of this process's temporary names for `target` (files and folders alike; the stem is cut
    short so that a name as long as the file system allows still has a temporary name)."""
    return f".{Path(target).stem[:64]}.{TEMP_MARK}-{HOST}-{os.getpid()}-"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # exists, owned by someone else
        return True
    return True


def remove_stale_temporaries(folder: str | os.PathLike) -> list[Path]:
    """Remove the temporaries that dead facegen processes of this host left in `folder` (once per folder and
    process); return what was removed."""
    folder = Path(folder)
    key = str(folder.resolve())
    if key in _cleaned:
        return []
    _cleaned.add(key)
    removed = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return []
    for entry in entries:
        match = _STALE.search(entry.name) if TEMP_MARK in entry.name else None
        if match is None or int(match.group(1)) == os.getpid() or _alive(int(match.group(1))):
            continue
        path = Path(entry.path)
        with contextlib.suppress(OSError):
            if entry.is_dir(follow_symlinks=False):
                shutil.rmtree(path)
            else:
                path.unlink()
            removed.append(path)
    return removed


def disk_full_error(target: str | os.PathLike, exc: BaseException | None, need_bytes: int = 0) -> FacegenError | None:
    """The one-line error for a write of `target` that failed with `exc` because its disk is full (an OSError
    with ENOSPC/EDQUOT, or any error while less than LOW_SPACE bytes are free), else None; `need_bytes` is what
    the write had reached when it failed (a lower bound of what it needs)."""
    target = Path(target)
    folder = target.parent if str(target.parent) else Path(".")
    full = isinstance(exc, OSError) and exc.errno in FULL_ERRNOS
    if not full and exc is not None and not isinstance(exc, (KeyboardInterrupt, SystemExit)):
        with contextlib.suppress(OSError):
            full = shutil.disk_usage(folder).free < LOW_SPACE
    if not full:
        return None
    return FacegenError(f"no space left on {_device(folder)} writing {target}: need about "
                        f"{max(1, round(need_bytes / 1e6))} MB; free some space or choose another -o folder")


def _device(folder: Path) -> str:
    """The mount point holding `folder` (what `df` calls the device's place)."""
    path = folder.resolve()
    while not os.path.ismount(path) and path != path.parent:
        path = path.parent
    return str(path)


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike) -> Iterator[Path]:
    """Yield an unused temporary path beside `target` (same suffix); rename it to `target` on success.

    On any exception (or Ctrl-C, SIGTERM, SIGHUP: see facegen.cli) the temporary file is removed, so no partial
    output remains; a full disk becomes one FacegenError.
    """
    target = Path(target)
    check_writable(target)
    folder = target.parent if str(target.parent) else Path(".")
    remove_stale_temporaries(folder)
    try:
        fd, tmp = tempfile.mkstemp(prefix=temp_prefix(target), suffix=target.suffix, dir=folder)
    except OSError as exc:
        full = disk_full_error(target, exc)
        if full is not None:
            raise full from exc
        raise FacegenError(f"cannot write in {folder} ({exc.strerror}): choose another -o path") from exc
    os.close(fd)
    tmp_path = Path(tmp)
    tmp_path.unlink()  # writers (pxr, soundfile, ...) create the file themselves
    try:
        yield tmp_path
        if tmp_path.is_file():  # some writers (safetensors) create 0600 files: follow the umask like the rest
            os.chmod(tmp_path, 0o666 & ~_umask())
        os.replace(tmp_path, target)
    except BaseException as exc:
        written = tmp_path.stat().st_size if tmp_path.is_file() else 0
        tmp_path.unlink(missing_ok=True)
        if not isinstance(exc, FacegenError):
            full = disk_full_error(target, exc, written)
            if full is not None:
                raise full from exc
        raise
