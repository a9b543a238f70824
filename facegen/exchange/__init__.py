"""Animation files: one module per format, chosen by the file's extension through the format table.

Each format module defines
    write(anim, path, *, write_audio=True, audio_source=None, **format_options) -> list[Path]
        (the asset's files: the asset, then any sidecars; every writer takes write_audio and audio_source,
        the input audio file, which must never be overwritten by a sidecar)
and, when the format can be read back,
    read(path, template=None, fps=None) -> Animation
Its extensions, options, streaming and validator are its row in exchange/formats.py. Importing this
package imports no format module (nor numpy): `facegen --help` reads the table.
"""

from __future__ import annotations

import importlib
import os
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

from facegen.errors import FacegenError
from facegen.exchange.formats import COMMON_OPTIONS, FORMATS, Format

if TYPE_CHECKING:
    from facegen.animation import Animation
    from facegen.face.mesh import Mesh


def extensions() -> list[str]:
    """The file extensions facegen writes, in table order."""
    return [ext for fmt in FORMATS for ext in fmt.extensions]


def format_of(path: str | os.PathLike) -> Format:
    """The table row for `path`'s extension; an unknown extension is a FacegenError."""
    return format_of_extension(Path(path).suffix, Path(path).name)


def format_of_extension(extension: str, name: str | None = None) -> Format:
    """The table row for a file extension (".usdc", "usdc", any case); an unknown one is a FacegenError
    (naming the file `name` when given)."""
    suffix = "." + extension.lower().lstrip(".") if extension else ""
    for fmt in FORMATS:
        if suffix in fmt.extensions:
            return fmt
    what = f"cannot handle {name!r}: " if name is not None else ""
    known = ", ".join(extensions())
    raise FacegenError(f"{what}unknown extension {suffix or '(none)'!r}; use one of {known}",
                       param="path")


def format_module(path: str | os.PathLike) -> ModuleType:
    """The module that handles `path`'s extension; an unknown extension is a FacegenError."""
    return importlib.import_module(format_of(path).module)


def import_writer(path: str | os.PathLike) -> None:
    """Import the writer of `path`'s format and the libraries it needs (pxr for USD: a quarter of a second),
    e.g. while waiting for other work, so that writing starts at once."""
    format_module(path)
    for library in format_of(path).libraries:
        importlib.import_module(library)


def check_write_options(path: str | os.PathLike, options: dict) -> None:
    """Refuse options the format of `path` does not take (before any work is done); the error's `param` names
    them (a front end says how it spells them)."""
    unknown = sorted(set(options) - set(format_of(path).options + COMMON_OPTIONS))
    if unknown:
        one = len(unknown) == 1
        raise FacegenError(f"{', '.join(unknown)} {'does' if one else 'do'} not apply to {Path(path).suffix} "
                           f"files: drop {'it' if one else 'them'} or choose another output format",
                           param=tuple(unknown) if len(unknown) > 1 else unknown[0])


def write_animation(anim: Animation, path: str | os.PathLike, **options) -> list[Path]:
    """Write `anim` in the format of `path`'s extension; return the files written (asset first).

    Options are the format's keyword arguments (e.g. `meters_per_unit` for USD, `write_audio` and
    `audio_source` for all); an option the format does not take is a FacegenError. The write follows the
    checked plan of facegen.exchange.plan (`plan_write`), as the CLI and batch do.
    """
    from facegen.exchange.plan import plan_write

    return plan_write(path, options=options).write(anim)


def read_animation(
    path: str | os.PathLike, template: Mesh | None = None, fps: float | None = None
) -> Animation:
    """Read an animation file; `template` gives faces/rest pose where the file has none (.npy)."""
    if not format_of(path).reads:
        raise FacegenError(f"facegen writes {Path(path).suffix} files but cannot read them back")
    return format_module(path).read(path, template=template, fps=fps)
