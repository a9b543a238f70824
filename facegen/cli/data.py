"""`facegen data ...`: import the raw BIWI release, build the synthetic corpus."""

from __future__ import annotations

import re

import click

from facegen.cli.command import Command
from facegen.cli.options import FPS
from facegen.errors import FacegenError
from facegen.runtime import Reporter


@click.group()
def data():
    """Datasets: import the raw BIWI release, build the synthetic corpus."""


data.command_class = Command  # its subcommands say library errors with their flags too


@data.command("import-biwi")
@click.argument("raw", type=click.Path(file_okay=False))
@click.argument("out", type=click.Path(file_okay=False))
@click.option("--transcripts", type=click.Path(), help="Folder or file with the sentence transcripts.")
@click.option("--regions", type=click.Path(file_okay=False),
              help="Folder with lve.txt / fdd.txt region files.")
@click.option("--subjects", help="Only these subjects, e.g. F1,M2.")
@click.option("--quiet", "-q", is_flag=True)
def import_biwi(raw, out, transcripts, regions, subjects, quiet):
    """Convert the raw BIWI release RAW into the community layout in OUT."""
    from facegen.datasets.raw import import_biwi as run

    report = run(raw, out, transcripts=transcripts, regions=regions,
                 subjects=subjects.split(",") if subjects else None, reporter=Reporter.stderr(quiet))
    click.echo(report.summary())


@data.command("synth")
@click.argument("out", type=click.Path(file_okay=False))
@click.option("--subjects", help="Speakers to generate, e.g. F2,F3 (default: all 14).")
@click.option("--sentences", help="Sentences, e.g. 1-40 (default: 1-48).")
@click.option("--preset", type=click.Choice(["paper", "voices"]),
              help="paper: training speakers e01-e48 and test-B speakers e37-e48 only; voices: the "
                   "multi-voice corpus (24 voices of espeak-ng, Festival and Flite, augmented, 2,400 "
                   "sentences; Flite held out).")
@click.option("--limit", type=click.IntRange(min=1),
              help="voices: only this many sequences per split (a trial).")
@click.option("--languages",
              help="voices: the other languages besides English, e.g. fr,de,ru, or none (default: the 20 it "
                   "has voices for; nl, pl and tr are never among them: held out).")
@click.option("--seed", default=0, show_default=True)
@click.option("--fps", type=FPS, default=25.0, show_default=True)
@click.option("--workers", type=click.IntRange(1, 256), default=2, show_default=True)
@click.option("--quiet", "-q", is_flag=True)
def synth(out, subjects, sentences, preset, limit, languages, seed, fps, workers, quiet):
    """Generate a synthetic speech-and-motion corpus in OUT (BIWI layout)."""
    reporter = Reporter.stderr(quiet)
    if preset == "voices":
        from facegen.synth.voice_corpus import FPS as VOICES_FPS
        from facegen.synth.voice_corpus import build

        if subjects or sentences or fps != VOICES_FPS:
            raise FacegenError("--subjects, --sentences and --fps do not apply to --preset voices: drop them")
        if workers < 1:
            raise FacegenError(f"--workers {workers} must be at least 1")
        chosen = None if languages is None else tuple(c for c in re.split(r"[,\s]+", languages.strip())
                                                      if c and c.lower() != "none")
        manifest = build(out, seed=seed, workers=workers, limit=limit, languages=chosen, reporter=reporter)
        failed = sum("error" in e for e in manifest["done"].values())
        click.echo(f"{len(manifest['done']) - failed} sequences in {out}"
                   + (f" ({failed} failed)" if failed else ""))
        return
    for name, value in (("--limit", limit), ("--languages", languages)):
        if value is not None:
            raise FacegenError(f"{name} applies to --preset voices only: drop it")
    from facegen.synth.corpus import synthesize_corpus

    report = synthesize_corpus(out, subjects, sentences, preset=preset, fps=fps, seed=seed, workers=workers,
                               reporter=reporter)
    click.echo(report.summary())
