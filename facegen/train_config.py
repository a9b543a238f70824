"""What a training run makes, as data: `TrainConfig` (no torch or numpy: the CLI reads its defaults).

`facegen train` takes its option defaults from it, `facegen.train.train` takes one, and the bundle's
provenance is written from it (`provenance`). Where and how a run happens is not part of it and stays an
argument of `train`: the device and thread count, resuming, the checkpoint and cache folders, where the
text model's files are, what to do with an unusable sequence, and progress output.

Defaults follow the paper: mean squared error over all vertex coordinates, Adam with a constant learning
rate of 1e-4, one sequence per step, 100 epochs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from facegen.datasets.splits import Splits
from facegen.errors import FacegenError
from facegen.model_config import FUSIONS, MODALITIES

OUTPUT_LAYERS = ("full", "pca")  # the paper's FC 3V, or the same layer trained in a PCA basis


@dataclass(frozen=True)
class TrainConfig:
    """The settings that decide a trained model.

    `modalities` both|audio|text and `fusion` tensor|concat choose the network (facegen.model);
    `text_backend` the language model (facegen.text: minilm, gpt2, a Hugging Face id or a local folder).
    `batch_size` > 1 averages the gradients of that many sequences per optimizer step (never padded).
    `splits` are the dataset's subjects and sentences (its training subjects become the speakers);
    `max_sequences` caps the training and validation sequences (taken round-robin over subjects).
    `model_options` overrides ModelConfig sizes (e.g. small models for tests). `precision` (fp32, fp16,
    int8; see facegen.bundle) is how the bundle stores its weights (checkpoints are always fp32).
    `output` "full" is the paper's FC 3V; "pca" trains it in a `basis`-dimensional PCA basis of the
    training motion (facegen.train_pca; the bundle stores the folded FC 3V), where `lip_weight`,
    `upper_weight` and `velocity_weight` add lip-vertex, upper-face and frame-to-frame terms to the loss
    (0: the paper's MSE). `text_free_lips` (pca, audio and text) adds a second pass with zero text features
    whose lips fit the target and which the full pass's lips follow, weighted so: the words then move the
    upper face but not the lips (the synthetic teacher's lips never depend on them). `patience` stops after
    that many epochs without a better validation loss (None: every epoch runs). `phones` adds the phone
    stream (per-frame phones from the dataset's alignment JSON) to the audio encoder. `init` is a bundle
    whose weights the run starts from (fine-tuning: facegen.train_init), None: a random initialisation.
    """

    text_backend: str = "minilm"
    modalities: str = "both"
    fusion: str = "tensor"
    epochs: int = 100
    lr: float = 1e-4
    batch_size: int = 1
    seed: int = 0
    splits: Splits = field(default_factory=Splits)
    max_sequences: int | None = None
    model_options: dict = field(default_factory=dict)
    precision: str = "fp32"
    output: str = "full"
    basis: int = 64
    lip_weight: float = 0.0
    velocity_weight: float = 0.0
    upper_weight: float = 0.0
    text_free_lips: float = 0.0
    patience: int | None = None
    phones: bool = False
    init: str | None = None

    def check(self) -> None:
        """Raise FacegenError for a setting no run can use (before any data is read)."""
        from facegen.bundle import PRECISIONS  # numpy: not on the CLI's start-up path
        if self.modalities not in MODALITIES:
            raise FacegenError(f"unknown modalities {self.modalities!r}: choose one of "
                               f"{', '.join(MODALITIES)}", param="modalities")
        if self.fusion not in FUSIONS:
            raise FacegenError(f"unknown fusion {self.fusion!r}: choose one of {', '.join(FUSIONS)}",
                               param="fusion")
        if (self.epochs < 1 or self.batch_size < 1 or not self.lr > 0
                or (self.max_sequences is not None and self.max_sequences < 1)):
            raise FacegenError("epochs, batch size and max sequences must be at least 1 and the learning "
                               "rate positive", param=("epochs", "batch_size", "max_sequences", "lr"))
        if self.output not in OUTPUT_LAYERS:
            raise FacegenError(f"unknown output layer {self.output!r}: choose full (the paper's FC 3V) or "
                               "pca", param="output")
        if self.output == "pca" and self.basis < 1:
            raise FacegenError(f"the basis must have at least 1 dimension, got {self.basis}", param="basis")
        weights = (self.lip_weight, self.upper_weight, self.velocity_weight, self.text_free_lips)
        names = ("lip_weight", "upper_weight", "velocity_weight", "text_free_lips")
        if not (min(weights) >= 0 and math.isfinite(sum(weights))):
            raise FacegenError("the lip, upper-face, velocity and text-free lips weights must be finite and "
                               "at least 0", param=names)
        if any(weights) and self.output != "pca":
            raise FacegenError("the lip, upper-face, velocity and text-free lips weights need the pca output "
                               "layer", param=(*names, "output"))
        if self.text_free_lips and self.modalities != "both":
            raise FacegenError("text-free lips need a model of audio and text (modalities both)",
                               param=("text_free_lips", "modalities"))
        if self.patience is not None and self.patience < 1:
            raise FacegenError(f"the patience must be at least 1 epoch, got {self.patience}",
                               param="patience")
        if self.precision not in PRECISIONS:
            raise FacegenError(f"unknown precision {self.precision!r}: use one of {', '.join(PRECISIONS)}",
                               param="precision")

    def provenance(self, run: dict) -> dict:
        """The bundle's provenance: this config's settings among what the run measured.

        `run` holds data, epochs, best_epoch, best_loss, loss, metrics, history, train_seconds,
        train_sequences, val_sequences, device and (with the pca output layer) basis_variance. The keys
        come in the order bundles have always had them.
        """
        out = {k: run[k] for k in ("data", "epochs", "best_epoch", "best_loss", "loss", "metrics", "history",
                                   "train_seconds")}
        out.update(split=self.splits.to_dict(), train_sequences=run["train_sequences"],
                   val_sequences=run["val_sequences"], seed=self.seed, lr=self.lr, batch_size=self.batch_size,
                   device=run["device"], output=self.output)
        if self.output == "pca":
            out.update(basis=self.basis, basis_variance=run["basis_variance"], lip_weight=self.lip_weight,
                       velocity_weight=self.velocity_weight, upper_weight=self.upper_weight)
            if self.text_free_lips:
                out["text_free_lips"] = self.text_free_lips
        if self.patience:
            out["patience"] = self.patience
        if self.phones:
            out["phones"] = "per-frame CMU phones"
        if self.init:
            out["init"] = run.get("init", self.init)
        return out
