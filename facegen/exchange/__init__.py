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

import os
from pathlib import Path
from typing import TYPE_CHECKING

from facegen.errors import FacegenError
from facegen.exchange.formats import (  # noqa: F401 - the package's API: the table's lookups
    FORMATS,
    Format,
    check_write_options,
    extensions,
    format_module,
    format_of,
    format_of_extension,
    import_writer,
)

if TYPE_CHECKING:
    from facegen.animation import Animation
    from facegen.face.mesh import Mesh


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
