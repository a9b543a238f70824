"""`facegen info`, `facegen train`, `facegen evaluate`: model bundles."""

from __future__ import annotations

import json
from pathlib import Path

import click

from facegen.cli.command import Command
from facegen.cli.options import DEVICE, WEIGHT, FiniteRange, split_options, splits
from facegen.model_config import FUSIONS, MODALITIES
from facegen.runtime import Reporter
from facegen.train_config import OUTPUT_LAYERS, TrainConfig


@click.command(cls=Command)
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
    regions = ", ".join(f"{k} ({v} vertices)" for k, v in meta.get("regions", {}).items())
    lines = [
        f"model bundle   {path}",
        f"format         {meta['format_version']}",
        f"network        modalities={cfg['modalities']} fusion={cfg['fusion']} text_dim={cfg['text_dim']}"
        + (f" phone stream ({cfg['n_phones']} phones)" if cfg.get('n_phones') else ""),
        f"text backend   {meta['text_backend']['id']} ({meta['text_backend']['dim']}-d)",
        f"audio          {feat['n_mels']} mel bands, {feat['sample_rate']} Hz, {feat['fps']:g} fps",
        f"speakers       {', '.join(f'{i}={s}' for i, s in enumerate(meta['speakers']))}",
        (f"topology       {topo['num_vertices']} vertices, {topo['num_faces']} faces, "
         f"fingerprint {topo['fingerprint']}"),
        f"regions        {regions or 'none'}",
    ]
    for k, v in meta.get("provenance", {}).items():
        if k == "history":
            v = f"{len(v)} epochs of train/val loss (see --json)"
        lines.append(f"{k:<14} {json.dumps(v) if isinstance(v, dict | list) else v}")
    click.echo("\n".join(lines))


@click.command(cls=Command, given_by={"output": ("output_layer",)})  # train(output=...) is the layer
@click.argument("data", type=click.Path(file_okay=False))
@click.option("--output", "-o", required=True, type=click.Path(dir_okay=False),
              help="The model bundle to write.")
@click.option("--text-backend", default=TrainConfig.text_backend, show_default=True,
              help="minilm (offline default), gpt2 (the paper's), or a Hugging Face id / local folder.")
@click.option("--text-model", type=click.Path(), help="Local folder with the text model's weights.")
@click.option("--modalities", type=click.Choice(MODALITIES), default=TrainConfig.modalities,
              show_default=True)
@click.option("--fusion", type=click.Choice(FUSIONS), default=TrainConfig.fusion, show_default=True)
@click.option("--epochs", type=click.IntRange(min=1), default=TrainConfig.epochs, show_default=True)
@click.option("--lr", type=FiniteRange(0, 10, min_open=True), default=TrainConfig.lr, show_default=True)
@click.option("--batch-size", type=click.IntRange(min=1), default=TrainConfig.batch_size, show_default=True)
@click.option("--seed", type=int, default=TrainConfig.seed, show_default=True)
@click.option("--device", type=DEVICE, default="auto", show_default=True)
@click.option("--resume", is_flag=True,
              help="Continue from the last checkpoint (after a kill or with more epochs).")
@click.option("--checkpoint-dir", type=click.Path(file_okay=False), help="Default: OUTPUT's name + '.ckpt/'.")
@click.option("--precision", type=click.Choice(["fp32", "fp16", "int8"]), default=TrainConfig.precision,
              show_default=True,
              help="How the bundle stores its weights.")
@click.option("--threads", type=click.IntRange(1, 1024),
              help="CPU threads for torch (default: 1 while OpenMP threads sleep between steps, "
              "OMP_WAIT_POLICY=PASSIVE, facegen's setting; all cores with OMP_WAIT_POLICY=ACTIVE).")
@click.option("--strict", is_flag=True,
              help="Refuse to train when a sequence is missing or corrupt (default: skip it).")
@click.option("--output-layer", "output_layer", type=click.Choice(OUTPUT_LAYERS), default=TrainConfig.output,
              show_default=True,
              help="full: the paper's FC 3V; pca: the same layer trained in a PCA basis of the training "
                   "motion.")
@click.option("--basis", type=click.IntRange(min=1), default=TrainConfig.basis, show_default=True,
              help="Dimensions of the PCA basis (--output-layer pca).")
@click.option("--lip-weight", type=WEIGHT, default=TrainConfig.lip_weight, show_default=True,
              help="Extra loss on the lip vertices (pca only).")
@click.option("--velocity-weight", type=WEIGHT, default=TrainConfig.velocity_weight, show_default=True,
              help="Loss on frame-to-frame motion (pca only).")
@click.option("--upper-weight", type=WEIGHT, default=TrainConfig.upper_weight, show_default=True,
              help="Extra loss on the upper-face vertices (pca only).")
@click.option("--text-free-lips", "text_free_lips", type=WEIGHT, default=TrainConfig.text_free_lips,
              show_default=True,
              help="Weight of a second pass without the words whose lips must fit too and which the full "
                   "pass's lips follow: the words move the upper face, not the lips (pca only).")
@click.option("--patience", type=click.IntRange(min=1),
              help="Stop after this many epochs without a better validation loss.")
@click.option("--phones", is_flag=True, help="Add the phone stream (per-frame phones) to the audio encoder.")
@click.option("--init", type=click.Path(dir_okay=False),
              help="Start from this bundle's weights (fine-tuning; the same network and features).")
@split_options
@click.option("--quiet", "-q", is_flag=True)
def train(data, output, text_backend, text_model, modalities, fusion, epochs, lr, batch_size, seed, device,
          resume, checkpoint_dir, precision, threads, strict, output_layer, basis, lip_weight,
          velocity_weight, upper_weight, text_free_lips, patience, phones, init, train_subjects,
          test_subjects, train_sentences, val_sentences, test_sentences, quiet):
    """Train a model on a BIWI-layout dataset DATA (the paper's setup by default)."""
    import os

    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # busy-waiting OpenMP threads stall on shared cores
    from facegen.train import train as run

    chosen = splits(train_subjects, test_subjects, train_sentences, val_sentences, test_sentences)
    config = TrainConfig(text_backend=text_backend, modalities=modalities, fusion=fusion, epochs=epochs,
                         lr=lr, batch_size=batch_size, seed=seed, splits=chosen, precision=precision,
                         output=output_layer, basis=basis, lip_weight=lip_weight,
                         velocity_weight=velocity_weight, upper_weight=upper_weight,
                         text_free_lips=text_free_lips, patience=patience,
                         phones=phones, init=init)
    result = run(data, output, config, device=device, threads=threads, resume=resume,
                 checkpoint_dir=checkpoint_dir, text_model_path=text_model,
                 on_bad="fail" if strict else "skip", reporter=Reporter.stderr(quiet))
    click.echo(json.dumps({"bundle": str(result.bundle), "epochs": result.epochs,
                           "best_epoch": result.best_epoch, "best_loss": result.best_loss,
                           "seconds": round(result.seconds, 1),
                           "curves": str(result.curves_csv), "skipped": len(result.skipped)}))


@click.command(cls=Command)
@click.argument("bundle", type=click.Path(dir_okay=False))
@click.argument("data", type=click.Path(file_okay=False))
@click.option("--split", type=click.Choice(["test-a", "test-b", "val", "train"]), default="test-a",
              show_default=True)
@click.option("--text-model", type=click.Path(), help="Local folder with the text model's weights.")
@click.option("--device", type=DEVICE, default="cpu", show_default=True)
@split_options
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

    reporter = Reporter.stderr(quiet)
    given = (train_subjects, test_subjects, train_sentences, val_sentences, test_sentences)
    chosen = splits(*given) if any(v is not None for v in given) else None
    result = run(bundle, data, split, splits=chosen, text_model_path=text_model, device=device,
                 on_bad="fail" if strict else "skip", reporter=reporter)
    click.echo(json.dumps(result, indent=1) if as_json else format_table(result))
    if plots:
        from facegen.plots import write_plots

        for path in write_plots(bundle, data, plots, split=split, splits=chosen, text_model_path=text_model,
                                device=device, reporter=reporter):
            click.echo(f"facegen: wrote {path}", err=True)
