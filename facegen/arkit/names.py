"""The names of ARKit's 52 face blend shapes, and how names in other files map to them.

ARKit (ARFaceAnchor.BlendShapeLocation) names the shapes in lowerCamel (`eyeBlinkLeft`); Audio2Face's JSON
uses the same names; Epic's Live Link Face CSV uses UpperCamel (`EyeBlinkLeft`) and adds nine head and eye
rotation columns. "Left" is the character's own left (+x on facegen's face, which looks down +z).
"""

from __future__ import annotations

import re

# in the order of Live Link Face's network protocol (the FaceBlendShape index)
ARKIT_NAMES: tuple[str, ...] = (
    "eyeBlinkLeft", "eyeLookDownLeft", "eyeLookInLeft", "eyeLookOutLeft", "eyeLookUpLeft", "eyeSquintLeft",
    "eyeWideLeft", "eyeBlinkRight", "eyeLookDownRight", "eyeLookInRight", "eyeLookOutRight", "eyeLookUpRight",
    "eyeSquintRight", "eyeWideRight", "jawForward", "jawLeft", "jawRight", "jawOpen", "mouthClose",
    "mouthFunnel", "mouthPucker", "mouthLeft", "mouthRight", "mouthSmileLeft", "mouthSmileRight",
    "mouthFrownLeft", "mouthFrownRight", "mouthDimpleLeft", "mouthDimpleRight", "mouthStretchLeft",
    "mouthStretchRight", "mouthRollLower", "mouthRollUpper", "mouthShrugLower", "mouthShrugUpper",
    "mouthPressLeft", "mouthPressRight", "mouthLowerDownLeft", "mouthLowerDownRight", "mouthUpperUpLeft",
    "mouthUpperUpRight", "browDownLeft", "browDownRight", "browInnerUp", "browOuterUpLeft",
    "browOuterUpRight",
    "cheekPuff", "cheekSquintLeft", "cheekSquintRight", "noseSneerLeft", "noseSneerRight", "tongueOut",
)

# Live Link Face CSV: Timecode, BlendShapeCount, the 52 shapes in UpperCamel, then these rotations (radians)
LIVE_LINK_ROTATIONS: tuple[str, ...] = ("HeadYaw", "HeadPitch", "HeadRoll", "LeftEyeYaw", "LeftEyePitch",
                                        "LeftEyeRoll", "RightEyeYaw", "RightEyePitch", "RightEyeRoll")


def live_link_name(name: str) -> str:
    """ARKit's lowerCamel name as Live Link Face's CSV column (`eyeBlinkLeft` -> `EyeBlinkLeft`)."""
    return name[0].upper() + name[1:]


def _csv_order(names: tuple[str, ...]) -> tuple[str, ...]:
    """The app's CSV lists JawRight before JawLeft and MouthRight before MouthLeft."""
    out = list(names)
    for left, right in (("jawLeft", "jawRight"), ("mouthLeft", "mouthRight")):
        i, j = out.index(left), out.index(right)
        out[i], out[j] = out[j], out[i]
    return tuple(out)


LIVE_LINK_COLUMNS: tuple[str, ...] = (("Timecode", "BlendShapeCount")
                                      + tuple(live_link_name(n) for n in _csv_order(ARKIT_NAMES))
                                      + LIVE_LINK_ROTATIONS)

_KEY = {n.lower(): n for n in ARKIT_NAMES}
_PREFIX = re.compile(r"^(?:.*[.:|/])|^(?:arkit|blendshape\d*|bs|facs)[_\-. ]+", re.IGNORECASE)


def arkit_name(name: str) -> str | None:
    """The ARKit shape a shape key / morph target called `name` stands for, or None: case-insensitive, with
    common prefixes stripped (`blendShape1.eyeBlinkLeft`, `ARKit_JawOpen`, `Face:mouthClose`) and `_L`/`_R`
    suffixes read as Left/Right (`mouthSmile_L`)."""
    key = _PREFIX.sub("", name.strip())
    key = re.sub(r"(?:[_\-. ]|(?<=[a-z]))(L|R)$", lambda m: "Left" if m.group(1) == "L" else "Right", key)
    return _KEY.get(key.replace("_", "").lower())
