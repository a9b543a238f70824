"""Animation files: one module per format, chosen by the file's extension.

Each format module defines
    write(anim, path, *, write_audio=True, audio_source=None, **format_options) -> list[Path]
        (the asset's files: the asset, then any sidecars; every writer takes write_audio and audio_source,
        the input audio file, which must never be overwritten by a sidecar)
and, when the format can be read back,
    read(path, template=None, fps=None) -> Animation
A new format is one new module plus its extensions in FORMATS.
"""

from __future__ import annotations

import importlib
import inspect
import os
from pathlib import Path
from types import ModuleType

import numpy as np

from facegen.animation import Animation
from facegen.errors import FacegenError
from facegen.mesh import Mesh

FORMATS: dict[str, str] = {
    ".usda": "facegen.exchange.usd",
    ".usdc": "facegen.exchange.usd",
    ".usd": "facegen.exchange.usd",
    ".npy": "facegen.exchange.npy",
    ".glb": "facegen.exchange.gltf",
    ".gltf": "facegen.exchange.gltf",
    ".usdz": "facegen.exchange.usdz",
}


def extensions() -> list[str]:
    """The file extensions facegen writes, in table order."""
    return list(FORMATS)


def format_module(path: str | os.PathLike) -> ModuleType:
    """The module that handles `path`'s extension; an unknown extension is a FacegenError."""
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        raise FacegenError(
            f"cannot handle {Path(path).name!r}: unknown extension {suffix or '(none)'!r}; "
            f"use one of {', '.join(FORMATS)}"
        )
    return importlib.import_module(FORMATS[suffix])


OPTION_FLAGS = {"mode": "--usd-mode", "morph_targets": "--morph-targets", "tolerance": "--tolerance"}


def check_write_options(path: str | os.PathLike, options: dict) -> None:
    """Refuse options the format of `path` does not take (before any work is done)."""
    module = format_module(path)
    accepted = [
        name
        for name, p in inspect.signature(module.write).parameters.items()
        if p.kind is inspect.Parameter.KEYWORD_ONLY
    ]
    unknown = sorted(set(options) - set(accepted))
    if unknown:
        names = ", ".join(OPTION_FLAGS.get(k, k) for k in unknown)
        raise FacegenError(
            f"{names} does not apply to {Path(path).suffix} files: drop it or choose another output format"
        )


def write_animation(anim: Animation, path: str | os.PathLike, **options) -> list[Path]:
    """Write `anim` in the format of `path`'s extension; return the files written (asset first).

    Options are the format's keyword arguments (e.g. `meters_per_unit` for USD, `write_audio` for all);
    an option the format does not take is a FacegenError.
    """
    check_write_options(path, options)
    module = format_module(path)
    return module.write(anim, path, **options)


def read_animation(
    path: str | os.PathLike, template: Mesh | None = None, fps: float | None = None
) -> Animation:
    """Read an animation file; `template` gives faces/rest pose where the file has none (.npy)."""
    module = format_module(path)
    if not hasattr(module, "read"):
        raise FacegenError(f"facegen writes {Path(path).suffix} files but cannot read them back")
    return module.read(path, template=template, fps=fps)


def check_animation(anim: Animation) -> None:
    """Refuse an Animation no writer can store: wrong shapes, no frames, bad fps, faces out of range."""
    vertices = anim.vertices if hasattr(anim.vertices, "blocks") else np.asarray(anim.vertices)  # FrameStream: lazy
    faces = np.asarray(anim.faces)
    if len(vertices.shape) != 3 or vertices.shape[2] != 3 or vertices.shape[0] == 0 or vertices.shape[1] == 0:
        raise FacegenError(f"animation vertices must be [T, V, 3] with T, V > 0, got {list(vertices.shape)}")
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.shape[0] == 0:
        raise FacegenError(f"animation faces must be [F, 3] triangles, got {list(faces.shape)}")
    if faces.min() < 0 or faces.max() >= vertices.shape[1]:
        raise FacegenError(f"animation faces index vertices outside 0..{vertices.shape[1] - 1}")
    if np.asarray(anim.template).shape != vertices.shape[1:]:
        raise FacegenError(
            f"animation template is {list(np.shape(anim.template))}, frames are {list(vertices.shape[1:])}"
        )
    if not (np.isfinite(anim.fps) and anim.fps > 0):
        raise FacegenError(f"animation fps must be a positive number, got {anim.fps}")
    if anim.audio is not None and np.asarray(anim.audio).ndim != 1:
        raise FacegenError(f"animation audio must be mono (1-D), got shape {list(np.shape(anim.audio))}")
    if anim.audio is not None and not (
        isinstance(anim.sample_rate, int | np.integer) and anim.sample_rate > 0
    ):
        raise FacegenError(f"animation sample rate must be a positive integer, got {anim.sample_rate!r}")
