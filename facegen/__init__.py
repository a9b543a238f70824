"""facegen: speech (audio + transcript) to expressive 3D face animation.

The library API, imported lazily (``import facegen`` stays light, so ``facegen --help`` is fast)::

    import facegen

    anim = facegen.animate("line.wav", text="What an excellent room you have, sir.", speaker="F2")
    facegen.write_animation(anim, "line.usdc")          # any of facegen.exchange.extensions()
    again = facegen.read_animation("line.usdc")
    bundle = facegen.load_bundle()                       # the built-in model (or a path to your own)
    facegen.animate("line.wav", reporter=facegen.Reporter(progress=print, note=print))  # say what it does
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

__version__ = "0.1.0"

_API = {
    "animate": "facegen.animator",
    "Animator": "facegen.animator",
    "load_bundle": "facegen.bundle",
    "Animation": "facegen.animation",
    "read_animation": "facegen.exchange",
    "write_animation": "facegen.exchange",
    "FacegenError": "facegen.errors",
    "Reporter": "facegen.runtime",
}
__all__ = ["Animation", "Animator", "FacegenError", "Reporter", "__version__", "animate", "load_bundle",
           "read_animation", "write_animation"]

if TYPE_CHECKING:
    from facegen.animation import Animation
    from facegen.animator import Animator, animate
    from facegen.bundle import load_bundle
    from facegen.errors import FacegenError
    from facegen.exchange import read_animation, write_animation
    from facegen.runtime import Reporter


def __getattr__(name: str):
    if name in _API:
        value = getattr(importlib.import_module(_API[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'facegen' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_API))
