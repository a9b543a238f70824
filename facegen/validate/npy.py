"""Checks on .npy animations ([T, 3V] float arrays, exchange/npy.py), added to a Report:

  file            a [T, 3V] float array, no pickles
  template        the template given, else the built-in model's face when the vertex count is its
                  (.npy files store no faces or rest pose)
  vertex count    every frame has the template's vertex count
  finite, displacement, audio (the WAV sidecar, or `audio_path`), audio duration   as in checks.py
"""

from __future__ import annotations

from pathlib import Path

from facegen.animation import DEFAULT_FPS
from facegen.exchange import npy as npy_format
from facegen.exchange.wav import sidecar_path
from facegen.validate.checks import check_duration, check_values, open_file, read_audio
from facegen.validate.report import Expected, Report


def check(report: Report, path: Path, expected: Expected) -> None:
    """Add the .npy checks for `path` to `report`; never raises for a bad file."""
    template = expected.template
    data = open_file(report, npy_format.load_frames, path)
    if data is None:
        return
    report.add("file", True, f"[{data.shape[0]}, {data.shape[1]}] {data.dtype} array")
    num_vertices = data.shape[1] // 3
    if template is None:  # what `facegen animate` writes with the default model: its face
        from facegen.bundle import read_template

        template = read_template(None)
        if num_vertices != template.num_vertices:
            report.add("template", False, f".npy files store no faces or rest pose, and {num_vertices} "
                       "vertices per frame are not the built-in model's face: pass the template mesh")
            return
        report.add("template", True, "the built-in model's face (the vertex count matches)")
    same = num_vertices == template.num_vertices
    report.add(
        "vertex count",
        same,
        f"{num_vertices} vertices per frame"
        + (" (the template's)" if same else f", the template has {template.num_vertices}"),
    )
    frames = data.reshape(len(data), num_vertices, 3) if same else []
    check_values(report, frames, None, template, expected.max_displacement)
    audio = None
    wav = Path(expected.audio_path) if expected.audio_path is not None else sidecar_path(path)
    if wav.is_file():
        audio = read_audio(report, "audio", wav, str(wav))
    else:
        report.add(
            "audio", not expected.require_audio,
            f"no audio file {wav}" + ("" if expected.require_audio else " (not required)"),
        )
    fps = expected.fps if expected.fps is not None else DEFAULT_FPS
    check_duration(report, len(data), float(fps), audio, expected.require_audio)
