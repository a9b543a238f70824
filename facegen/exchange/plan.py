"""The write plan: one checked decision of how an animation file is written, made before any work.

    plan = plan_write("out.usdc", options={"rig": "arkit"}, template=mesh, audio_source="clip.wav")
    anim = ...  # plan.streams: the writer reads frames block by block, so a FrameStream will do
    plan.write(anim)  # -> [out.usdc, out.wav]: all files or none (one facegen.atomic.Transaction)

`plan_write` refuses, as one FacegenError, everything that can be known from the path, the options and the
template: an unknown extension, an unwritable folder or name, an unwritable sidecar WAV (unless it is the
input audio, which is kept and referenced), options the format does not take, an unknown rig, a template
without the ARKit rig's regions. It settles what follows from them (USD writes the ARKit rig as UsdSkel blend
shapes) and whether the writer streams. The CLI, batch and `write_animation` all write through a plan; what a
format can do is its row in exchange/formats.py, so nothing here tests a suffix.

A preview video (or any other file) joins the asset's transaction when written inside one:

    with Transaction():
        plan.write(anim)
        render_animation(anim, plan.preview)
"""

from __future__ import annotations

import importlib
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from facegen.atomic import Transaction, check_writable
from facegen.exchange.formats import Format, check_write_options, format_of, import_writer

if TYPE_CHECKING:
    from facegen.animation import Animation
    from facegen.face.mesh import Mesh


@dataclass(frozen=True)
class WritePlan:
    """How one animation file is written: its format, its checked options, the files it makes."""

    path: Path
    format: Format
    options: dict = field(default_factory=dict)  # the writer's keyword options (checked; defaults settled)
    audio_source: Path | None = None  # the input audio: never overwritten (referenced when it is the sidecar)
    sidecar: Path | None = None  # the WAV written beside the asset (None: the format writes none, or it is
    #                              the input audio itself)
    preview: Path | None = None  # a preview video written with the asset (by the caller, in one transaction)
    streams: bool = False  # the writer reads the frames block by block: the animation may be a FrameStream
    rig: str | None = None  # "arkit" when the files hold the ARKit shapes or weights

    @property
    def outputs(self) -> list[Path]:
        """Every path the plan may write (the asset, its sidecar, the preview): none may be an input."""
        return [p for p in (self.path, self.sidecar, self.preview) if p is not None]

    def import_writer(self) -> None:
        """Import the writer and the libraries it needs (e.g. while the clip is being prepared)."""
        import_writer(self.path)

    def check_template(self, template: Mesh) -> None:
        """Refuse a template the plan's rig cannot be written for (ARKit: without the rig's regions), before
        any work; `plan_write(..., template=)` does it when the template is known then."""
        if self.rig == "arkit":
            from facegen.exchange.morph_targets import check_rig

            check_rig(self.rig, template)

    def write(self, anim: Animation) -> list[Path]:
        """Write `anim`; return the files written (the asset first). All of them or none: the writer stages
        every file in one Transaction (joining the one open around this call, if any)."""
        module = importlib.import_module(self.format.module)
        with Transaction():
            return module.write(anim, self.path, audio_source=self.audio_source, **self.options)


def plan_write(
    path: str | os.PathLike,
    *,
    options: dict | None = None,
    template: Mesh | None = None,
    audio_source: str | os.PathLike | None = None,
    preview: str | os.PathLike | None = None,
) -> WritePlan:
    """The checked plan for writing `path` with the format's `options` (see the module docstring).

    `template` is the face the animation will have: the ARKit rig's regions are checked on it; None leaves
    that check to `WritePlan.check_template` (e.g. once the model is loaded) or to the writer.
    `preview`: a video written with the asset: its folder is checked here, and the animation is then
    needed whole (no streaming); its own format is the renderer's to check.
    """
    from facegen.exchange.wav import is_same_file, sidecar_path

    path = Path(path)
    fmt = format_of(path)
    check_writable(path)
    options = dict(options or {})
    source = options.pop("audio_source", audio_source)
    source = Path(source) if source is not None else None
    sidecar = sidecar_path(path) if fmt.sidecar and options.get("write_audio", True) else None
    if sidecar is not None and is_same_file(source, sidecar):
        sidecar = None  # the input audio is the sidecar: kept and referenced
    if sidecar is not None:
        check_writable(sidecar)
    preview = Path(preview) if preview is not None else None
    if preview is not None:
        check_writable(preview)
    check_write_options(path, options)
    rig = _rig(fmt, options)
    streams = fmt.streams_with(options) and preview is None
    plan = WritePlan(path, fmt, options, source, sidecar, preview, streams, rig)
    if template is not None:
        plan.check_template(template)
    return plan


def _rig(fmt: Format, options: dict) -> str | None:
    """The rig the files hold ("arkit", "pca" or None: no morph targets); for ARKit, USD's default mode
    becomes blend shapes (in `options`), the only way USD carries the ARKit shapes."""
    rig = "arkit" if fmt.arkit else options.get("rig")
    if rig is None:
        return None
    from facegen.exchange.morph_targets import check_rig

    check_rig(rig)
    if rig == "arkit" and "mode" in fmt.options:
        options.setdefault("mode", "blendshapes")
    return rig
