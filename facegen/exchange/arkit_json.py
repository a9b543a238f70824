"""Audio2Face blend-shape JSON: the animation as ARKit's 52 shape weights per frame (arkit/solve.py's fit).

The layout is NVIDIA Audio2Face's blend-shape export, which ARKit-aware importers (Blender add-ons, three.js
and Babylon.js loaders, Unreal plug-ins) read by key:

    {"exportFps": 25, "trackPath": "clip.wav", "numPoses": 52, "numFrames": T,
     "facsNames": ["eyeBlinkLeft", ...],            ARKit's lowerCamel names, in ARKit's order
     "weightMat": [[52 weights in [0, 1]], ...],     one row per frame
     "facegen": {"version", "model", "lip_error_mm", "face_error_mm", "audio"}}

`trackPath` names the audio track as Audio2Face does (here the WAV sidecar beside the file, "" without audio);
the extra "facegen" key holds the fit's reconstruction errors and where the weights came from. Weights are
rounded to 5 decimals (1e-5 of the full range) to keep the file small.
`write_fitted` (fit, text, WAV sidecar, atomically) is shared with the Live Link Face CSV (arkit_csv.py).
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

import numpy as np

from facegen import __version__
from facegen.animation import Animation, check_animation
from facegen.arkit.solve import Fit, fit_arkit
from facegen.exchange.wav import atomic_with_sidecar

DECIMALS = 5


def write(anim: Animation, path: str | os.PathLike, *, write_audio: bool = True,
          audio_source: str | os.PathLike | None = None) -> list[Path]:
    """Fit the ARKit weights of `anim` and write them as Audio2Face JSON with, when there is audio, a WAV
    sidecar; return the files. A template without the rig's regions is a FacegenError (nothing written)."""
    return write_fitted(anim, path, _document, write_audio, audio_source)


def write_fitted(anim: Animation, path: str | os.PathLike,
                 text: Callable[[Animation, Fit, str], str | Iterable[str]], write_audio: bool,
                 audio_source: str | os.PathLike | None) -> list[Path]:
    """Fit the ARKit weights of `anim`, write `text(anim, fit, audio track name or "")` (the text, or its
    parts in order) to `path` and the audio as a WAV sidecar, atomically; return the files. Shared by the
    ARKit weight formats (JSON, CSV)."""
    check_animation(anim)
    fit = fit_arkit(anim)
    path = Path(path)
    audio = anim.audio if write_audio and anim.audio is not None and len(anim.audio) else None
    with atomic_with_sidecar(path, audio, anim.sample_rate, audio_source) as (tmp, wav):
        parts = text(anim, fit, wav.name if wav is not None else "")
        with open(tmp, "w", encoding="utf-8") as file:
            file.writelines([parts] if isinstance(parts, str) else parts)
    return [path] if wav is None else [path, wav]


ROWS = 4096  # weightMat rows turned into text at a time: a long clip's rows never exist as Python floats


# the run's controls, kept in the "facegen" block
CONTROLS = ("language", "blinks", "emotion", "emotion_spans", "strength", "head_motion")


def _document(anim: Animation, fit: Fit, track: str) -> Iterator[str]:
    """The JSON text in parts: the text of json.dumps, with weightMat's rows made a block at a time."""
    doc = {
        "exportFps": int(anim.fps) if float(anim.fps).is_integer() else float(anim.fps),
        "trackPath": track,
        "numPoses": len(fit.names),
        "numFrames": len(fit.weights),
        "facsNames": list(fit.names),
        "weightMat": [],
        "facegen": {
            "version": __version__,
            "model": anim.metadata.get("model"),
            "lip_error_mm": round(fit.lip_error_mm, 4),
            "face_error_mm": round(fit.face_error_mm, 4),
            "audio": track or None,
            **{k: anim.metadata[k] for k in CONTROLS if k in anim.metadata},
        },
        **({} if anim.head is None else {"facegenHead": {
            "angles": ["yaw", "pitch", "roll"], "units": "degrees", "order": "Ry(yaw) Rx(pitch) Rz(roll)",
            "pivot": [round(float(x), 6) for x in anim.head_pivot],
            "values": np.asarray(anim.head, np.float64).round(3).tolist()}}),
    }
    head, tail = json.dumps(doc, separators=(",", ":")).split('"weightMat":[]')
    yield head + '"weightMat":['
    for start in range(0, len(fit.weights), ROWS):
        rows = fit.weights[start:start + ROWS].astype(np.float64).round(DECIMALS).tolist()
        yield ("," if start else "") + json.dumps(rows, separators=(",", ":"))[1:-1]
    yield "]" + tail + "\n"
