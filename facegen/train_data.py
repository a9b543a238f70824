"""What a training run trains on: the dataset's items with their features, the PCA targets, and the batches.

`load_train_data` reads the split's sequences and their features (computed once, cached in the dataset's
cache folder); `pca_targets` fits the basis of the training motion and projects every item onto it (for
TrainConfig.output "pca"); `make_batches` puts each sequence's tensors on the device, one `Batch` each.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import torch

from facegen.atomic import atomic_path
from facegen.audio import FeatureConfig, mel_filters
from facegen.datasets.biwi import Dataset, Item
from facegen.datasets.cache import BadSequence
from facegen.errors import FacegenError
from facegen.model import FaceModel, one_hot
from facegen.runtime import Reporter
from facegen.train_config import TrainConfig

if TYPE_CHECKING:  # imported where used: an audio-only model needs no text model, a full output no basis
    from facegen.text import TextBackend
    from facegen.train_pca import CoefficientLoss


def round_robin(names: list, key) -> list:
    """Interleave items by subject (F2_e01, F3_e01, …) so a prefix covers every subject."""
    groups: dict[str, list] = {}
    for x in names:
        groups.setdefault(key(x), []).append(x)
    out = []
    for i in range(max((len(g) for g in groups.values()), default=0)):
        out += [g[i] for g in groups.values() if i < len(g)]
    return out


class Batch:
    """One sequence's tensors on the device (features kept; the target is read per step)."""

    def __init__(self, item: Item, speaker: int, num_speakers: int, device: torch.device) -> None:
        self.item = item
        self.mel = torch.from_numpy(item.mel)[None].to(device)
        self.text = None if item.text is None else torch.from_numpy(item.text)[None].to(device)
        self.speaker = one_hot(speaker, num_speakers).to(device)
        self.template = item.template.reshape(-1)
        self.device = device

        self.coefficients: torch.Tensor | None = None  # [T, K] targets when training in a PCA basis
        self.phones: torch.Tensor | None = None  # [1, T, P] phone one-hot (models with a phone stream)

    def target(self) -> torch.Tensor:
        """Ground-truth offsets from the subject's template, [T, 3V] float32."""
        v = self.item.vertices()
        v -= self.template
        return torch.from_numpy(v).to(self.device)

    def loss(self, model: FaceModel, coefficient_loss=None) -> torch.Tensor:
        if self.coefficients is not None:
            pred = model.coefficients(self.mel, self.text, self.speaker, self.phones)[0]
            loss = coefficient_loss(pred, self.coefficients)
            weight = coefficient_loss.text_free_weight  # 0 unless the config allows it (audio and text)
            if weight:
                # the text-free pass: the lips from the sound and the phones alone (zero text features)
                # fit the target, and the full pass's lips follow them: words move the upper face, not lips
                free = model.coefficients(self.mel, torch.zeros_like(self.text), self.speaker, self.phones)[0]
                loss = loss + weight * (coefficient_loss.lips(free, self.coefficients)
                                        + coefficient_loss.lips(pred, free.detach()))
            return loss
        out = model(self.mel, self.text, self.speaker, self.phones)
        return torch.nn.functional.mse_loss(out.view(out.shape[1], -1), self.target())


@dataclass
class TrainData:
    """The dataset as a run uses it: its training and validation items with their features."""

    dataset: Dataset
    features: FeatureConfig
    filters: np.ndarray
    backend: TextBackend | None
    train: list[Item]
    val: list[Item]

    @property
    def mesh(self):
        return self.dataset.mesh


def load_train_data(data_root: str | os.PathLike, config: TrainConfig, cache_dir: str | os.PathLike | None,
                    text_model_path: str | os.PathLike | None, on_bad: str, reporter: Reporter) -> TrainData:
    """Read the split's sequences and their features (computed once, cached in the dataset's cache folder);
    `reporter` hears of the skipped sequences (its notes) and draws the bars."""
    dataset = Dataset(data_root, cache_dir=cache_dir, on_bad=on_bad, reporter=reporter)
    features = FeatureConfig()
    filters = mel_filters(features)
    backend = None
    if config.modalities in ("both", "text"):
        from facegen.text import load_text_backend

        backend = load_text_backend(config.text_backend, text_model_path)
    seqs = [dataset.split(split, config.splits) for split in ("train", "val")]
    if config.max_sequences is not None:
        seqs = [round_robin(s, lambda seq: seq.subject)[:config.max_sequences] for s in seqs]
    reporter.progress(f"features of {len(seqs[0])} training and {len(seqs[1])} validation sequences "
                      f"(cached in {dataset.cache_dir})")
    train_items, val_items = (dataset.load(s, features, filters, backend) for s in seqs)
    if not train_items:
        raise FacegenError(f"no usable training sequence in {dataset.root} for subjects "
                           f"{' '.join(config.splits.train_subjects)}: check the files named above and the "
                           "split options")
    vertices = train_items[0].template.shape[0]
    if dataset.mesh.num_vertices != vertices:
        raise FacegenError(f"{dataset.root}/BIWI.ply has {dataset.mesh.num_vertices} vertices but the "
                           f"templates have {vertices}: use the face list of this dataset")
    return TrainData(dataset, features, filters, backend, train_items, val_items)


@dataclass
class PcaTargets:
    """The PCA basis of the training motion, every item's target in it, and the losses computed in it."""

    pca: np.ndarray
    mean: np.ndarray
    kept: float  # share of the training motion's variance the basis keeps
    coefficients: dict[str, np.ndarray]
    loss: CoefficientLoss  # with the config's lip, upper-face and velocity weights (training)
    val_loss: CoefficientLoss  # the plain MSE in the basis (validation)


def pca_targets(config: TrainConfig, data: TrainData, dev: torch.device, reporter: Reporter) -> PcaTargets:
    """Fit the basis (output "pca") and project every item onto it (cached by the basis's digest)."""
    from facegen.train_pca import CoefficientLoss, basis_digest, fit_basis, project

    reporter.progress(f"PCA basis of the training motion ({config.basis} directions)")
    pca, mean, kept = fit_basis(data.train, config.basis, seed=config.seed)
    reporter.progress(f"the basis keeps {100 * kept:.3f} % of the training motion's variance")
    folder = data.dataset.cache_dir / f"coefficients-{basis_digest(pca, mean)}"
    folder.mkdir(parents=True, exist_ok=True)
    coefficients = {}
    for it in data.train + data.val:
        path = folder / f"{it.name}.npy"
        if path.is_file():
            coefficients[it.name] = np.load(path)
        else:
            coefficients[it.name] = project(it, pca, mean)
            with atomic_path(path) as tmp:
                np.save(tmp, coefficients[it.name])
    regions = data.mesh.regions
    loss = CoefficientLoss(pca, regions.get("lips"), config.lip_weight, config.velocity_weight, dev,
                           upper=regions.get("upper_face"), upper_weight=config.upper_weight,
                           text_free_weight=config.text_free_lips)
    return PcaTargets(pca, mean, kept, coefficients, loss, CoefficientLoss(pca, None))


def make_batches(data: TrainData, config: TrainConfig, basis: PcaTargets | None,
             dev: torch.device) -> tuple[list[Batch], list[Batch]]:
    """The training and validation batches (validation: of the training subjects only) on the device."""
    speakers = list(config.splits.train_subjects)
    speaker_of = {s: i for i, s in enumerate(speakers)}
    train_batches = [Batch(it, speaker_of[it.subject], len(speakers), dev) for it in data.train]
    val_batches = [Batch(it, speaker_of[it.subject], len(speakers), dev) for it in data.val
                   if it.subject in speaker_of]
    for b in train_batches + val_batches:
        if basis is not None and b.item.name in basis.coefficients:
            b.coefficients = torch.from_numpy(basis.coefficients[b.item.name]).to(dev)
        if config.phones:
            try:
                phones = data.dataset.phones(b.item.seq, b.item.num_frames, data.features.fps)
            except BadSequence as exc:
                raise FacegenError(f"{exc}: train the phone stream on a corpus with phone timings "
                                   "(facegen data synth --preset voices)") from None
            b.phones = torch.from_numpy(phones)[None].to(dev)
    return train_batches, val_batches
