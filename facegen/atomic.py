"""Write outputs atomically: a temporary file in the target folder, renamed on success.

Temporary names carry a mark no user file has — `.<stem>.facegen-tmp-<host>-<pid>-<random><suffix>` — so that
a run writing into a folder can remove what a killed run (SIGKILL, power loss) left there: files with our
mark, this host's id and the pid of a process that no longer exists (`remove_stale_temporaries`). Other hosts'
temporaries on a shared folder are left alone. A failure while writing removes the temporary file; a full disk
is reported as one line (`no space left ...`), whatever the library that was writing said.

An output of several files (an asset, its sidecar WAV, its clip folder, a preview video) is one `Transaction`:
all its files are renamed into place together at the end, or all removed on an error. `atomic_path` is a
transaction of one file, and joins the transaction open around it.
"""

from __future__ import annotations

import contextlib
import contextvars
import errno
import hashlib
import os
import re
import secrets
import shutil
import socket
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Self

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
    folder = _folder(target)
    if folder.exists() and not folder.is_dir():
        raise FacegenError(f"output folder {folder} is a file: choose another output path", param="path")
    if not folder.is_dir():
        raise FacegenError(f"output folder {folder} does not exist: create it or choose another output path",
                           param="path")
    if not os.access(folder, os.W_OK):
        raise FacegenError(f"output folder {folder} is not writable: choose another output path",
                           param="path")
    limit = _name_max(folder)
    size = len(os.fsencode(target.name))
    if size > limit:
        raise FacegenError(f"output name {target.name[:40]}... is {size} bytes long; this file system allows "
                           f"{limit}: choose a shorter output name", param="path")
    if target.is_dir():
        raise FacegenError(f"{target} is a folder, so facegen cannot write that file there: rename or remove "
                           "the folder, or choose another output name", param="path")


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


def disk_full_error(target: str | os.PathLike, exc: BaseException | None,
                    need_bytes: int = 0) -> FacegenError | None:
    """The one-line error for a write of `target` that failed with `exc` because its disk is full (an OSError
    with ENOSPC/EDQUOT, or any error while less than LOW_SPACE bytes are free), else None; `need_bytes` is
    what the write had reached when it failed (a lower bound of what it needs)."""
    target = Path(target)
    folder = target.parent if str(target.parent) else Path(".")
    full = isinstance(exc, OSError) and exc.errno in FULL_ERRNOS
    if not full and isinstance(exc, Exception):  # not an interrupt, a signal (runtime.Terminated), an exit
        with contextlib.suppress(OSError):
            full = shutil.disk_usage(folder).free < LOW_SPACE
    if not full:
        return None
    return FacegenError(f"no space left on {_device(folder)} writing {target}: need about "
                        f"{max(1, round(need_bytes / 1e6))} MB; free some space or choose another output "
                        "folder", param="path")


def _device(folder: Path) -> str:
    """The mount point holding `folder` (what `df` calls the device's place)."""
    path = folder.resolve()
    while not os.path.ismount(path) and path != path.parent:
        path = path.parent
    return str(path)


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike) -> Iterator[Path]:
    """Yield an unused temporary path beside `target` (same suffix); rename it to `target` on success.

    On any exception (or Ctrl-C, SIGTERM, SIGHUP: see facegen.cli) the temporary file is removed, so no
    partial output remains; a full disk becomes one FacegenError. Inside a Transaction the rename waits for
    its commit.
    """
    with Transaction() as transaction:
        yield transaction.file(target)


@contextlib.contextmanager
def output_folders(*targets: str | os.PathLike | None) -> Iterator[None]:
    """Create the missing folders above each target (as `mkdir -p`), and remove those made here again when the
    block fails: a run that writes nothing leaves no empty folder behind."""
    made: list[Path] = []
    try:
        for target in targets:
            if target is None:
                continue
            folder = Path(target).parent
            missing = []
            while not folder.exists() and not folder.is_symlink() and folder != folder.parent:
                missing.append(folder)
                folder = folder.parent
            for folder in reversed(missing):
                try:
                    folder.mkdir()
                except OSError as exc:
                    raise FacegenError(f"cannot create the output folder {folder} ({exc.strerror}): choose "
                                       "another output path", param="path") from exc
                made.append(folder)
        yield
    except BaseException:
        for folder in reversed(made):  # the deepest first; a folder something else wrote into stays
            with contextlib.suppress(OSError):
                folder.rmdir()
        raise


_current: contextvars.ContextVar[Transaction | None] = contextvars.ContextVar("transaction", default=None)


@dataclass
class _Staged:
    """One output of a transaction: `temp` becomes `target` at the commit (kind "file" or "folder"), or a
    scratch folder removed at the end (kind "scratch"), or an outdated `target` removed at the commit (kind
    "remove")."""
    kind: str
    target: Path
    temp: Path | None = None


class Transaction:
    """All or nothing for an output of one or more files and folders (an asset, its sidecar WAV, its clip
    folder, its preview video): each is written to a marked temporary beside its target (`file`, `folder`),
    and all are renamed into place when the outermost transaction ends without an error, or all removed when
    it fails.

    A Transaction opened while another is open in this thread joins it (its files are renamed at the outer
    commit; a failure inside it removes its own temporaries, as a savepoint); `join=False` starts an
    independent one (e.g. the files of a package written in a scratch folder, which must be in place before
    they are packed). Every temporary carries the mark of `remove_stale_temporaries`, so a killed run's
    leftovers are cleaned.
    """

    def __init__(self, *, join: bool = True) -> None:
        self._join = join
        self._root: Transaction = self
        self._staged: list[_Staged] = []
        self._start = 0
        self._token: contextvars.Token | None = None

    def __enter__(self) -> Self:
        outer = _current.get()
        if self._join and outer is not None:
            self._root = outer
            self._start = len(outer._staged)
        else:
            self._token = _current.set(self)
        return self

    def file(self, target: str | os.PathLike) -> Path:
        """An unused temporary path beside `target` (same suffix, not created: writers make the file) that
        becomes `target` at the commit."""
        target = Path(target)
        check_writable(target)
        folder = _folder(target)
        remove_stale_temporaries(folder)
        temp = self._new_temp("file", target, _create_file)
        temp.unlink()  # writers (pxr, soundfile, ...) create the file themselves
        return temp

    def folder(self, target: str | os.PathLike) -> Path:
        """A new temporary folder beside `target` that replaces it (an older folder of that name is removed)
        at the commit."""
        target = Path(target)
        if target.exists() and not target.is_dir():
            raise FacegenError(f"{target} is a file, so facegen cannot write the folder there: rename or "
                               "remove it, or choose another output name", param="path")
        check_writable(_folder(target) / f"{target.name}.new")  # a writable parent, a name not too long
        return self._new_temp("folder", target, os.mkdir)

    def scratch(self, near: str | os.PathLike) -> Path:
        """A new temporary folder beside `near` for intermediate files, removed when this transaction ends."""
        return self._new_temp("scratch", Path(near), os.mkdir)

    def remove(self, path: str | os.PathLike) -> None:
        """Remove `path` (an outdated file or folder of the asset) at the commit, not before."""
        self._root._staged.append(_Staged("remove", Path(path)))

    def _new_temp(self, kind: str, target: Path, make) -> Path:
        """A new temporary path beside `target` (`make(path)` creates it: a file keeps `target`'s suffix),
        staged before it exists: an interrupt (Ctrl-C) at any moment leaves nothing behind."""
        folder = _folder(target)
        suffix = target.suffix if kind == "file" else ""
        while True:
            staged = _Staged(kind, target, folder / f"{temp_prefix(target)}{secrets.token_hex(4)}{suffix}")
            self._root._staged.append(staged)
            try:
                make(staged.temp)
                return staged.temp
            except FileExistsError:
                self._root._staged.remove(staged)
            except OSError as exc:
                self._root._staged.remove(staged)
                full = disk_full_error(target, exc)
                if full is not None:
                    raise full from exc
                raise FacegenError(f"cannot write in {folder} ({exc.strerror}): choose another output path",
                                   param="path") from exc

    def __exit__(self, kind, exc, traceback) -> None:
        if self._token is not None:
            _current.reset(self._token)
        mine = self._root._staged[self._start :]
        if exc is None:
            if self._root is not self:
                self._remove_scratch(mine)  # scratch folders serve only the block that made them
                return
            try:
                self._commit(mine)
            except BaseException as failure:
                self._fail(mine, failure)
                raise
            return
        self._fail(mine, exc)

    def _remove_scratch(self, mine: list[_Staged]) -> None:
        for staged in mine:
            if staged.kind == "scratch":
                shutil.rmtree(staged.temp, ignore_errors=True)
        self._root._staged[self._start :] = [s for s in mine if s.kind != "scratch"]

    def _commit(self, staged: list[_Staged]) -> None:
        """Rename every temporary into place, the last staged first (a sidecar before its asset), then remove
        the outdated paths; a failed rename takes back what was already placed."""
        self._remove_scratch(staged)
        mask = _umask()
        placed: list[_Staged] = []
        trash = []
        try:
            for entry in reversed(staged):
                if entry.kind == "file":
                    if entry.temp.is_file():  # some writers (safetensors) make 0600 files: follow the umask
                        os.chmod(entry.temp, 0o666 & ~mask)
                    os.replace(entry.temp, entry.target)
                elif entry.kind == "folder":
                    os.chmod(entry.temp, 0o777 & ~mask)
                    if entry.target.exists():
                        trash.append(_trash_beside(entry.target))
                        os.replace(entry.target, trash[-1] / entry.target.name)
                    os.replace(entry.temp, entry.target)
                placed.append(entry)
            for entry in staged:
                if entry.kind == "remove":
                    _delete(entry.target)
        except BaseException:
            for entry in placed:
                _delete(entry.target)
            raise
        finally:
            for folder in trash:
                shutil.rmtree(folder, ignore_errors=True)
            del self._staged[:]

    def _fail(self, mine: list[_Staged], exc: BaseException) -> None:
        """Remove this block's temporaries; a full disk becomes one FacegenError naming the first target."""
        written = sum(_size(s.temp) for s in mine if s.temp is not None)
        for entry in mine:
            if entry.temp is not None:
                _delete(entry.temp)
        del self._root._staged[self._start :]
        if mine and not isinstance(exc, FacegenError):
            full = disk_full_error(mine[0].target, exc, written)
            if full is not None:
                raise full from exc


def _trash_beside(target: Path) -> Path:
    """A new folder beside `target` that an outdated folder is moved into before it is removed."""
    try:
        return Path(tempfile.mkdtemp(prefix=temp_prefix(target), dir=_folder(target)))
    except OSError as exc:
        raise FacegenError(f"cannot write in {_folder(target)} ({exc.strerror}): choose another output path",
                           param="path") from exc


def _create_file(path: Path) -> None:
    os.close(os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600))


def _folder(target: Path) -> Path:
    return target.parent if str(target.parent) else Path(".")


def _delete(path: Path) -> None:
    """Remove a file or a folder tree, if it is there."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def _size(path: Path) -> int:
    """The bytes in a file, or in a folder's files."""
    with contextlib.suppress(OSError):
        if path.is_file():
            return path.stat().st_size
        if path.is_dir():
            return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())
    return 0
