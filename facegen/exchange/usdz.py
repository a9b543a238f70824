"""USDZ: the USD stage (binary crate) and its audio packaged in one file.

`out.usdz` is an uncompressed zip, as the USDZ spec wants, holding

    out.usdc   the stage exactly as usd.py writes it (points or blendshapes mode), the package's root layer
    out.wav    the clip's audio (16-bit PCM); the stage's SpatialAudio filePath is @./out.wav@, which
               resolves inside the package (`/abs/out.usdz[out.wav]`)
    out.clips/ a long clip's value clips, rest layer and manifest (usd_clips.py), which
               CreateNewUsdzPackage follows from the stage's clip set and sublayer

No sidecar is written beside the package: it is self-contained. The package is made with
UsdUtils.CreateNewUsdzPackage from a marked scratch folder and renamed into place (one
facegen.atomic.Transaction), so a failed write leaves nothing behind.
"""

from __future__ import annotations

import os
from pathlib import Path

from facegen.animation import Animation
from facegen.atomic import Transaction
from facegen.errors import FacegenError
from facegen.exchange import usd
from facegen.exchange.formats import by_module
from facegen.face.mesh import Mesh

FORMAT = by_module(__name__)


def write(anim: Animation, path: str | os.PathLike, *, write_audio: bool = True,
          audio_source: str | os.PathLike | None = None, **usd_options) -> list[Path]:
    """Write `anim` as a .usdz package: the .usdc stage (`usd_options` as usd.write: mode, morph_targets,
    tolerance, meters_per_unit) with its WAV inside.

    Returns [path]: the package is the only file. `audio_source` is accepted for the common writer
    signature; nothing is written beside the package, so the input audio is never touched.
    """
    from pxr import Sdf, UsdUtils

    del audio_source  # the audio goes inside the package; no file beside it can be overwritten
    path = Path(path)
    if path.suffix.lower() not in FORMAT.extensions:
        raise FacegenError(f"{path} is not a USDZ file name: use {', '.join(FORMAT.extensions)}")
    with Transaction() as transaction:
        tmp = transaction.file(path)
        stage_file = transaction.scratch(path) / f"{path.stem}.usdc"  # marked: a killed run's is cleaned
        with Transaction(join=False):  # the stage's files are in place in the scratch folder before packing
            usd.write(anim, stage_file, write_audio=write_audio, **usd_options)
        made = UsdUtils.CreateNewUsdzPackage(Sdf.AssetPath(str(stage_file)), str(tmp))
        if not made or not tmp.is_file():
            raise FacegenError(f"cannot write the USDZ package {path}: check free disk space and permissions")
    return [path]


def read(path: str | os.PathLike, template: Mesh | None = None, fps: float | None = None) -> Animation:
    """Read a .usdz package written by facegen (or any USDZ holding one animated face mesh)."""
    return usd.read(path, template=template, fps=fps)


def contents(path: str | os.PathLike) -> list[str]:
    """The file names inside a .usdz package, in package order (the root layer first); an unreadable
    package is a FacegenError."""
    from pxr import Sdf

    package = Sdf.ZipFile.Open(str(path))
    if package is None:
        raise FacegenError(f"{path} is not a readable zip package: write it again")
    return list(package.GetFileNames())
