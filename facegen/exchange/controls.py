"""What each output format carries of the run's controls, and the warning when it cannot carry one asked for.

`CONTROLS` is the one table: a row per control (`--blink-rate`, `--seed`, `--head-motion`, `--emotion`,
`--strength`, `--fps`, and the gaze and parts that have no flag), a cell per format of exchange/formats.py
saying how its files carry it. docs/dcc.md shows it (`markdown_table()`; tests/test_cli_controls.py checks
the two agree).

Where a format cannot hold what a control asked for, the row has a `Loss` for that format: `dropped(path,
controls)` gives one warning line per control whose value was asked for (not its default) and is lost there,
naming the control, the format and what to do instead. `facegen animate` says them before writing, `facegen
batch` once per run. The lines, exactly as they were measured true of the writers:

- .npy and `--fps` other than 25: the file holds no frame rate; facegen (render, validate, read_animation)
  reads it at 25 unless told.
- .npy and `--head-motion` other than 0 and 1: the file holds vertex positions only (face-local); the head's
  angles go beside it as NAME.head.npy (exchange/npy.py).
- .csv and a fractional `--fps` (29.97): the file holds no frame rate and its timecodes count whole frames
  within each second, so readers that take the rate from them (facegen's Blender helper) get a whole number.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from facegen.animation import DEFAULT_FPS
from facegen.blinks import DEFAULT_RATE
from facegen.exchange.formats import FORMATS, format_of
from facegen.head import DEFAULT_AMOUNT


@dataclass(frozen=True)
class Loss:
    """A control a format cannot carry: `when(value)` is True for the values it loses; `says` is the warning,
    formatted with flag, value, file (the output's name) and head (its NAME.head.npy)."""

    when: Callable[[object], bool]
    says: str


@dataclass(frozen=True)
class Control:
    """A control of a run: its library parameter `name` (facegen.animate, batch; a manifest column where
    there is one), its command-line `flag` ("" when always on), its `default` (a value not asked for), how
    each format carries it (`carried`: format name -> text) and where it is lost (`lost`)."""

    name: str
    flag: str
    default: object
    carried: dict[str, str]
    lost: dict[str, Loss] = field(default_factory=dict)


def _cells(mesh: str, arkit: str, **own: str) -> dict[str, str]:
    """A row's cells: `mesh` for the mesh formats, `arkit` for the ARKit weight files, `own` by format name
    with spaces as underscores (Live_Link_Face_CSV)."""
    cells = {f.name: arkit if f.arkit else mesh for f in FORMATS}
    cells.update({name.replace("_", " "): text for name, text in own.items()})
    return cells


_RECORDED = "; recorded in the metadata"
CONTROLS: tuple[Control, ...] = (
    Control("blink_rate", "--blink-rate", DEFAULT_RATE, _cells("the lids' vertices", "eyeBlinkLeft/Right")),
    Control("seed", "--seed", 0, _cells("same seed, same file", "same seed, same file")),
    Control("head_motion", "--head-motion", DEFAULT_AMOUNT, _cells(
        "/Face's xformOp:rotateZXY:head samples", "",
        glTF="node Head's rotation channel",
        NumPy="beside it: NAME.head.npy ([T, 3] yaw, pitch, roll degrees); the .npy stays face-local",
        Audio2Face_JSON="the extra key facegenHead (read by examples/threejs and facegen's Blender helper "
                        "with `--head OBJECT`; Audio2Face importers ignore it)",
        Live_Link_Face_CSV="HeadYaw, HeadPitch, HeadRoll (radians)"),
        {"NumPy": Loss(lambda v: v != 0,
                       ".npy holds vertex positions only: {flag} {value} is written beside it, to {head} "
                       "([T, 3] yaw, pitch, roll degrees); .usd*, .glb, .json and .csv carry the head in the "
                       "file")}),
    Control("emotion", "--emotion", None, _cells(
        "the vertices" + _RECORDED, "the weights (brows, smiles, ...)" + _RECORDED,
        NumPy="the vertices (not recorded)", Live_Link_Face_CSV="the weights (not recorded)")),
    Control("strength", "--strength", None, _cells(
        "the vertices" + _RECORDED, "the weights" + _RECORDED,
        NumPy="the vertices (not recorded)", Live_Link_Face_CSV="the weights (not recorded)")),
    Control("fps", "--fps", None, _cells(
        "timeCodesPerSecond", "",
        glTF="key times in seconds; asset.extras.facegen.fps",
        NumPy="not stored: read at 25 unless told (--fps of render, validate)",
        Audio2Face_JSON="exportFps",
        Live_Link_Face_CSV="in the timecodes only, which count whole frames in each second (a fractional "
                           "rate is lost)"),
        {"NumPy": Loss(lambda v: v != DEFAULT_FPS,
                       ".npy holds no frame rate: {flag} {value} is not stored in {file}, which facegen "
                       "reads at 25 fps; read it with --fps {value} (render, validate) or write .usd*, .glb "
                       "or .json, which store it"),
         "Live Link Face CSV": Loss(lambda v: not float(v).is_integer(),
                                    ".csv holds no frame rate and its timecodes count whole frames: readers "
                                    "that take the rate from them get {whole} fps from {file}, not {flag} "
                                    "{value}; set {value} fps where you import it, or write .json (exportFps)"
                                    )}),
    Control("gaze", "", None, _cells(
        "the eyeballs' vertices turn; the LeftEye and RightEye parts too", "eyeLook* (In, Out, Up, Down)",
        NumPy="the eyeballs' vertices turn",
        Live_Link_Face_CSV="eyeLook* and LeftEye/RightEye yaw, pitch (radians)")),
    Control("parts", "", None, _cells(
        "/Face/LeftEye, RightEye, UpperTeeth, LowerTeeth, Tongue (prims, materials)",
        "the tongue as tongueOut (0.5 at a th); the eyes as eyeLook*; the teeth follow jawOpen",
        glTF="nodes LeftEye ... Tongue under Face (meshes, materials, channels)",
        NumPy="none: the 23,370-vertex face only")),
)


def _shown(value: object) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def dropped(path: str | os.PathLike, controls: dict[str, object]) -> list[str]:
    """One warning line (without "facegen: warning: ") per control in `controls` (library name -> value)
    that was asked for (a value other than its default) and that the format of `path` cannot carry, in
    table order; [] when the format carries them all."""
    from facegen.exchange.npy import head_path

    path = Path(path)
    fmt = format_of(path)
    lines = []
    for control in CONTROLS:
        loss = control.lost.get(fmt.name)
        value = controls.get(control.name, control.default)
        if loss is None or value is None or value == control.default or not loss.when(value):
            continue
        # {whole}: the frames a second a fractional rate's timecodes count (.csv)
        whole = math.ceil(value) if isinstance(value, int | float) and math.isfinite(value) else value
        lines.append(loss.says.format(flag=control.flag, value=_shown(value), file=path.name,
                                      head=head_path(path).name, whole=whole))
    return lines


def markdown_table() -> str:
    """The table as docs/dcc.md shows it: a row per control, a column per format."""
    head = "| control | " + " | ".join(f"{f.name} ({', '.join(f.extensions)})" for f in FORMATS) + " |"
    lines = [head, "|" + " --- |" * (len(FORMATS) + 1)]
    for control in CONTROLS:
        name = f"`{control.flag}`" if control.flag else control.name + " (always on)"
        cells = [control.carried[f.name] + (" **(warns)**" if f.name in control.lost else "")
                 for f in FORMATS]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
