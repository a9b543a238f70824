"""The "rig" check shared by the glTF and USD-blendshapes checkers: which shapes the file's targets are.

  rig   the morph targets / blend shapes by name: ARKit shapes (their names through facegen.arkit.names, so
        `blendShape1.jawOpen` or `ARKit_JawOpen` count), every one found listed — all 52 expected, the
        missing ones listed (a warning) — with the fit's stated mean errors (lip vertices and whole face,
        mm) when the file has them; or another rig (facegen's PCA targets), counted
"""

from __future__ import annotations

from facegen.arkit.names import ARKIT_NAMES, arkit_name
from facegen.exchange.morph_targets import REST_SHAPE
from facegen.validate.report import Report

_SHOWN = 6  # names listed in the detail before "..."


def check_rig(report: Report, names: list[str], lip_error_mm=None, face_error_mm=None) -> None:
    """Add the "rig" check for targets called `names` (and the fit errors the file states, if any)."""
    shapes = [n for n in names if n != REST_SHAPE]
    found = {arkit_name(n) for n in shapes} - {None}
    if not found:
        report.add("rig", True, f"{len(shapes)} targets, none named as ARKit shapes "
                   f"({_listed(shapes)}): a PCA or custom rig")
        return
    missing = [n for n in ARKIT_NAMES if n not in found]
    errors = "; ".join(f"{what} {value:.3g} mm" for what, value in (("lip error", lip_error_mm),
                                                                    ("face error", face_error_mm))
                       if isinstance(value, int | float))
    detail = (f"ARKit: {len(found)} of {len(ARKIT_NAMES)} shapes "
              f"({', '.join(sorted(found, key=ARKIT_NAMES.index))})"
              + (f"; missing {_listed(missing)}" if missing else "")
              + (f"; the fit's mean {errors}" if errors else ""))
    report.add("rig", not missing, detail, "warning")


def _listed(names: list[str]) -> str:
    return ", ".join(names[:_SHOWN]) + (f", ... ({len(names)} in all)" if len(names) > _SHOWN else "")
