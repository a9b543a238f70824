"""The `facegen` command line: parse options, call the library, print, exit codes.

Errors a user can cause (FacegenError, bad options) print one line and exit 2; `--debug` shows the traceback.
Heavy libraries are imported inside the commands so `facegen --help` stays fast.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from facegen import __version__
from facegen.errors import FacegenError


def _progress(quiet: bool):
    if quiet:
        return lambda _msg: None
    return lambda msg: click.echo(f"facegen: {msg}", err=True)


def _read_text(text: str | None, text_file: str | None) -> str | None:
    if text_file is None:
        return text
    try:
        return Path(text_file).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise FacegenError(f"cannot read transcript file {text_file} ({exc}): pass a UTF-8 text file") from exc


def _one_of(**options) -> None:
    given = [k for k, v in options.items() if v]
    if len(given) > 1:
        names = " and ".join("--" + k.replace("_", "-") for k in given)
        raise FacegenError(f"{names} cannot be used together: give only one source of words")


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="facegen")
@click.option("--debug", is_flag=True, help="Show tracebacks for errors.")
def cli(debug: bool) -> None:
    """Speech (audio + transcript) to expressive 3D face animation in USD, glTF and npy."""


@cli.command()
@click.argument("audio", type=click.Path(dir_okay=False))
@click.option("--text", "-t", help="The transcript (words spoken).")
@click.option("--text-file", type=click.Path(dir_okay=False), help="A UTF-8 file with the transcript.")
@click.option("--alignment", type=click.Path(dir_okay=False),
              help="Word timings you already have: Gentle/WhisperX JSON, TextGrid, JSON or CSV word list.")
@click.option("--no-text", is_flag=True, help="Use no words at all (zero text features).")
@click.option("--speaker", "-s", help="Speaking style: a speaker name or index of the model (default: the first).")
@click.option("--model", "-m", type=click.Path(dir_okay=False), help="Model bundle (default: the built-in model).")
@click.option("--template", type=click.Path(dir_okay=False),
              help="A face mesh (PLY/OBJ) with the model's topology to animate instead of its template.")
@click.option("--text-model", help="Local folder (or cached id) of the text model, if not where the bundle says.")
@click.option("--output", "-o", required=True, type=click.Path(dir_okay=False),
              help="Output file: .usda .usdc .usd .usdz .glb .gltf .npy.")
@click.option("--usd-mode", type=click.Choice(["points", "blendshapes"]),
              help="USD: time-sampled points (default) or UsdSkel blend shapes (compact, for game engines).")
@click.option("--morph-targets", metavar="K|all",
              help="glTF / USD blendshapes: number of PCA morph targets (default: as many as the tolerance "
                   "needs), or 'all' for one per frame (short clips).")
@click.option("--tolerance", type=float,
              help="glTF / USD blendshapes: largest vertex error allowed, as a fraction of the face size "
                   "(default 1e-3).")
@click.option("--preview", type=click.Path(dir_okay=False), help="Also render a preview video (.mp4) with sound.")
@click.option("--quiet", "-q", is_flag=True, help="No progress messages.")
def animate(audio, text, text_file, alignment, no_text, speaker, model, template, text_model, output, usd_mode,
            morph_targets, tolerance, preview, quiet):
    """Animate the face for AUDIO and write OUTPUT."""
    from facegen.animate import animate as run
    from facegen.atomic import check_writable
    from facegen.exchange import check_write_options, format_module, write_animation

    _one_of(text=text, text_file=text_file, alignment=alignment, no_text=no_text)
    format_module(output)  # an unknown extension or unwritable folder fails before any work
    check_writable(output)
    options = {k: v for k, v in (("mode", usd_mode), ("morph_targets", morph_targets), ("tolerance", tolerance))
               if v is not None}
    check_write_options(output, options)
    if preview:
        from facegen.render import check_output

        check_output(preview)
    progress = _progress(quiet)
    anim = run(audio, text=_read_text(text, text_file), alignment=alignment, no_text=no_text, speaker=speaker,
               bundle=model, template=template, text_model=text_model, progress=progress,
               warn=_progress(False))
    written = write_animation(anim, output, audio_source=audio, **options)
    progress(f"wrote {', '.join(str(p) for p in written)} ({anim.num_frames} frames at {anim.fps:g} fps)")
    if preview:
        from facegen.render import render_animation

        result = render_animation(anim, preview, progress=not quiet)
        for note in result.notes:
            progress(note)
        progress(f"wrote {result.path} ({result.width}x{result.height}, {result.seconds:.1f} s to render)")


@cli.command()
@click.argument("input_file", metavar="IN", type=click.Path(dir_okay=False))
@click.option("--output", "-o", required=True, type=click.Path(dir_okay=False), help="The video (.mp4).")
@click.option("--compare", type=click.Path(dir_okay=False),
              help="Another animation (ground truth or another model) shown beside IN with an error heat map.")
@click.option("--model", "-m", type=click.Path(dir_okay=False), help="Bundle whose template a .npy IN uses.")
@click.option("--template", type=click.Path(dir_okay=False), help="Template mesh (PLY/OBJ) for a .npy IN.")
@click.option("--fps", type=float, help="Frame rate of a .npy IN (default 25).")
@click.option("--size", default=512, show_default=True, help="Pixels per view (square).")
@click.option("--views", default="front,three_quarter", show_default=True,
              help="Comma-separated views: front, three_quarter, profile.")
@click.option("--error-scale", type=float, help="Fix the heat map's top value (model units) across videos.")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar.")
def render(input_file, output, compare, model, template, fps, size, views, error_scale, quiet):
    """Render an animation file IN to a preview video with its sound."""
    from facegen.render import render as run

    if model and template:
        raise FacegenError("--model and --template cannot be used together: pass one reference")
    mesh = template
    if model:
        from facegen.bundle import load_bundle

        mesh = load_bundle(model).template
    result = run(input_file, output, size=size, views=views, compare=compare, template=mesh, fps=fps,
                 error_scale=error_scale, progress=not quiet)
    for note in result.notes:
        click.echo(f"facegen: {note}", err=True)
    click.echo(str(result.path))


@cli.command()
@click.argument("audio", type=click.Path(dir_okay=False))
@click.option("--text", "-t", help="The transcript.")
@click.option("--text-file", type=click.Path(dir_okay=False), help="A UTF-8 file with the transcript.")
@click.option("--output", "-o", type=click.Path(dir_okay=False),
              help="words.json or words.TextGrid (default: JSON on stdout).")
def align(audio, text, text_file, output):
    """Find when each word of the transcript is spoken in AUDIO."""
    from facegen import align as al
    from facegen.animate import get_words
    from facegen.audio import check_speech, load_audio

    _one_of(text=text, text_file=text_file)
    if output and Path(output).suffix.lower() not in (".json", ".textgrid"):
        raise FacegenError(f"cannot write alignments as {Path(output).suffix or 'no extension'}: use .json or .TextGrid")
    samples, sr = load_audio(audio)
    check_speech(samples, sr, 25.0, name=f"audio file {audio}")
    words, _ = get_words(samples, sr, text=_read_text(text, text_file), warn=_progress(False))
    if output:
        al.write_alignment(words, output)
    else:
        click.echo(json.dumps({"words": [{"word": w.text, "start": w.start, "end": w.end} for w in words]}, indent=1))


@cli.command()
@click.argument("bundle", required=False, type=click.Path(dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Print the metadata as JSON.")
def info(bundle, as_json):
    """Describe a model BUNDLE (default: the built-in model)."""
    from facegen.bundle import default_bundle_path, read_metadata

    path = Path(bundle) if bundle else default_bundle_path()
    meta = read_metadata(path)
    if as_json:
        click.echo(json.dumps(meta, indent=2))
        return
    cfg, feat, topo = meta["model_config"], meta["feature_config"], meta["topology"]
    lines = [
        f"model bundle   {path}",
        f"format         {meta['format_version']}",
        f"network        modalities={cfg['modalities']} fusion={cfg['fusion']} text_dim={cfg['text_dim']}",
        f"text backend   {meta['text_backend']['id']} ({meta['text_backend']['dim']}-d)",
        f"audio          {feat['n_mels']} mel bands, {feat['sample_rate']} Hz, {feat['fps']:g} fps",
        f"speakers       {', '.join(f'{i}={s}' for i, s in enumerate(meta['speakers']))}",
        f"topology       {topo['num_vertices']} vertices, {topo['num_faces']} faces, fingerprint {topo['fingerprint']}",
        f"regions        {', '.join(f'{k} ({v} vertices)' for k, v in meta.get('regions', {}).items()) or 'none'}",
    ]
    for k, v in meta.get("provenance", {}).items():
        lines.append(f"{k:<14} {json.dumps(v) if isinstance(v, dict | list) else v}")
    click.echo("\n".join(lines))


@cli.command()
@click.argument("file", type=click.Path(dir_okay=False))
@click.option("--model", "-m", type=click.Path(dir_okay=False), help="Check against this bundle's template.")
@click.option("--template", type=click.Path(dir_okay=False), help="Check against this mesh (PLY/OBJ).")
@click.option("--fps", type=float, help="The frame rate the file must have.")
@click.option("--audio", "audio_path", type=click.Path(dir_okay=False),
              help="The audio the animation must match (default: the file's own/sidecar audio).")
@click.option("--no-audio-required", is_flag=True, help="Do not fail when no audio is attached.")
@click.option("--reference", type=click.Path(dir_okay=False),
              help="The source animation (.npy/.usd*) that a glTF/blendshape file must reproduce within its tolerance.")
@click.option("--json", "as_json", is_flag=True, help="Machine-readable report.")
def validate(file, model, template, fps, audio_path, no_audio_required, reference, as_json):
    """Check an animation FILE written by facegen (or another tool). Exit 1 when a check fails."""
    from facegen.validate import validate as run

    if model and template:
        raise FacegenError("--model and --template cannot be used together: pass one reference")
    mesh = None
    if model:
        from facegen.bundle import load_bundle

        mesh = load_bundle(model).template
    elif template:
        from facegen.mesh import read_mesh

        mesh = read_mesh(template)
    report = run(file, template=mesh, fps=fps, audio_path=audio_path, require_audio=not no_audio_required,
                 reference=reference)
    click.echo(report.to_json() if as_json else report.to_text())
    sys.exit(0 if report.ok else 1)


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    debug = "--debug" in argv
    try:
        cli.main(args=argv, prog_name="facegen", standalone_mode=False)
    except FacegenError as exc:
        if debug:
            raise
        click.echo(f"facegen: error: {exc}", err=True)
        sys.exit(2)
    except click.exceptions.Abort:
        click.echo("facegen: interrupted", err=True)
        sys.exit(130)
    except click.ClickException as exc:
        hint = f" (see 'facegen {exc.ctx.info_name} --help')" if getattr(exc, "ctx", None) else ""
        click.echo(f"facegen: error: {exc.format_message()}{hint}", err=True)
        sys.exit(exc.exit_code)
    except KeyboardInterrupt:
        click.echo("facegen: interrupted", err=True)
        sys.exit(130)
    except Exception as exc:
        if debug:
            raise
        click.echo(f"facegen: internal error: {type(exc).__name__}: {exc} (rerun with --debug and report it)",
                   err=True)
        sys.exit(1)
