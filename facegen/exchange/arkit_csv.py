"""Live Link Face CSV: the animation as ARKit's 52 shape weights per frame (arkit/solve.py's fit), in the
layout Epic's Live Link Face app records and Unreal's LiveLinkFaceImporter, Maya/Blender importers read.

    Timecode,BlendShapeCount,EyeBlinkLeft,...,TongueOut,HeadYaw,HeadPitch,HeadRoll,LeftEyeYaw,...,RightEyeRoll
    00:00:00:00.000,61,0.00000,...

The columns are `facegen.arkit.names.LIVE_LINK_COLUMNS` (the weights are placed by name); one row per frame:
the timecode `HH:MM:SS:FF.mmm` (FF: the frame within its second at the clip's fps, the sub-frame part .000),
BlendShapeCount 61 (the 52 shapes and 9 rotations, as the app writes), the weights in [0, 1] and the head
and eye rotations in radians (facegen.head's head motion, facegen.gaze's gaze). The file holds no fps: readers
take it from the timecodes or ask. The audio goes beside the file as a WAV sidecar.
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path

import numpy as np

from facegen.animation import Animation
from facegen.arkit.names import LIVE_LINK_COLUMNS, LIVE_LINK_ROTATIONS, arkit_name
from facegen.arkit.solve import Fit
from facegen.exchange.arkit_json import write_fitted

TIMECODE = re.compile(r"^(\d{2,3}):(\d{2}):(\d{2}):(\d{2,3})(?:\.(\d{1,9}))?$")  # bounded: no 10**400


def timecode(frame: int, fps: float) -> str:
    """Live Link Face's `HH:MM:SS:FF.mmm` for `frame` at `fps` (FF counts the frames within the second)."""
    second = math.floor(frame / fps + 1e-9)
    within = frame - math.ceil(second * fps - 1e-9)
    return f"{second // 3600:02d}:{second // 60 % 60:02d}:{second % 60:02d}:{within:02d}.000"


def parse_timecode(text: str) -> tuple[int, int, float] | None:
    """(whole seconds, frame within the second, sub-frame fraction) of a timecode, or None if malformed."""
    m = TIMECODE.match(text.strip())
    if m is None:
        return None
    hours, minutes, seconds, frame, sub = m.groups()
    return int(hours) * 3600 + int(minutes) * 60 + int(seconds), int(frame), float(f"0.{sub or 0}")


def write(anim: Animation, path: str | os.PathLike, *, write_audio: bool = True,
          audio_source: str | os.PathLike | None = None) -> list[Path]:
    """Fit the ARKit weights of `anim` and write them as Live Link Face CSV with, when there is audio, a WAV
    sidecar; return the files. A template without the rig's regions is a FacegenError (nothing written)."""
    return write_fitted(anim, path, _table, write_audio, audio_source)


def _table(anim: Animation, fit: Fit, track: str) -> str:
    shapes = LIVE_LINK_COLUMNS[2 : len(LIVE_LINK_COLUMNS) - len(LIVE_LINK_ROTATIONS)]
    order = [fit.names.index(arkit_name(column)) for column in shapes]
    count = len(shapes) + len(LIVE_LINK_ROTATIONS)
    weights = np.char.mod("%.5f", fit.weights[:, order].astype(np.float64))
    rotations = np.char.mod("%.5f", _rotations(anim, len(weights)))
    lines = [",".join(LIVE_LINK_COLUMNS)]
    lines += [f"{timecode(t, anim.fps)},{count},{','.join(row)},{','.join(turn)}"
              for t, (row, turn) in enumerate(zip(weights, rotations, strict=True))]
    return "\n".join(lines) + "\n"


def _rotations(anim: Animation, frames: int) -> np.ndarray:
    """The LIVE_LINK_ROTATIONS columns [frames, 9] in radians: the head's yaw, pitch, roll (facegen.head's
    angles) and the eyes' yaw (+ toward the character's left) and pitch (+ up) from the animation's saccades
    (facegen.gaze), both eyes alike, no eye roll."""
    from facegen.gaze import Saccade, gaze_curve

    out = np.zeros((frames, len(LIVE_LINK_ROTATIONS)))
    if anim.head is not None:
        head = np.radians(np.asarray(anim.head, np.float64)[:frames])
        for k, name in enumerate(("HeadYaw", "HeadPitch", "HeadRoll")):
            out[:len(head), LIVE_LINK_ROTATIONS.index(name)] = head[:, k]
    found = [Saccade(*s) for s in anim.metadata.get("saccades") or []]
    if found:
        gaze = np.radians(gaze_curve(found, frames, anim.fps).astype(np.float64))
        for side in ("Left", "Right"):
            out[:, LIVE_LINK_ROTATIONS.index(f"{side}EyeYaw")] = gaze[:, 0]
            out[:, LIVE_LINK_ROTATIONS.index(f"{side}EyePitch")] = gaze[:, 1]
    return out
