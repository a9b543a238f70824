"""Training: a TrainConfig (facegen.train_config; the paper's setup by default) on a dataset in the BIWI
community layout, resumable and deterministic. `train` runs it in steps: check the output paths, load the data
and its features, fit the PCA basis (output "pca"), build the model (`_Run`), resume, run the epochs,
write the bundle.

Every epoch: the validation loss is computed, the weights with the lowest validation loss so far are
kept (without a validation split, the lowest training loss), and one checkpoint file is written
atomically (safetensors + JSON metadata: weights, best weights, Adam state, RNG state, epoch, loss
history — no pickle), together with the loss curves (loss.csv, loss.png). `resume=True` continues from
that checkpoint, so a killed run loses at most the epoch in progress, and the result is identical to an
uninterrupted run: the order of sequences in epoch e depends only on (seed, e).

On CPU the run is deterministic for a given seed and thread count (torch.use_deterministic_algorithms).
The model written is the best checkpoint, as a bundle (facegen.bundle) with the dataset's BIWI.ply as
its template, the training subjects as its speakers, and provenance (data, epochs, best epoch, losses,
the per-epoch loss history, training time, split).

Speed on CPU: fused Adam, gradients freed rather than zeroed, denormals flushed (Adam's second moments
of the zero-initialised output layer otherwise fall into slow denormal arithmetic), the big per-step
buffers kept in the heap (see _reuse_heap), features computed once and cached, targets read from
memory-mapped .npy files as contiguous float32. Threads: spinning OpenMP threads on busy cores made
2-thread steps 3-5x slower than 1-thread ones, and sleeping ones (OMP_WAIT_POLICY=PASSIVE) made them 3.7x
slower even on idle cores (benchmarks/bench_train.py, 2 cores: 1 thread 16.1 sequences/s, 2 passive 4.3,
2 spinning 17.9); so `facegen train` sets PASSIVE and trains on 1 thread unless told otherwise.
"""

from __future__ import annotations

import contextlib
import csv
import ctypes
import json
import math
import os
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from facegen.atomic import atomic_path, check_writable
from facegen.audio import FeatureConfig
from facegen.errors import FacegenError
from facegen.model import FaceModel, ModelConfig
from facegen.phonetics import PHONES
from facegen.plot_basics import plot_loss_curves
from facegen.runtime import STDERR, Reporter, select_device
from facegen.runtime import threads as thread_limit
from facegen.train_config import TrainConfig
from facegen.train_data import Batch, PcaTargets, TrainData, load_train_data, make_batches, pca_targets

CHECKPOINT = "checkpoint.safetensors"
CHECKPOINT_VERSION = 1
MIN_MEL_STD = 1.0  # dB: a mel band that barely varies in training is not amplified
PNG_EVERY = 30.0  # seconds between redraws of loss.png during training (it is always drawn at the end)


@dataclass
class TrainResult:
    bundle: Path
    checkpoint_dir: Path
    epochs: int  # epochs completed in total (including resumed ones)
    epochs_run: int  # epochs run by this call
    best_epoch: int
    best_loss: float  # validation loss of the best epoch (training loss without a validation split)
    history: list[dict] = field(default_factory=list)
    seconds: float = 0.0  # training time in total, over all resumed runs
    curves_csv: Path | None = None
    curves_png: Path | None = None
    train_sequences: int = 0
    val_sequences: int = 0
    skipped: list[tuple[str, str]] = field(default_factory=list)


@contextlib.contextmanager
def _reuse_heap() -> Iterator[None]:
    """Keep freed memory in the process (glibc) instead of unmapping it after every step.

    A training step allocates ~200 MB of short-lived buffers (outputs, gradients, targets), each above
    glibc's mmap threshold: by default every one is mapped and unmapped again, costing ~30,000 page
    faults and ~18% of a step's CPU time. With mmap off and a high trim threshold the heap keeps them.
    Elsewhere than glibc this does nothing.
    """
    try:
        libc = ctypes.CDLL("libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        yield
        return
    m_trim_threshold, m_mmap_max = -1, -4
    mallopt(m_mmap_max, 0)
    mallopt(m_trim_threshold, 1 << 30)
    try:
        yield
    finally:  # glibc's defaults
        mallopt(m_mmap_max, 65536)
        mallopt(m_trim_threshold, 128 * 1024)


@contextlib.contextmanager
def torch_settings(threads: int | None) -> Iterator[None]:
    """Deterministic algorithms, flushed denormals, the thread count and heap reuse, restored afterwards.
    `threads` None: 1 while OpenMP threads sleep between steps (OMP_WAIT_POLICY=PASSIVE, see above), else all
    cores."""
    if threads is None and os.environ.get("OMP_WAIT_POLICY", "").upper() == "PASSIVE":
        threads = 1
    deterministic = torch.are_deterministic_algorithms_enabled()
    warn_only = torch.is_deterministic_algorithms_warn_only_enabled()
    torch.use_deterministic_algorithms(True, warn_only=True)
    torch.set_flush_denormal(True)
    try:
        with thread_limit(threads, ("torch",)), _reuse_heap():
            yield
    finally:
        torch.use_deterministic_algorithms(deterministic, warn_only=warn_only)
        torch.set_flush_denormal(False)


class _NonFinite(Exception):
    def __init__(self, name: str, value: float) -> None:
        super().__init__(name, value)
        self.name, self.value = name, value


def epoch_order(seed: int, epoch: int, n: int) -> np.ndarray:
    """The order of the training sequences in `epoch`: a function of (seed, epoch) only."""
    return np.random.default_rng([seed, epoch]).permutation(n)


def train_epoch(model: FaceModel, optimizer: torch.optim.Optimizer, batches: list[Batch], order,
                batch_size: int = 1, bar=None, coefficient_loss=None) -> float:
    """One pass over `batches` in `order`, one optimizer step per `batch_size` sequences; the mean loss.

    Raises _NonFinite at the first NaN or infinite loss (before it reaches the weights).
    """
    model.train()
    optimizer.zero_grad(set_to_none=True)
    total = 0.0
    for step, index in enumerate(order):
        batch = batches[index]
        loss = batch.loss(model, coefficient_loss)
        value = float(loss.detach())
        if not math.isfinite(value):
            raise _NonFinite(batch.item.name, value)
        (loss / batch_size if batch_size > 1 else loss).backward()
        if (step + 1) % batch_size == 0 or step + 1 == len(order):
            optimizer.step()
            optimizer.zero_grad(set_to_none=True)
        total += value
        if bar is not None:
            bar.update(1)
            if step % 8 == 0:
                bar.set_postfix(loss=f"{total / (step + 1):.3e}")
    return total / max(len(order), 1)


def _validate(model: FaceModel, batches: list[Batch], coefficient_loss=None) -> float:
    if not batches:
        return float("nan")
    model.eval()
    with torch.no_grad():
        losses = [float(b.loss(model, coefficient_loss)) for b in batches]
    model.train()
    return float(np.mean(losses))


# ------------------------------------------------------------------------------------- checkpoints
def _state_tensors(prefix: str, state: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    return {f"{prefix}.{k}": v.detach().cpu().contiguous().clone() for k, v in state.items()}


def save_checkpoint(path: Path, model: FaceModel, best: dict[str, torch.Tensor],
                    optimizer: torch.optim.Optimizer, meta: dict) -> None:
    """Weights, best weights, Adam state and RNG state in one safetensors file, written atomically."""
    from safetensors.torch import save_file

    tensors = _state_tensors("model", model.state_dict())
    tensors.update(_state_tensors("best", best))
    opt = optimizer.state_dict()
    for pid, state in opt["state"].items():
        for key, value in state.items():
            if torch.is_tensor(value):
                tensors[f"optim.{pid}.{key}"] = value.detach().cpu().contiguous().clone()
    tensors["rng.torch"] = torch.get_rng_state()
    groups = [{k: list(v) if isinstance(v, tuple) else v for k, v in g.items()} for g in opt["param_groups"]]
    meta = dict(meta, version=CHECKPOINT_VERSION, param_groups=groups)
    with atomic_path(path) as tmp:
        save_file(tensors, str(tmp), metadata={"facegen_checkpoint": json.dumps(meta)})


def load_checkpoint(path: Path) -> tuple[dict[str, torch.Tensor], dict]:
    from safetensors import safe_open
    from safetensors.torch import load_file

    try:
        with safe_open(str(path), framework="pt") as f:
            meta = json.loads((f.metadata() or {})["facegen_checkpoint"])
        tensors = load_file(str(path))
    except Exception as exc:  # safetensors has its own error types
        raise FacegenError(f"checkpoint {path} is unreadable ({exc}): delete it and train without "
                           "resuming", param="resume") from exc
    if meta.get("version", 0) > CHECKPOINT_VERSION:
        raise FacegenError(f"checkpoint {path} was written by a newer facegen: upgrade facegen")
    return tensors, meta


def _restore(tensors: dict[str, torch.Tensor], meta: dict, model: FaceModel,
             optimizer: torch.optim.Optimizer) -> dict[str, torch.Tensor]:
    def part(prefix: str) -> dict[str, torch.Tensor]:
        n = len(prefix) + 1
        return {k[n:]: v for k, v in tensors.items() if k.startswith(prefix + ".")}

    model.load_state_dict(part("model"))
    state: dict[int, dict] = {}
    for key, value in part("optim").items():
        pid, name = key.split(".", 1)
        state.setdefault(int(pid), {})[name] = value
    groups = [{k: tuple(v) if k == "betas" else v for k, v in g.items()} for g in meta["param_groups"]]
    optimizer.load_state_dict({"state": state, "param_groups": groups})
    torch.set_rng_state(tensors["rng.torch"])
    return part("best")


# ------------------------------------------------------------------------------------------ curves
def write_curves(history: list[dict], folder: Path, png: bool = True) -> tuple[Path, Path | None]:
    """loss.csv and (with `png`) loss.png in `folder`."""
    csv_path = folder / "loss.csv"
    with atomic_path(csv_path) as tmp, open(tmp, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["epoch", "train_loss", "val_loss", "seconds"])
        for h in history:
            writer.writerow([h["epoch"], f"{h['train_loss']:.6e}", f"{h['val_loss']:.6e}",
                             f"{h['seconds']:.2f}"])
    if not png:
        return csv_path, None
    return csv_path, plot_loss_curves(history, folder / "loss.png", figsize=(6, 4))


def loss_history(history: list[dict]) -> list[dict]:
    """The per-epoch losses for the bundle's provenance: epoch, train_loss, val_loss (None without a
    validation split), 6 significant digits (a few KB for hundreds of epochs)."""
    def short(x: float) -> float | None:
        return None if not math.isfinite(x) else float(f"{x:.6g}")

    return [{"epoch": int(h["epoch"]), "train_loss": short(h["train_loss"]), "val_loss": short(h["val_loss"])}
            for h in history]


# ----------------------------------------------------------------------------------------- training
def default_checkpoint_dir(out_bundle: str | os.PathLike) -> Path:
    """model.safetensors → model.ckpt/ beside it."""
    out = Path(out_bundle)
    return out.with_name(out.stem + ".ckpt")


def train(
    data_root: str | os.PathLike,
    out_bundle: str | os.PathLike,
    config: TrainConfig | None = None,
    *,
    device: str = "auto",
    threads: int | None = None,
    resume: bool = False,
    checkpoint_dir: str | os.PathLike | None = None,
    cache_dir: str | os.PathLike | None = None,
    text_model_path: str | os.PathLike | None = None,
    on_bad: str = "skip",
    reporter: Reporter = STDERR,
) -> TrainResult:
    """Train the model `config` describes (default: the paper's setup) on the dataset at `data_root`;
    write the best epoch's weights as a bundle to `out_bundle`.

    The rest is how the run happens: `device` (auto, cpu, cuda) and `threads` (torch's CPU threads, None: all
    cores, or 1 under OMP_WAIT_POLICY=PASSIVE); `resume` continues from the checkpoint in `checkpoint_dir`
    (default: default_checkpoint_dir); `cache_dir` holds the dataset's features (default: the dataset's own);
    `text_model_path` is where the text model's files are; `on_bad` "skip" reports and skips unusable
    sequences, "fail" stops at the first; `reporter` (default: on stderr) gets the progress messages and bars,
    and the skipped sequences as its notes (Reporter.stderr(quiet=True): notes only).
    """
    config = config or TrainConfig()
    config.check()
    say = reporter.progress
    out_bundle, ckpt_dir = _output_paths(Path(out_bundle), checkpoint_dir)
    dev = select_device(device)
    data = load_train_data(data_root, config, cache_dir, text_model_path, on_bad, reporter)
    cfg = ModelConfig(num_vertices=data.mesh.num_vertices, num_speakers=len(config.splits.train_subjects),
                      text_dim=data.backend.dim if data.backend is not None else 0,
                      modalities=config.modalities, fusion=config.fusion,
                      output_basis=config.basis if config.output == "pca" else 0,
                      n_phones=len(PHONES) if config.phones else 0, **config.model_options)
    basis = pca_targets(config, data, dev, reporter) if config.output == "pca" else None
    signature = {
        "model_config": cfg.to_dict(), "feature_config": data.features.to_dict(),
        "text_backend": data.backend.id if data.backend is not None else "none",
        "splits": config.splits.to_dict(), "seed": config.seed, "batch_size": config.batch_size,
        "train": [it.name for it in data.train], "val": [it.name for it in data.val], "output": config.output,
        "lip_weight": config.lip_weight, "velocity_weight": config.velocity_weight,
        **({"upper_weight": config.upper_weight} if config.upper_weight else {}),
        **({"text_free_lips": config.text_free_lips} if config.text_free_lips else {}),
        **({"init": str(config.init)} if config.init else {}),
    }
    with torch_settings(threads):
        run = _Run(config, cfg, data, basis, dev, ckpt_dir, reporter)
        if resume:
            run.resume(signature)
        try:
            ckpt_dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise FacegenError(f"cannot create the checkpoint folder {ckpt_dir} ({exc.strerror}): "
                               "pass a writable checkpoint folder", param="checkpoint_dir") from exc
        train_batches, val_batches = make_batches(data, config, basis, dev)
        say(f"training {config.modalities} ({config.fusion}) on {len(train_batches)} sequences, validating "
            f"on {len(val_batches)}, {config.epochs} epochs, device {dev}")
        seconds = run.epochs(train_batches, val_batches, basis, signature)
        csv_path, png_path = write_curves(run.history, ckpt_dir)
        run.model.load_state_dict(run.best_state)
        history, best_epoch, best_loss = run.history, run.best_epoch, run.best_loss
        provenance = config.provenance({
            "data": data.dataset.root.resolve().name, "epochs": len(history), "best_epoch": best_epoch,
            "best_loss": best_loss, "loss": "val" if val_batches else "train",
            "metrics": ({k: history[best_epoch - 1][k] for k in ("train_loss", "val_loss")}
                        if best_epoch else {}),
            "history": loss_history(history), "train_seconds": round(seconds, 1),
            "train_sequences": len(train_batches), "val_sequences": len(val_batches), "device": str(dev),
            "basis_variance": round(basis.kept, 6) if basis is not None else None})
        from facegen.bundle import save_bundle

        bundle = _make_bundle(run.model.cpu().eval(), data, list(config.splits.train_subjects), provenance)
        save_bundle(bundle, out_bundle, precision=config.precision)
        say(f"wrote {out_bundle} (best epoch {best_epoch}, {'validation' if val_batches else 'training'} "
            f"loss {best_loss:.4e}); curves in {csv_path}" + (f" and {png_path}" if png_path else ""))
    return TrainResult(bundle=out_bundle, checkpoint_dir=ckpt_dir, epochs=len(history),
                       epochs_run=run.epochs_run, best_epoch=best_epoch, best_loss=best_loss, history=history,
                       seconds=seconds, curves_csv=csv_path, curves_png=png_path,
                       train_sequences=len(train_batches), val_sequences=len(val_batches),
                       skipped=list(data.dataset.skipped))


def _output_paths(out_bundle: Path, checkpoint_dir: str | os.PathLike | None) -> tuple[Path, Path]:
    """The bundle's path and the checkpoint folder, both checked writable before hours of training."""
    if out_bundle.suffix.lower() != ".safetensors":
        given = out_bundle.suffix or "a name without extension"
        raise FacegenError(f"a model bundle is a .safetensors file, not {given}: name it "
                           f"{out_bundle.with_suffix('.safetensors').name}", param="out_bundle")
    check_writable(out_bundle)
    ckpt_dir = Path(checkpoint_dir) if checkpoint_dir is not None else default_checkpoint_dir(out_bundle)
    existing = next(p for p in (ckpt_dir.absolute(), *ckpt_dir.absolute().parents) if p.exists())
    if not existing.is_dir() or not os.access(existing, os.W_OK):
        raise FacegenError(f"cannot write the checkpoint folder {ckpt_dir} ({existing} is not a writable "
                           "folder): pass a writable checkpoint folder", param="checkpoint_dir")
    return out_bundle, ckpt_dir


class _Run:
    """The model and optimizer of one train() call and where training stands (epochs done, loss history,
    the best epoch's weights), with the steps that move it on: resume, epochs."""

    def __init__(self, config: TrainConfig, cfg: ModelConfig, data: TrainData, basis: PcaTargets | None,
                 dev: torch.device, ckpt_dir: Path, reporter: Reporter) -> None:
        self.config, self.ckpt_dir, self.reporter = config, ckpt_dir, reporter
        torch.manual_seed(config.seed)
        model = FaceModel(cfg)
        if basis is not None:
            model.set_basis(torch.from_numpy(basis.pca), torch.from_numpy(basis.mean))
        if config.init:  # fine-tuning: its weights and mel normalisation
            from facegen.train_init import warm_start

            warm_start(model, config.init, data.features)
        else:
            mels = np.concatenate([it.mel for it in data.train]).astype(np.float64)
            with torch.no_grad():
                model.mel_mean.copy_(torch.from_numpy(mels.mean(0)).float())
                model.mel_std.copy_(torch.from_numpy(mels.std(0)).float().clamp(min=MIN_MEL_STD))
        self.model = model.to(dev).train()
        self.optimizer = torch.optim.Adam(model.parameters(), lr=config.lr, fused=dev.type in ("cpu", "cuda"))
        self.best_state = {k: v.detach().cpu().clone() for k, v in model.state_dict().items()}
        self.history: list[dict] = []
        self.best_epoch, self.best_loss = 0, math.inf
        self.done, self.seconds_before = 0, 0.0  # epochs of earlier calls (resumed) and their time
        self.epochs_run = 0  # epochs of this call

    def resume(self, signature: dict) -> None:
        """Continue from the checkpoint when there is one made with the same `signature`."""
        path, lr, say = self.ckpt_dir / CHECKPOINT, self.config.lr, self.reporter.progress
        if not path.is_file():
            say(f"no checkpoint in {self.ckpt_dir}: starting from scratch")
            return
        tensors, meta = load_checkpoint(path)
        stored = dict(meta.get("signature", {}))
        if "feature_config" in stored:  # written before a feature setting existed: its default
            stored["feature_config"] = FeatureConfig.from_dict(stored["feature_config"]).to_dict()
        differs = [k for k in {**signature, **stored} if stored.get(k) != signature.get(k)]
        if differs:
            raise FacegenError(f"checkpoint {path} was made with a different setup ({', '.join(differs)} "
                               "differ): train without resuming, or with another checkpoint folder",
                               param=("resume", "checkpoint_dir"))
        self.best_state = _restore(tensors, meta, self.model, self.optimizer)
        self.history, self.done = meta["history"], int(meta["epoch"])
        self.best_epoch, self.best_loss = int(meta["best_epoch"]), float(meta["best_loss"])
        self.seconds_before = float(meta.get("seconds", 0.0))
        for group in self.optimizer.param_groups:
            if group["lr"] != lr:
                say(f"learning rate changed from {group['lr']:g} to {lr:g}")
                group["lr"] = lr
        say(f"resuming after epoch {self.done} from {path}")

    def epochs(self, train_batches: list[Batch], val_batches: list[Batch], basis: PcaTargets | None,
               signature: dict) -> float:
        """Run the epochs left (a checkpoint and the curves after each); the training time in total (s)."""
        config, ckpt_dir, say = self.config, self.ckpt_dir, self.reporter.progress
        run_start = last_png = time.perf_counter()
        for epoch in range(self.done, config.epochs):
            if config.patience is not None and self.best_epoch and epoch - self.best_epoch >= config.patience:
                say(f"no better validation loss for {config.patience} epochs: stopping after epoch {epoch}")
                break
            t0 = time.perf_counter()
            order = epoch_order(config.seed, epoch, len(train_batches))
            bar = self.reporter.bar(total=len(order), desc=f"epoch {epoch + 1}/{config.epochs}", unit="seq",
                                    leave=False)
            try:
                train_loss = train_epoch(self.model, self.optimizer, train_batches, order, config.batch_size,
                                         bar, basis.loss if basis is not None else None)
            except _NonFinite as exc:
                kept = (f"the last good checkpoint (epoch {epoch}) is in {ckpt_dir}" if epoch else
                        "no checkpoint was written yet")
                raise FacegenError(
                    f"the training loss became {exc.value} at epoch {epoch + 1} on {exc.name}: training "
                    f"stopped and {kept}: lower the learning rate (and resume), or check that sequence",
                    param=("lr", "resume")) from None
            bar.close()
            val_loss = _validate(self.model, val_batches, basis.val_loss if basis is not None else None)
            score = val_loss if val_batches else train_loss
            improved = score < self.best_loss
            if improved:
                self.best_epoch, self.best_loss = epoch + 1, score
                self.best_state = {k: v.detach().cpu().clone() for k, v in self.model.state_dict().items()}
            self.history.append({"epoch": epoch + 1, "train_loss": train_loss, "val_loss": val_loss,
                                 "seconds": time.perf_counter() - t0})
            self.epochs_run += 1
            save_checkpoint(ckpt_dir / CHECKPOINT, self.model, self.best_state, self.optimizer, {
                "signature": signature, "epoch": epoch + 1, "history": self.history,
                "best_epoch": self.best_epoch, "best_loss": self.best_loss,
                "seconds": self.seconds_before + time.perf_counter() - run_start})
            png = time.perf_counter() - last_png > PNG_EVERY  # drawing takes ~0.3 s: not after short epochs
            write_curves(self.history, ckpt_dir, png=png)
            if png:
                last_png = time.perf_counter()
            say(f"epoch {epoch + 1}/{config.epochs}: train {train_loss:.4e}  val {val_loss:.4e}  "
                f"({self.history[-1]['seconds']:.1f} s){'  best' if improved else ''}")
        return self.seconds_before + time.perf_counter() - run_start


def _make_bundle(model: FaceModel, data: TrainData, speakers: list[str], provenance: dict):
    """The bundle of a trained model: its features, the dataset's face as template, speakers, provenance."""
    from facegen import __version__
    from facegen.bundle import Bundle
    from facegen.face.mesh import Mesh

    mesh = data.mesh
    template = Mesh(mesh.vertices.astype(np.float32), mesh.faces, dict(mesh.regions))
    return Bundle(model=model, features=data.features, mel_filters=data.filters,
                  text_backend=data.backend.id if data.backend is not None else "none",
                  speakers=speakers, template=template,
                  provenance=dict(provenance, facegen=__version__,
                                  trained=time.strftime("%Y-%m-%dT%H:%M:%S%z")))
