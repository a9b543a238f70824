"""What the commands share: option types, callbacks and the checks every command makes the same way.

Only click and light facegen modules are imported here; a helper that needs more imports it inside.
"""

from __future__ import annotations

import math
from pathlib import Path

import click

from facegen.errors import FacegenError


class FiniteRange(click.FloatRange):
    """A float range that also refuses nan and inf (click's FloatRange lets nan through)."""

    def convert(self, value, param, ctx):
        number = super().convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{number} is not a finite number", param, ctx)
        return number


FPS = FiniteRange(0, 1000, min_open=True)
WEIGHT = FiniteRange(0, 1e6)
DEVICE = click.Choice(["auto", "cpu", "cuda"])


def protect_inputs(outputs: list, **inputs) -> None:
    """Refuse an output path that names one of the command's input files (it would be overwritten)."""
    from facegen.exchange.wav import is_same_file

    for out in outputs:
        for name, path in inputs.items():
            if out and path and (Path(out).resolve() == Path(path).resolve() or is_same_file(path, out)):
                raise FacegenError(f"{out} is the {name} file this command reads: writing it would destroy "
                                   "an input; choose another output name")


def read_text(text: str | None, text_file: str | None) -> str | None:
    """The transcript given inline (--text) or read from a UTF-8 file (--text-file): a regular file of at
    most input_files.TRANSCRIPT_BYTES (a FIFO, a device or a larger file is refused at once)."""
    if text_file is None:
        return text
    from facegen.input_files import TRANSCRIPT_BYTES, read_input_text

    return read_input_text(text_file, what="transcript file", limit=TRANSCRIPT_BYTES,
                           fix="pass a UTF-8 text file", param="text",
                           too_big="split the recording and its transcript into parts")


def one_of(**options) -> None:
    """Refuse more than one of the given sources of words (keyword names are the flags' names)."""
    given = [k for k, v in options.items() if v]
    if len(given) > 1:
        names = " and ".join("--" + k.replace("_", "-") for k in given)
        raise FacegenError(f"{names} cannot be used together: give only one source of words")


def morph_targets_option(_ctx, _param, value: str | None) -> int | str | None:
    """--morph-targets K|all, parsed by the library (callback)."""
    from facegen.exchange.pca import parse_morph_targets

    return parse_morph_targets(value)


def usd_clips_option(_ctx, _param, value: str | None) -> int | str | None:
    """--usd-clips auto|never|N, parsed by the library (callback)."""
    from facegen.exchange.usd_clips import parse_clips

    return parse_clips(value)


def split_options(f):
    """The five options that choose a dataset split's subjects and sentences (train, evaluate)."""
    for opt in reversed([
        click.option("--train-subjects", help="Training subjects, e.g. F2,F3,F4,M3,M4,M5 (the default)."),
        click.option("--test-subjects", help="Test-B subjects (default: F1,F5,F6,F7,F8,M1,M2,M6)."),
        click.option("--train-sentences", help="Training sentences, e.g. 1-32 (the default)."),
        click.option("--val-sentences", help="Validation sentences (default 33-36)."),
        click.option("--test-sentences", help="Test sentences (default 37-40)."),
    ]):
        f = opt(f)
    return f


def splits(train_subjects, test_subjects, train_sentences, val_sentences, test_sentences):
    """The dataset Splits that split_options' values describe."""
    from facegen.datasets.splits import Splits

    return Splits.from_options(train_subjects, test_subjects, train_sentences, val_sentences, test_sentences)
