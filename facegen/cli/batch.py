"""`facegen batch`: many clips from a manifest, with reports."""

from __future__ import annotations

import sys

import click

from facegen.cli.command import Command
from facegen.cli.options import DEVICE, FiniteRange


@click.command(cls=Command)
@click.argument("manifest", type=click.Path(dir_okay=False))
@click.option("--output-dir", "-o", required=True, type=click.Path(file_okay=False),
              help="Folder for the outputs, the reports (report.json, JUnit report.xml) and the run state.")
@click.option("--jobs", "-j", type=click.IntRange(min=1),
              help="Worker processes (Ray: actors) [default: the cores].")
@click.option("--formats", metavar="EXT,EXT",
              help="Write every item in these formats from one inference, e.g. usdc,glb,json (default: each "
                   "row's output).")
@click.option("--force", is_flag=True, help="Redo items unchanged since the last run (default: skip them).")
@click.option("--engine", type=click.Choice(["local", "ray"]), default="local", show_default=True,
              help="local: worker processes on this machine; ray: Ray tasks (pip install 'facegen[ray]').")
@click.option("--ray-address", metavar="HOST:PORT",
              help="A running Ray cluster (default: start a local instance).")
@click.option("--model", "-m", type=click.Path(dir_okay=False),
              help="Model bundle (default: the built-in model).")
@click.option("--text-model", help="Local folder (or cached id) of the text model.")
@click.option("--device", type=DEVICE, default="auto", show_default=True)
@click.option("--batch-size", type=click.IntRange(min=1), default=16, show_default=True,
              help="Clips of a worker run through the network at once.")
@click.option("--ext", default=".usdc", show_default=True, help="Output format for rows without an output.")
@click.option("--usd-mode", type=click.Choice(["points", "blendshapes"]), default="blendshapes",
              show_default=True,
              help="USD outputs: UsdSkel blend shapes (2.6 MB for a 4 s line) or time-sampled points "
                   "(31 MB).")
@click.option("--fps", type=FiniteRange(0, 240, min_open=True),
              help="Frames per second of every output (default: the model's, 25).")
@click.option("--on-mismatch", type=click.Choice(["error", "warn"]), default="error", show_default=True,
              help="A line whose transcript does not match its speech: an error, or written and flagged in "
                   "the reports (each item's match score is there either way).")
@click.option("--blink-rate", type=FiniteRange(0, 120), default=17.0, show_default=True, metavar="PER_MIN",
              help="Blinks per minute in every line, timed by its speech; 0 = none.")
@click.option("--seed", type=click.IntRange(0, 2**32 - 1), default=0, show_default=True,
              help="Seed of the random layers (blinks): a rerun gives the same files.")
@click.option("--head-motion", type=FiniteRange(0, 3), default=1.0, show_default=True, metavar="AMOUNT",
              help="How much every line's head moves with its voice: 0 = still, 1 = as people do.")
@click.option("--lip-seal/--no-lip-seal", default=True, show_default=True,
              help="Shut the lips on p, b and m where the model leaves them apart.")
@click.option("--emotion", metavar="LABEL[:INTENSITY]",
              help="An emotion over every line (neutral, happy, sad, angry, surprised, afraid, disgusted; "
                   "intensity 0-1); a manifest's 'emotion' column sets it per line.")
@click.option("--strength", metavar="REGION=SCALE,...",
              help="Scale the model's motion by region in every line: lips, jaw, upper, 0-3 each (e.g. "
                   "lips=1.2,upper=1.5); a manifest's 'strength' column sets it per line.")
@click.option("--language", "-l", default="en", show_default=True, metavar="CODE",
              help="The transcripts' language (`facegen languages` lists them); a manifest's 'language' "
                   "column sets it per line.")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar.")
def batch(manifest, output_dir, jobs, formats, force, engine, ray_address, model, text_model, device,
          batch_size, ext, usd_mode, fps, on_mismatch, blink_rate, seed, head_motion, lip_seal, emotion,
          strength, language, quiet):
    """Animate many clips listed in MANIFEST (CSV, JSON or JSON lines: audio, text|text_file|alignment,
    speaker, output) into OUTPUT_DIR, each worker loading the model once; items unchanged since the last run
    are skipped. Writes OUTPUT_DIR/report.json and report.xml (JUnit). Exit 1 when any item failed.

    USD outputs are UsdSkel blend shapes unless --usd-mode points: a twelfth of the size for short lines, a
    hundredth for long clips (benchmarks/bench_sizes.py); ARKit .json (0.04 MB a line) is the smallest."""
    from facegen.batch_run import run_manifest
    from facegen.runtime import Reporter

    reporter = Reporter.stderr(quiet)
    bars = []  # made once the plan says how many items there are

    def planned(total: int, _to_run: int) -> None:
        bars.append(reporter.bar(total=total, desc="batch", unit="clip", leave=False))

    try:
        outcome = run_manifest(manifest, output_dir, jobs=jobs, formats=formats, force=force, engine=engine,
                               ray_address=ray_address, model=model, text_model=text_model, device=device,
                               batch_size=batch_size, default_ext=ext, fps=fps, usd_mode=usd_mode,
                               on_mismatch=on_mismatch, blink_rate=blink_rate, seed=seed,
                               emotion=emotion, head_motion=head_motion, lip_seal=lip_seal, strength=strength,
                               language=language, reporter=reporter,
                               on_plan=planned,
                               on_result=lambda _r: bars and bars[0].update(1))
    finally:
        for bar in bars:
            bar.close()
    for r in outcome.results:
        if r.status in ("failed", "error"):
            why = r.error or "; ".join(f for v in r.validation for f in v["failures"])
            click.echo(f"facegen: line {r.job.line}: {r.job.output}: {r.status}: {why}", err=True)
    click.echo(outcome.summary)
    sys.exit(0 if outcome.ok else 1)
