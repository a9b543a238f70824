"""Checks on written animation assets: `validate(path) -> Report`, one checker module per format.

Each check has a name, ok, a one-line detail and a severity. An "error" check that fails makes the report
fail; a "warning" is shown but never fails it. The format table (exchange/formats.py) names each format's
checker module here (usd.py for USD and USDZ, npy.py, gltf.py, arkit.py for the ARKit weight files: Audio2Face
JSON and Live Link Face CSV); each has `check(report, path, expected)`,
and the checks they share are in checks.py.
"""

from __future__ import annotations

import importlib
import os
from pathlib import Path
from typing import TYPE_CHECKING

from facegen.errors import FacegenError
from facegen.exchange import extensions, format_of
from facegen.validate.report import DEFAULT_MAX_DISPLACEMENT, Expected, Report

if TYPE_CHECKING:
    from facegen.animation import Animation
    from facegen.face.mesh import Mesh

def validate(
    path: str | os.PathLike,
    template: Mesh | None = None,
    fps: float | None = None,
    audio_path: str | os.PathLike | None = None,
    *,
    require_audio: bool = True,
    max_displacement: float = DEFAULT_MAX_DISPLACEMENT,
    reference: str | os.PathLike | Animation | None = None,
) -> Report:
    """Check an animation file written by facegen (or any file of the same layout); never raises for
    a bad file: every problem is a failed check in the returned Report. `reference` (glTF only): the
    source animation the file's morph targets must reproduce within its stated tolerance."""
    path = Path(path)
    report = Report(str(path))
    try:
        checker = importlib.import_module(format_of(path).validator)
    except FacegenError:
        suffix = path.suffix.lower()
        report.add("file", False, f"cannot validate {suffix or 'files without extension'}: "
                                  f"use one of {', '.join(extensions())}")
        return report
    expected = Expected(template, fps, audio_path, require_audio, max_displacement, reference)
    checker.check(report, path, expected)
    return report
