"""The files a user gives facegen to read (transcripts, alignment files, manifests, templates.pkl), read one
way: regular files only, and no more than a bound.

A FIFO without a writer would block `open` forever, /dev/zero and /dev/urandom never end, and a folder or a
socket is no input at all: the path is checked with stat before it is opened, opened without blocking, and
checked again on the open file (the path may have changed in between). The bytes read stop one past the
bound, so a file that grows while it is read is refused too, in bounded memory.
"""

from __future__ import annotations

import errno
import os
import stat
from typing import BinaryIO

from facegen.errors import FacegenError

TRANSCRIPT_BYTES = 1 << 20  # about 18 hours of speech (150 words a minute, ~6 bytes a word)
MANIFEST_BYTES = 16 << 20  # about 100,000 rows with their transcripts

_KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a named pipe (FIFO)"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def _not_regular(mode: int, path: str | os.PathLike) -> OSError | None:
    """The OSError for a file of `mode` that is not a regular file (strerror says what it is), else None."""
    if stat.S_ISREG(mode):
        return None
    kind = next((name for test, name in _KINDS if test(mode)), "not a plain file")
    return OSError(errno.EISDIR if stat.S_ISDIR(mode) else errno.EINVAL, f"{kind}, not a regular file",
                   os.fspath(path))


def _regular(path: str | os.PathLike) -> os.stat_result:
    """os.stat(path) (links followed) of a regular file; an OSError for anything else and for a NUL byte."""
    try:
        found = os.stat(path)
    except ValueError as exc:  # a NUL byte in the path
        raise OSError(errno.EINVAL, "the path contains a NUL byte", repr(os.fspath(path))) from exc
    problem = _not_regular(found.st_mode, path)
    if problem is not None:
        raise problem
    return found


def open_input(path: str | os.PathLike) -> BinaryIO:
    """`path` open for reading in binary, when it is a regular file (symbolic links followed); anything else
    is an OSError at once, its strerror saying what the path is ("a named pipe (FIFO), not a regular file"),
    as is a path with a NUL byte."""
    _regular(path)
    flags = os.O_RDONLY | getattr(os, "O_BINARY", 0) | getattr(os, "O_CLOEXEC", 0)
    fd = os.open(path, flags | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0))
    try:
        problem = _not_regular(os.fstat(fd).st_mode, path)  # replaced by something else since the stat
        if problem is not None:
            raise problem
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def _size(n: int) -> str:
    return f"{n / 1e6:.1f} MB" if n >= 100_000 else f"{n / 1e3:.0f} kB" if n >= 1000 else f"{n} bytes"


def _shown(path: str | os.PathLike, name: str | None) -> str:
    return (os.fspath(path) if name is None else name).replace("\0", "\\0")  # one printable line


def check_input(path: str | os.PathLike, *, what: str, limit: int, too_big: str, fix: str = "check the path",
                name: str | None = None, param: str | None = None) -> None:
    """Refuse, without reading it, a file read_input would refuse now (the same FacegenErrors): a front end
    checks its inputs before it loads a model."""
    try:
        size = _regular(path).st_size
    except OSError as exc:
        raise FacegenError(f"cannot read {what} {_shown(path, name)} ({exc.strerror or exc}): {fix}",
                           param=param) from exc
    if size > limit:
        raise FacegenError(f"{what} {_shown(path, name)} is {_size(size)}, more than facegen reads "
                           f"({_size(limit)}): {too_big}", param=param)


def read_input(path: str | os.PathLike, *, what: str, limit: int, too_big: str, fix: str = "check the path",
               name: str | None = None, param: str | None = None) -> bytes:
    """The bytes of the regular file `path`, a user's `what` ("transcript file", "manifest"), at most `limit`
    bytes; every refusal is one FacegenError, said with `name` (the path as the user wrote it; default
    `path`): "cannot read {what} {name} ({reason}): {fix}" for a missing or unreadable path, a FIFO, a device
    or a folder, and "{what} {name} is 5.2 MB, more than facegen reads (1.0 MB): {too_big}" for a larger file.
    """
    try:
        with open_input(path) as f:
            size = os.fstat(f.fileno()).st_size
            data = f.read(size + 1) if size <= limit else b""  # a buffer of the size, not of the bound
            if size < len(data) <= limit:  # grown since (or a size the system does not know): on to the bound
                data += f.read(limit + 1 - len(data))
    except OSError as exc:
        raise FacegenError(f"cannot read {what} {_shown(path, name)} ({exc.strerror or exc}): {fix}",
                           param=param) from exc
    if size > limit or len(data) > limit:
        found = _size(size) if size > limit else f"at least {_size(len(data))}"  # grown while read
        raise FacegenError(f"{what} {_shown(path, name)} is {found}, more than facegen reads "
                           f"({_size(limit)}): {too_big}", param=param)
    return data


def read_input_text(path: str | os.PathLike, *, what: str, limit: int, too_big: str,
                    fix: str = "check the path", name: str | None = None, param: str | None = None,
                    encoding: str = "utf-8") -> str:
    """read_input's bytes as text in `encoding` ("utf-8-sig": a byte order mark is dropped); bytes that are
    not are a FacegenError too ("... is not UTF-8 text (invalid start byte at byte 12): save it as UTF-8")."""
    data = read_input(path, what=what, limit=limit, too_big=too_big, fix=fix, name=name, param=param)
    try:
        return data.decode(encoding)
    except UnicodeDecodeError as exc:
        raise FacegenError(f"{what} {_shown(path, name)} is not UTF-8 text ({exc.reason} at byte "
                           f"{exc.start}): save it as UTF-8", param=param) from exc
