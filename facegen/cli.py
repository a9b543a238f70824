"""The `facegen` command line: parse options, call the library, print, exit codes.

Errors a user can cause (FacegenError, bad options) print one line and exit 2; `--debug` shows the traceback.
Heavy libraries are imported inside the commands so `facegen --help` stays fast, and the `facegen` process
ends without the interpreter's teardown once its outputs are written and its streams flushed (`main`).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from facegen import __version__
from facegen.errors import FacegenError
from facegen.exchange import extensions
from facegen.runtime import Say, say_stderr, silent


def _progress(quiet: bool) -> Say:
    """Where a command's progress messages go: "facegen: ..." lines on stderr, or nowhere with --quiet."""
    return silent if quiet else say_stderr


def _protect_inputs(outputs: list, **inputs) -> None:
    """Refuse an output path that names one of the command's input files (it would be overwritten)."""
    from facegen.exchange.wav import is_same_file

    for out in outputs:
        for name, path in inputs.items():
            if out and path and (Path(out).resolve() == Path(path).resolve() or is_same_file(path, out)):
                raise FacegenError(f"{out} is the {name} file this command reads: writing it would destroy an "
                                   "input; choose another output name")


def _read_text(text: str | None, text_file: str | None) -> str | None:
    if text_file is None:
        return text
    try:
        return Path(text_file).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise FacegenError(f"cannot read transcript file {text_file} ({exc}): pass a UTF-8 text file") from exc


def _morph_targets(_ctx, _param, value: str | None) -> int | str | None:
    from facegen.exchange.pca import parse_morph_targets

    return parse_morph_targets(value)


def _usd_clips(_ctx, _param, value: str | None) -> int | str | None:
    from facegen.exchange.usd_clips import parse_clips

    return parse_clips(value)


def _one_of(**options) -> None:
    given = [k for k, v in options.items() if v]
    if len(given) > 1:
        names = " and ".join("--" + k.replace("_", "-") for k in given)
        raise FacegenError(f"{names} cannot be used together: give only one source of words")


class _FiniteRange(click.FloatRange):
    """A float range that also refuses nan and inf (click's FloatRange lets nan through)."""

    def convert(self, value, param, ctx):
        import math

        number = super().convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{number} is not a finite number", param, ctx)
        return number


FPS = _FiniteRange(0, 1000, min_open=True)
WEIGHT = _FiniteRange(0, 1e6)

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
              help=f"Output file: {' '.join(extensions())}.")
@click.option("--usd-mode", type=click.Choice(["points", "blendshapes"]),
              help="USD: time-sampled points (default) or UsdSkel blend shapes (compact, for game engines).")
@click.option("--usd-clips", metavar="auto|never|N", callback=_usd_clips,
              help="USD points: auto (default) writes clips over 2 minutes as value clips in OUTPUT.clips/ "
                   "(bounded memory), never keeps one file, N writes value clips of N frames.")
@click.option("--rig", type=click.Choice(["pca", "arkit"]),
              help="glTF / USD: the morph targets: pca (default: a PCA of the clip, the fewest targets) or arkit "
                   "(Apple's 52 ARKit blend shapes, named as ARKit names them, with their fitted weights; "
                   "USD: UsdSkel blend shapes).")
@click.option("--morph-targets", metavar="K|all", callback=_morph_targets,
              help="glTF / USD blendshapes: number of PCA morph targets (default: as many as the tolerance "
                   "needs), or 'all' for one per frame (short clips).")
@click.option("--tolerance", type=_FiniteRange(0, 1, min_open=True),
              help="glTF / USD blendshapes: largest vertex error allowed, as a fraction of the face size "
                   "(default 1e-3).")
@click.option("--preview", type=click.Path(dir_okay=False), help="Also render a preview video (.mp4) with sound.")
@click.option("--device", type=click.Choice(["auto", "cpu", "cuda"]), default="auto", show_default=True,
              help="Where the network runs: auto = a CUDA GPU when there is one, else the CPU.")
@click.option("--quiet", "-q", is_flag=True, help="No progress messages.")
def animate(audio, text, text_file, alignment, no_text, speaker, model, template, text_model, output, usd_mode,
            usd_clips, rig, morph_targets, tolerance, preview, device, quiet):
    """Animate the face for AUDIO and write OUTPUT."""
    from facegen.atomic import check_writable
    from facegen.exchange import check_write_options, format_module, format_of, import_writer, write_animation
    from facegen.exchange.wav import is_same_file, sidecar_path
    from facegen.pipeline import animate as run

    _one_of(text=text, text_file=text_file, alignment=alignment, no_text=no_text)
    format_module(output)  # an unknown extension or unwritable folder fails before any work
    check_writable(output)
    sidecar = sidecar_path(output)
    if not is_same_file(audio, sidecar):
        check_writable(sidecar)
    _protect_inputs([output, sidecar, preview], transcript=text_file,
                    alignment=alignment, model=model, template=template)
    options = {k: v for k, v in (("mode", usd_mode), ("clips", usd_clips), ("rig", rig), ("morph_targets", morph_targets),
                                 ("tolerance", tolerance)) if v is not None}
    check_write_options(output, options)
    if rig == "arkit" or format_of(output).arkit:  # ARKit weights need the rig's regions: checked before any work
        from facegen.bundle import load_bundle
        from facegen.exchange.basis import check_rig
        from facegen.pipeline import resolve_template

        model = load_bundle(model)
        check_rig("arkit", resolve_template(model, template))
        if "mode" in format_of(output).options:
            options.setdefault("mode", "blendshapes")  # USD: the ARKit shapes are UsdSkel blend shapes
    if preview:
        from facegen.render import check_output

        check_output(preview)
    progress = _progress(quiet)
    # writers that read frames block by block: no [T, V, 3] array in memory
    stream = format_of(output).streams_with(options) and not preview
    anim = run(audio, text=_read_text(text, text_file), alignment=alignment, no_text=no_text, speaker=speaker,
               bundle=model, template=template, text_model=text_model, device=device, stream=stream,
               progress=progress, warn=_progress(False), meanwhile=lambda: import_writer(output))
    written = write_animation(anim, output, audio_source=audio, **options)
    progress(f"wrote {', '.join(str(p) for p in written)} ({anim.num_frames} frames at {anim.fps:g} fps)")
    if preview:
        from facegen.render import render_animation

        try:
            result = render_animation(anim, preview, progress=not quiet)
        except BaseException:  # all or nothing: no animation without the preview asked for
            for path in written:
                if not is_same_file(audio, path):
                    path.unlink(missing_ok=True)
            raise
        for note in result.notes:
            progress(note)
        progress(f"wrote {result.path} ({result.width}x{result.height}, {result.seconds:.1f} s to render)")


@cli.command()
@click.argument("input_file", metavar="IN", type=click.Path(dir_okay=False))
@click.option("--output", "-o", required=True, type=click.Path(dir_okay=False), help="The video (.mp4).")
@click.option("--compare", type=click.Path(dir_okay=False),
              help="Another animation (ground truth or another model) shown beside IN with an error heat map.")
@click.option("--model", "-m", type=click.Path(dir_okay=False), help="Bundle whose template a .npy IN uses (default: the built-in model's, when the vertex count matches).")
@click.option("--template", type=click.Path(dir_okay=False), help="Template mesh (PLY/OBJ) for a .npy IN.")
@click.option("--fps", type=FPS, help="Frame rate of a .npy IN (default 25).")
@click.option("--size", type=click.IntRange(16, 8192), default=512, show_default=True, help="Pixels per view (square).")
@click.option("--views", default="front,three_quarter", show_default=True,
              help="Comma-separated views: front, three_quarter, profile.")
@click.option("--error-scale", type=_FiniteRange(0, min_open=True), help="Fix the heat map's top value (model units) across videos.")
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
@click.option("--phones", is_flag=True,
              help="Also write each word's phones (CMU, pocketsphinx phone alignment): a `phones` list / tier.")
def align(audio, text, text_file, output, phones):
    """Find when each word (and with --phones each phone) of the transcript is spoken in AUDIO."""
    from facegen.audio import check_speech, load_audio
    from facegen.pipeline import get_words
    from facegen.words import alignment_json, write_alignment

    _one_of(text=text, text_file=text_file)
    _protect_inputs([output], audio=audio, transcript=text_file)
    if output and Path(output).suffix.lower() not in (".json", ".textgrid"):
        raise FacegenError(f"cannot write alignments as {Path(output).suffix or 'no extension'}: use .json or .TextGrid")
    samples, sr = load_audio(audio)
    check_speech(samples, sr, 25.0, name=f"audio file {audio}")
    transcript = _read_text(text, text_file)
    if phones:
        if transcript is None:
            raise FacegenError("--phones needs the transcript: pass --text or --text-file")
        from facegen.align import align_phones

        words, found = align_phones(samples, sr, transcript)
    else:
        words, _ = get_words(samples, sr, text=transcript, warn=_progress(False))
        found = None
    if output:
        write_alignment(words, output, duration=len(samples) / sr, phones=found)
    else:
        click.echo(json.dumps(alignment_json(words, found), indent=1))


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
        f"network        modalities={cfg['modalities']} fusion={cfg['fusion']} text_dim={cfg['text_dim']}"
        + (f" phone stream ({cfg['n_phones']} phones)" if cfg.get('n_phones') else ""),
        f"text backend   {meta['text_backend']['id']} ({meta['text_backend']['dim']}-d)",
        f"audio          {feat['n_mels']} mel bands, {feat['sample_rate']} Hz, {feat['fps']:g} fps",
        f"speakers       {', '.join(f'{i}={s}' for i, s in enumerate(meta['speakers']))}",
        f"topology       {topo['num_vertices']} vertices, {topo['num_faces']} faces, fingerprint {topo['fingerprint']}",
        f"regions        {', '.join(f'{k} ({v} vertices)' for k, v in meta.get('regions', {}).items()) or 'none'}",
    ]
    for k, v in meta.get("provenance", {}).items():
        if k == "history":
            v = f"{len(v)} epochs of train/val loss (see --json)"
        lines.append(f"{k:<14} {json.dumps(v) if isinstance(v, dict | list) else v}")
    click.echo("\n".join(lines))


@cli.command()
@click.argument("file", type=click.Path(dir_okay=False))
@click.option("--model", "-m", type=click.Path(dir_okay=False), help="Check against this bundle's template.")
@click.option("--template", type=click.Path(dir_okay=False), help="Check against this mesh (PLY/OBJ).")
@click.option("--fps", type=FPS, help="The frame rate the file must have.")
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
    if not Path(file).is_file():
        raise FacegenError(f"{file} does not exist: pass the animation file to check")
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


@cli.command()
@click.argument("manifest", type=click.Path(dir_okay=False))
@click.option("--output-dir", "-o", required=True, type=click.Path(file_okay=False),
              help="Folder for the outputs, the reports (report.json, JUnit report.xml) and the run state.")
@click.option("--jobs", "-j", type=click.IntRange(min=1), help="Worker processes (Ray: actors) [default: the cores].")
@click.option("--formats", metavar="EXT,EXT", help="Write every item in these formats from one inference, e.g. "
                                                    "usdc,glb,json (default: each row's output).")
@click.option("--force", is_flag=True, help="Redo items unchanged since the last run (default: skip them).")
@click.option("--engine", type=click.Choice(["local", "ray"]), default="local", show_default=True,
              help="local: worker processes on this machine; ray: Ray tasks (pip install 'facegen[ray]').")
@click.option("--ray-address", metavar="HOST:PORT", help="A running Ray cluster (default: start a local instance).")
@click.option("--model", "-m", type=click.Path(dir_okay=False), help="Model bundle (default: the built-in model).")
@click.option("--text-model", help="Local folder (or cached id) of the text model.")
@click.option("--device", type=click.Choice(["auto", "cpu", "cuda"]), default="auto", show_default=True)
@click.option("--batch-size", type=click.IntRange(min=1), default=16, show_default=True,
              help="Clips of a worker run through the network at once.")
@click.option("--ext", default=".usdc", show_default=True, help="Output format for rows without an output.")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar.")
def batch(manifest, output_dir, jobs, formats, force, engine, ray_address, model, text_model, device, batch_size,
          ext, quiet):
    """Animate many clips listed in MANIFEST (CSV, JSON or JSON lines: audio, text|text_file|alignment, speaker,
    output) into OUTPUT_DIR, each worker loading the model once; items unchanged since the last run are
    skipped. Writes OUTPUT_DIR/report.json and report.xml (JUnit). Exit 1 when any item failed."""
    from facegen.batch_run import run_manifest
    from facegen.runtime import progress_bar

    bars = []  # made once the plan says how many items there are

    def planned(total: int, _to_run: int) -> None:
        bars.append(progress_bar(total=total, desc="batch", unit="clip", enabled=not quiet, leave=False))

    try:
        outcome = run_manifest(manifest, output_dir, jobs=jobs, formats=formats, force=force, engine=engine,
                               ray_address=ray_address, model=model, text_model=text_model, device=device,
                               batch_size=batch_size, default_ext=ext, on_plan=planned,
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


def _split_options(f):
    for opt in reversed([
        click.option("--train-subjects", help="Training subjects, e.g. F2,F3,F4,M3,M4,M5 (the default)."),
        click.option("--test-subjects", help="Test-B subjects (default: F1,F5,F6,F7,F8,M1,M2,M6)."),
        click.option("--train-sentences", help="Training sentences, e.g. 1-32 (the default)."),
        click.option("--val-sentences", help="Validation sentences (default 33-36)."),
        click.option("--test-sentences", help="Test sentences (default 37-40)."),
    ]):
        f = opt(f)
    return f


def _splits(train_subjects, test_subjects, train_sentences, val_sentences, test_sentences):
    from facegen.datasets.splits import Splits

    return Splits.from_options(train_subjects, test_subjects, train_sentences, val_sentences, test_sentences)


@cli.command()
@click.argument("data", type=click.Path(file_okay=False))
@click.option("--output", "-o", required=True, type=click.Path(dir_okay=False), help="The model bundle to write.")
@click.option("--text-backend", default="minilm", show_default=True,
              help="minilm (offline default), gpt2 (the paper's), or a Hugging Face id / local folder.")
@click.option("--text-model", type=click.Path(), help="Local folder with the text model's weights.")
@click.option("--modalities", type=click.Choice(["both", "audio", "text"]), default="both", show_default=True)
@click.option("--fusion", type=click.Choice(["tensor", "concat"]), default="tensor", show_default=True)
@click.option("--epochs", type=click.IntRange(min=1), default=100, show_default=True)
@click.option("--lr", type=_FiniteRange(0, 10, min_open=True), default=1e-4, show_default=True)
@click.option("--batch-size", type=click.IntRange(min=1), default=1, show_default=True)
@click.option("--seed", default=0, show_default=True)
@click.option("--device", type=click.Choice(["auto", "cpu", "cuda"]), default="auto", show_default=True)
@click.option("--resume", is_flag=True, help="Continue from the last checkpoint (after a kill or with more epochs).")
@click.option("--checkpoint-dir", type=click.Path(file_okay=False), help="Default: OUTPUT's name + '.ckpt/'.")
@click.option("--precision", type=click.Choice(["fp32", "fp16", "int8"]), default="fp32", show_default=True,
              help="How the bundle stores its weights.")
@click.option("--threads", type=click.IntRange(1, 1024), help="CPU threads for torch (default: all cores).")
@click.option("--strict", is_flag=True, help="Refuse to train when a sequence is missing or corrupt (default: skip it).")
@click.option("--output-layer", "output_layer", type=click.Choice(["full", "pca"]), default="full", show_default=True,
              help="full: the paper's FC 3V; pca: the same layer trained in a PCA basis of the training motion.")
@click.option("--basis", type=click.IntRange(min=1), default=64, show_default=True, help="Dimensions of the PCA basis (--output-layer pca).")
@click.option("--lip-weight", type=WEIGHT, default=0.0, show_default=True, help="Extra loss on the lip vertices (pca only).")
@click.option("--velocity-weight", type=WEIGHT, default=0.0, show_default=True, help="Loss on frame-to-frame motion (pca only).")
@click.option("--upper-weight", type=WEIGHT, default=0.0, show_default=True,
              help="Extra loss on the upper-face vertices (pca only).")
@click.option("--patience", type=click.IntRange(min=1), help="Stop after this many epochs without a better validation loss.")
@click.option("--phones", is_flag=True, help="Add the phone stream (per-frame phones) to the audio encoder.")
@_split_options
@click.option("--quiet", "-q", is_flag=True)
def train(data, output, text_backend, text_model, modalities, fusion, epochs, lr, batch_size, seed, device, resume,
          checkpoint_dir, precision, threads, strict, output_layer, basis, lip_weight, velocity_weight, upper_weight,
          patience, phones, train_subjects, test_subjects, train_sentences, val_sentences, test_sentences, quiet):
    """Train a model on a BIWI-layout dataset DATA (the paper's setup by default)."""
    import os

    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # busy-waiting OpenMP threads stall on shared cores
    from facegen.train import train as run

    splits = _splits(train_subjects, test_subjects, train_sentences, val_sentences, test_sentences)
    result = run(data, output, text_backend=text_backend, text_model_path=text_model, modalities=modalities,
                 fusion=fusion, epochs=epochs, lr=lr, batch_size=batch_size, seed=seed, device=device,
                 resume=resume, splits=splits, checkpoint_dir=checkpoint_dir, precision=precision, threads=threads,
                 on_bad="fail" if strict else "skip", quiet=quiet, output=output_layer, basis=basis,
                 lip_weight=lip_weight, velocity_weight=velocity_weight, upper_weight=upper_weight, patience=patience,
                 phones=phones)
    click.echo(json.dumps({"bundle": str(result.bundle), "epochs": result.epochs, "best_epoch": result.best_epoch,
                           "best_loss": result.best_loss, "seconds": round(result.seconds, 1),
                           "curves": str(result.curves_csv), "skipped": len(result.skipped)}))


@cli.command()
@click.argument("bundle", type=click.Path(dir_okay=False))
@click.argument("data", type=click.Path(file_okay=False))
@click.option("--split", type=click.Choice(["test-a", "test-b", "val", "train"]), default="test-a", show_default=True)
@click.option("--text-model", type=click.Path(), help="Local folder with the text model's weights.")
@click.option("--device", type=click.Choice(["auto", "cpu", "cuda"]), default="cpu", show_default=True)
@_split_options
@click.option("--json", "as_json", is_flag=True, help="Print the metrics as JSON.")
@click.option("--plots", type=click.Path(file_okay=False),
              help="Also write the paper's analysis figures (PNG) into this folder.")
@click.option("--strict", is_flag=True, help="Fail on a missing or corrupt sequence (default: skip it).")
@click.option("--quiet", "-q", is_flag=True)
def evaluate(bundle, data, split, text_model, device, train_subjects, test_subjects, train_sentences,
             val_sentences, test_sentences, as_json, plots, strict, quiet):
    """Evaluate a model BUNDLE on a split of the dataset DATA: LVE, FDD, vertex errors."""
    from facegen.evaluate import evaluate as run
    from facegen.evaluate import format_table

    given = (train_subjects, test_subjects, train_sentences, val_sentences, test_sentences)
    splits = _splits(*given) if any(v is not None for v in given) else None
    result = run(bundle, data, split, splits=splits, text_model_path=text_model, device=device,
                 on_bad="fail" if strict else "skip", quiet=quiet)
    click.echo(json.dumps(result, indent=1) if as_json else format_table(result))
    if plots:
        from facegen.plots import write_plots

        for path in write_plots(bundle, data, plots, split=split, splits=splits, text_model_path=text_model,
                                device=device, quiet=quiet):
            click.echo(f"facegen: wrote {path}", err=True)


@cli.group()
def data():
    """Datasets: import the raw BIWI release, build the synthetic corpus."""


@data.command("import-biwi")
@click.argument("raw", type=click.Path(file_okay=False))
@click.argument("out", type=click.Path(file_okay=False))
@click.option("--transcripts", type=click.Path(), help="Folder or file with the sentence transcripts.")
@click.option("--regions", type=click.Path(file_okay=False), help="Folder with lve.txt / fdd.txt region files.")
@click.option("--subjects", help="Only these subjects, e.g. F1,M2.")
@click.option("--quiet", "-q", is_flag=True)
def import_biwi(raw, out, transcripts, regions, subjects, quiet):
    """Convert the raw BIWI release RAW into the community layout in OUT."""
    from facegen.datasets.raw import import_biwi as run

    report = run(raw, out, transcripts=transcripts, regions=regions,
                 subjects=subjects.split(",") if subjects else None, progress=not quiet)
    click.echo(report.summary())


@data.command("synth")
@click.argument("out", type=click.Path(file_okay=False))
@click.option("--subjects", help="Speakers to generate, e.g. F2,F3 (default: all 14).")
@click.option("--sentences", help="Sentences, e.g. 1-40 (default: 1-48).")
@click.option("--preset", type=click.Choice(["paper", "voices"]),
              help="paper: training speakers e01-e48 and test-B speakers e37-e48 only; voices: the multi-voice "
                   "corpus (24 voices of espeak-ng, Festival and Flite, augmented, 2,400 sentences; Flite held out).")
@click.option("--limit", type=click.IntRange(min=1), help="voices: only this many sequences per split (a trial).")
@click.option("--seed", default=0, show_default=True)
@click.option("--fps", type=FPS, default=25.0, show_default=True)
@click.option("--workers", type=click.IntRange(1, 256), default=2, show_default=True)
@click.option("--quiet", "-q", is_flag=True)
def synth(out, subjects, sentences, preset, limit, seed, fps, workers, quiet):
    """Generate a synthetic speech-and-motion corpus in OUT (BIWI layout)."""
    if preset == "voices":
        from facegen.synth.voice_corpus import FPS, build

        if subjects or sentences or fps != FPS:
            raise FacegenError("--subjects, --sentences and --fps do not apply to --preset voices: drop them")
        if workers < 1:
            raise FacegenError(f"--workers {workers} must be at least 1")
        manifest = build(out, seed=seed, workers=workers, limit=limit, say=_progress(quiet))
        failed = sum("error" in e for e in manifest["done"].values())
        click.echo(f"{len(manifest['done']) - failed} sequences in {out}" + (f" ({failed} failed)" if failed else ""))
        return
    if limit is not None:
        raise FacegenError("--limit applies to --preset voices only: drop it")
    from facegen.synth.corpus import synthesize_corpus

    report = synthesize_corpus(out, subjects, sentences, preset=preset, fps=fps, seed=seed, workers=workers,
                               progress=not quiet)
    click.echo(report.summary())


def main(argv: list[str] | None = None) -> None:
    """Run the command line `argv` and exit: 0 done, 1 a check or item failed (or an internal error), 2 a user
    error (one line), 130 Ctrl-C, 128 + N signal N.

    Called without `argv` (the `facegen` script, `python -m facegen`) it is the whole process: once the command
    has returned (its outputs written, closed and renamed into place), it runs the atexit handlers (the
    FACEGEN_PROFILE report among them), flushes stdout and stderr and ends with os._exit, skipping the
    interpreter's teardown (about a second of freeing torch's and pxr's objects). With `argv` (tests, callers
    in a process of their own) it raises SystemExit as usual. `--debug` lets errors propagate with their
    traceback, through the usual exit.
    """
    import os

    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # before torch loads OpenMP: no spinning on busy cores
    whole_process = argv is None
    argv = sys.argv[1:] if argv is None else argv
    debug = "--debug" in argv
    from facegen.runtime import stop_on_signals

    stop_on_signals()
    try:
        code = _run(argv, debug)
    except SystemExit as exc:  # a command's own exit code (validate: 1 when a check fails, batch: 1 ...)
        code = exc.code
    if not isinstance(code, int):  # sys.exit() or sys.exit("message"), as Python ends on them
        if code is not None:
            click.echo(str(code), err=True)
        code = 0 if code is None else 1
    if whole_process:
        _exit_now(code)
    sys.exit(code)


def _run(argv: list[str], debug: bool) -> int:
    """The command's exit code; errors a user can cause, interrupts and internal errors said in one line."""
    try:
        cli.main(args=argv, prog_name="facegen", standalone_mode=False)
        return 0
    except FacegenError as exc:
        if debug:
            raise
        click.echo(f"facegen: error: {exc}", err=True)
        return 2
    except click.exceptions.Abort as exc:  # click turns KeyboardInterrupt (and Terminated) into Abort
        return _interrupted(exc.__cause__)
    except click.ClickException as exc:
        hint = f" (see '{exc.ctx.command_path} --help')" if getattr(exc, "ctx", None) else ""
        click.echo(f"facegen: error: {exc.format_message()}{hint}", err=True)
        return exc.exit_code
    except KeyboardInterrupt as exc:
        return _interrupted(exc)
    except Exception as exc:
        if debug:
            raise
        click.echo(f"facegen: internal error: {type(exc).__name__}: {exc} (rerun with --debug and report it)",
                   err=True)
        return 1


def _exit_now(code: int) -> None:
    """End the process with `code` without the interpreter's teardown, after what the interpreter would still do
    that matters: wait for non-daemon threads, run the atexit handlers (the profile report, multiprocessing's
    clean-up), flush stdout and stderr."""
    import atexit
    import os
    import threading

    for thread in threading.enumerate():
        if thread is not threading.current_thread() and not thread.daemon:
            thread.join()
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (AttributeError, OSError, ValueError):  # closed, or a reader that went away (facegen ... | head)
            pass
    os._exit(code)


def _interrupted(exc: BaseException | None) -> int:
    """The exit code after Ctrl-C (130) or SIGTERM/SIGHUP (128 + the signal), said in one line."""
    from facegen.runtime import Terminated

    if isinstance(exc, Terminated):
        import signal

        click.echo(f"facegen: stopped by {signal.Signals(exc.signum).name}", err=True)
        return 128 + exc.signum
    click.echo("facegen: interrupted", err=True)
    return 130
