"""`facegen render` and `facegen validate`: commands on animation files already written."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from facegen.cli.command import Command
from facegen.cli.options import FPS, FiniteRange
from facegen.errors import FacegenError
from facegen.runtime import Reporter


@click.command(cls=Command, given_by={"template": ("model", "template")})
@click.argument("input_file", metavar="IN", type=click.Path(dir_okay=False))
@click.option("--output", "-o", required=True, type=click.Path(dir_okay=False), help="The video (.mp4).")
@click.option("--compare", type=click.Path(dir_okay=False),
              help="Another animation (ground truth or another model) shown beside IN with an error heat "
                   "map.")
@click.option("--model", "-m", type=click.Path(dir_okay=False),
              help="Bundle whose template a .npy IN uses (default: the built-in model's, when the vertex "
                   "count matches).")
@click.option("--template", type=click.Path(dir_okay=False), help="Template mesh (PLY/OBJ) for a .npy IN.")
@click.option("--fps", type=FPS, help="Frame rate of a .npy IN (default 25).")
@click.option("--size", type=click.IntRange(16, 8192), default=512, show_default=True,
              help="Pixels per view (square).")
@click.option("--views", default="front,three_quarter", show_default=True,
              help="Comma-separated views: front, three_quarter, profile.")
@click.option("--error-scale", type=FiniteRange(0, min_open=True),
              help="Fix the heat map's top value (model units) across videos.")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar.")
def render(input_file, output, compare, model, template, fps, size, views, error_scale, quiet):
    """Render an animation file IN to a preview video with its sound."""
    from facegen.render import render as run

    if model and template:
        raise FacegenError("--model and --template cannot be used together: pass one reference")
    mesh = template
    if model:
        from facegen.bundle import read_template

        mesh = read_template(model)
    reporter = Reporter.stderr(quiet)
    from facegen.atomic import output_folders

    with output_folders(output):  # made as needed, removed again when nothing is written
        result = run(input_file, output, size=size, views=views, compare=compare, template=mesh, fps=fps,
                     error_scale=error_scale, reporter=reporter)
    for note in result.notes:
        click.echo(f"facegen: {note}", err=True)
    # as animate says it: "wrote PATH (...)", a progress line (silenced by --quiet)
    reporter.progress(f"wrote {result.path} ({result.width}x{result.height}, {result.frames} frames, "
                      f"{result.seconds:.1f} s to render)")


@click.command(cls=Command)
@click.argument("file", type=click.Path(dir_okay=False))
@click.option("--model", "-m", type=click.Path(dir_okay=False), help="Check against this bundle's template.")
@click.option("--template", type=click.Path(dir_okay=False), help="Check against this mesh (PLY/OBJ).")
@click.option("--fps", type=FPS, help="The frame rate the file must have.")
@click.option("--audio", "audio_path", type=click.Path(dir_okay=False),
              help="The audio the animation must match (default: the file's own/sidecar audio).")
@click.option("--no-audio-required", is_flag=True, help="Do not fail when no audio is attached.")
@click.option("--reference", type=click.Path(dir_okay=False),
              help="The source animation (.npy/.usd*) that a glTF/blendshape file must reproduce within its "
                   "tolerance.")
@click.option("--json", "as_json", is_flag=True, help="Machine-readable report.")
def validate(file, model, template, fps, audio_path, no_audio_required, reference, as_json):
    """Check an animation FILE written by facegen (or another tool). Exit 1 when a check fails."""
    from facegen.validate import validate as run

    if model and template:
        raise FacegenError("--model and --template cannot be used together: pass one reference")
    if not Path(file).exists():
        raise FacegenError(f"{file} does not exist: pass the animation file to check")
    from facegen.input_files import check_input

    # a FIFO, a device or a folder: said as what it is (validate reads files in bounded memory, any size)
    check_input(file, what="animation file", limit=1 << 62, too_big="", fix="pass the animation file")
    mesh = None
    if model:
        from facegen.bundle import read_template

        mesh = read_template(model)  # the face alone: validate never imports torch
    elif template:
        from facegen.face.mesh import read_mesh

        mesh = read_mesh(template)
    report = run(file, template=mesh, fps=fps, audio_path=audio_path, require_audio=not no_audio_required,
                 reference=reference)
    click.echo(report.to_json() if as_json else report.to_text())
    sys.exit(0 if report.ok else 1)
