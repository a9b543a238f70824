"""The format table: one row per animation file format, read by `facegen.exchange`, the CLI and `validate`.

A row names the format's module (its `write` and, when the format can be read back, `read`), the file
extensions it owns, the write options it takes besides the common `write_audio` and `audio_source`, whether
its writer streams (reads `anim.frame_blocks()`, so a FrameStream is never held whole), the module of
`facegen.validate` that checks its files, and what its files carry (a sidecar WAV, the mesh, the frame rate,
ARKit weights): code asks the row, never the suffix. A new format is one new module plus one row here.

The rows live in this one small module rather than in each format module so that reading the table (the
CLI's `--help` lists the extensions) imports neither numpy nor pxr/pygltflib; tests/test_exchange_usd.py
checks each row's options against its module's `write` signature.
"""

from __future__ import annotations

import importlib
import os
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

from facegen.errors import FacegenError

COMMON_OPTIONS = ("write_audio", "audio_source")


@dataclass(frozen=True)
class Format:
    name: str
    module: str
    extensions: tuple[str, ...]
    options: tuple[str, ...]  # write options besides COMMON_OPTIONS
    validator: str
    streams: bool = False  # its writer reads frames block by block
    whole_clip: tuple[str, str] | None = None  # (option, value) making the writer need all frames at once
    arkit: bool = False  # its files hold ARKit shape weights (fitted on the rig's face: facegen.arkit)
    libraries: tuple[str, ...] = ()  # modules its writer imports that are slow to import (import_writer)
    sidecar: bool = True  # its writer puts the audio beside the file as a WAV (out.wav)
    reads: bool = True  # facegen reads its files back (its module has `read`)
    holds_mesh: bool = True  # its files hold the faces and rest pose (else a template gives them)
    holds_fps: bool = True  # its files hold the frame rate (else the caller gives it)

    def streams_with(self, options: dict) -> bool:
        """True when writing with `options` reads the frames block by block."""
        if self.whole_clip is None:
            return self.streams
        option, value = self.whole_clip
        return self.streams and options.get(option) != value


USD_LIBRARIES = ("pxr.Usd", "pxr.UsdGeom", "pxr.UsdSkel", "pxr.UsdShade", "pxr.UsdMedia")  # ~0.25 s
FORMATS = (
    Format("USD", "facegen.exchange.usd", (".usda", ".usdc", ".usd"),
           ("mode", "rig", "morph_targets", "tolerance", "meters_per_unit", "clips"), "facegen.validate.usd",
           streams=True, whole_clip=("mode", "blendshapes"),  # blendshapes: a PCA over the whole clip
           libraries=USD_LIBRARIES),
    Format("NumPy", "facegen.exchange.npy", (".npy",), (), "facegen.validate.npy", streams=True,
           holds_mesh=False, holds_fps=False),  # [T, 3V] vertex positions only
    Format("glTF", "facegen.exchange.gltf", (".glb", ".gltf"),
           ("rig", "morph_targets", "tolerance", "meters_per_unit"), "facegen.validate.gltf"),
    Format("USDZ", "facegen.exchange.usdz", (".usdz",),
           ("mode", "rig", "morph_targets", "tolerance", "meters_per_unit", "clips"),
           "facegen.validate.usd", libraries=USD_LIBRARIES, sidecar=False),  # the audio is in the package
    # ARKit's 52 shape weights per frame (fitted on facegen's face): Audio2Face JSON, Live Link Face CSV
    Format("Audio2Face JSON", "facegen.exchange.arkit_json", (".json",), (), "facegen.validate.arkit",
           streams=True, arkit=True, reads=False, holds_mesh=False),
    Format("Live Link Face CSV", "facegen.exchange.arkit_csv", (".csv",), (), "facegen.validate.arkit",
           streams=True, arkit=True, reads=False, holds_mesh=False),
)


def by_module(module: str) -> Format:
    """The row of format module `module` (a format module's own row: `by_module(__name__)`)."""
    return next(f for f in FORMATS if f.module == module)


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
