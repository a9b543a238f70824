"""The class of every facegen command: it says a library error in the command's own flags.

The library's FacegenError names the parameter a problem is about (`param`, e.g. "text" or "bundle"), never
a flag; the command that ran it knows which of its options or arguments gives that parameter, and adds them
to the message: "the transcript is empty: pass the words spoken (--text or --text-file)".
"""

from __future__ import annotations

import click

from facegen.errors import FacegenError

# library parameter -> the names of the click parameters that give it, where the two names differ
GIVEN_BY: dict[str, tuple[str, ...]] = {
    "text": ("text", "text_file"),
    "bundle": ("model",),
    "text_model_path": ("text_model",),
    "mode": ("usd_mode",),
    "clips": ("usd_clips",),
    "out_bundle": ("output",),
    "plots_dir": ("plots",),
    "speakers": ("subjects",),
}


def spelling(param: click.Parameter) -> str:
    """How a user writes a click parameter: its long flag (--text-model), or an argument's name (BUNDLE)."""
    if isinstance(param, click.Option):
        return max(param.opts, key=lambda o: o.startswith("--"))
    return (param.metavar or param.name or "").upper()


def flags_for(command: click.Command, names: tuple[str, ...],
              given_by: dict[str, tuple[str, ...]]) -> list[str]:
    """How the command's user writes each library parameter in `names` ("--text or --text-file"); a
    parameter the command has no option or argument for is left out."""
    own = {p.name: p for p in command.params}
    said = []
    for name in names:
        found = [spelling(own[c]) for c in given_by.get(name, GIVEN_BY.get(name, ())) if c in own]
        if not found and name in own:
            found = [spelling(own[name])]
        if found:
            said.append(" or ".join(found))
    return said


def with_flags(exc: FacegenError, command: click.Command, given_by: dict[str, tuple[str, ...]]) -> str:
    """The error's message with the command's flags for its parameters, as the CLI prints it."""
    flags = flags_for(command, exc.params, given_by)
    return f"{exc} ({', '.join(flags)})" if flags else str(exc)


class Command(click.Command):
    """A facegen command: a FacegenError it raises is said with the command's flags for its parameters.

    `given_by` maps a library parameter to this command's click parameter names where they differ beyond
    GIVEN_BY (train's `output`, the output layer, is given by `output_layer`).
    """

    def __init__(self, *args, given_by: dict[str, tuple[str, ...]] | None = None, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.given_by = given_by or {}

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except FacegenError as exc:
            if exc.params and not getattr(exc, "flags_added", False):
                exc.args = (with_flags(exc, self, self.given_by),)  # the line facegen prints, --debug's too
                exc.flags_added = True
            raise
