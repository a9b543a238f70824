"""Evaluation on a dataset split: LVE and FDD as the community computes them, and vertex errors.

For a sequence with ground truth Y [T, V, 3], prediction Ŷ = template + model offsets, and the
subject's template M [V, 3] (all in mesh units: the BIWI normalisation makes the face's total surface
area 1):

- **LVE** (lip vertex error; FaceFormer / CodeTalker ``cal_metric.py``): per frame, the maximum over the
  lip-region vertices (regions/lve.txt) of the squared L2 error ‖ŷ_v − y_v‖²; the mean over all frames
  of all sequences. Unit: squared mesh units.
- **FDD** (upper-face dynamics deviation; CodeTalker): for each upper-face vertex (regions/fdd.txt), the
  standard deviation over time (population, ddof 0) of the squared displacement norm ‖y_v,t − m_v‖²;
  per sequence, the mean over those vertices of ground truth minus prediction, std(Y) − std(Ŷ); the
  mean over sequences. Signed (positive: the prediction moves less than the truth), as in CodeTalker.
  Unit: squared mesh units.
- **mean error**: the L2 distance ‖ŷ_v − y_v‖ averaged over all vertices and all frames (mesh units);
  **upper-face error** the same over the upper-face region; **lower-face error** over every vertex *not*
  in the upper-face region (lips, jaw, chin, cheeks, …); **lip error** over the lip region.
  Frame-weighted: the mean over all frames of all sequences, like LVE.

Lip sync (facegen.lipsync), when the model's face has the mouth regions (facegen's procedural face):
aperture r (lag 0 and best lag), aperture ratio, crossed lips, bilabial closure at the p/b/m midpoints
of the dataset's phone timings (alignments/{name}.json "phones"), stillness outside speech and the
upper face's motion, against the ground truth; pooled over sequences by frames (by bilabials).

Conditioning: sequences of a split of training subjects (train, val, test-a) are predicted with their
own speaker's one-hot vector. Test B's subjects were never seen, so — as the paper and the community
do — each of their sequences is predicted once for every training speaker; every (sequence, speaker)
pair counts as one sequence in the means above (per-sequence rows show the mean over speakers).
"""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from facegen.animator import Animator, NetworkInput
from facegen.datasets.biwi import Dataset, Item
from facegen.datasets.cache import BadSequence
from facegen.datasets.splits import Splits, check_split
from facegen.errors import FacegenError
from facegen.face.regions import LIPS, UPPER_FACE, file_stem
from facegen.lipsync import pool_lipsync
from facegen.runtime import STDERR, Reporter

if TYPE_CHECKING:
    from facegen.bundle import Bundle

METRICS = ("lve", "fdd", "mean_error", "upper_error", "lower_error", "lip_error")
UNITS = {
    "lve": "squared mesh units (mean over frames of the max over lip vertices of the squared L2 error)",
    "fdd": "squared mesh units (upper face: std over time of the squared displacement norm, "
           "truth - prediction)",
    "mean_error": "mesh units (mean L2 distance per vertex, all vertices)",
    "upper_error": "mesh units (mean L2 distance per vertex, upper-face region fdd.txt)",
    "lower_error": "mesh units (mean L2 distance per vertex, all vertices outside the upper-face region)",
    "lip_error": "mesh units (mean L2 distance per vertex, lip region lve.txt)",
}


def sequence_metrics(pred: np.ndarray, gt: np.ndarray, template: np.ndarray, lips: np.ndarray,
                     upper: np.ndarray) -> dict:
    """The metrics of one sequence: pred, gt [T, V, 3]; template [V, 3]; lips, upper vertex indices.

    Returns frames, lve (mean over this sequence's frames), lve_sum (for pooling), fdd and the
    per-vertex mean errors (see the module docstring).
    """
    pred = np.asarray(pred, np.float64)
    gt = np.asarray(gt, np.float64)
    template = np.asarray(template, np.float64)
    if pred.shape != gt.shape or pred.ndim != 3 or gt.shape[1:] != template.shape:
        raise ValueError(f"shapes differ: prediction {pred.shape}, truth {gt.shape}, "
                         f"template {template.shape}")
    err2 = np.square(pred - gt).sum(axis=2)  # [T, V] squared L2 error per vertex
    lve_frames = err2[:, lips].max(axis=1)
    motion_gt = np.square(gt[:, upper] - template[upper]).sum(axis=2)  # [T, U] squared displacement norms
    motion_pred = np.square(pred[:, upper] - template[upper]).sum(axis=2)
    fdd = float(np.mean(motion_gt.std(axis=0) - motion_pred.std(axis=0)))
    dist = np.sqrt(err2)
    lower = np.setdiff1d(np.arange(gt.shape[1]), upper)
    return {
        "frames": int(gt.shape[0]),
        "lve": float(lve_frames.mean()),
        "lve_sum": float(lve_frames.sum()),
        "fdd": fdd,
        "mean_error": float(dist.mean()),
        "upper_error": float(dist[:, upper].mean()),
        "lower_error": float(dist[:, lower].mean()) if lower.size else float("nan"),
        "lip_error": float(dist[:, lips].mean()),
    }


def pool(rows: list[dict]) -> dict:
    """Pool per-(sequence, condition) metrics: LVE and errors over all frames, FDD over sequences."""
    frames = sum(r["frames"] for r in rows)
    if not rows or frames == 0:
        return {k: float("nan") for k in METRICS} | {"frames": 0}
    out = {"frames": frames, "lve": sum(r["lve_sum"] for r in rows) / frames,
           "fdd": float(np.mean([r["fdd"] for r in rows]))}
    for k in ("mean_error", "upper_error", "lower_error", "lip_error"):
        out[k] = sum(r[k] * r["frames"] for r in rows) / frames
    return out


def _region(dataset: Dataset, bundle, name: str, num_vertices: int) -> np.ndarray:
    """The vertex indices of region `name`: the dataset's region file, else the bundle's template's."""
    file = f"{file_stem(name)}.txt"
    idx = dataset.regions.get(name)
    if idx is None:
        idx = bundle.template.regions.get(name)
    if idx is None or len(idx) == 0:
        raise FacegenError(f"no {name} region: put {file} in {dataset.root}/regions/ (the community's region "
                           "files) or use a bundle that has it")
    idx = np.asarray(idx, np.int64)
    if idx.min() < 0 or idx.max() >= num_vertices:
        raise FacegenError(f"the {name} region ({file}) has indices outside the {num_vertices} vertices")
    return idx


@dataclass
class Run:
    """An Animator ready to predict the usable sequences of a dataset split (see `prepare`)."""

    animator: Animator
    dataset: Dataset
    split: str
    items: list[Item]
    lips: np.ndarray  # vertex indices of the lip region
    upper: np.ndarray  # vertex indices of the upper-face region

    @property
    def bundle(self) -> Bundle:
        return self.animator.bundle

    def conditions(self, item: Item) -> list[int]:
        """Speaker indices to condition `item` on: its own speaker, or every speaker for test B."""
        if self.split == "test-b":
            return list(range(len(self.bundle.speakers)))
        return [self.bundle.speakers.index(item.subject)]

    def predict(self, item: Item, condition: int, encoders: bool = False
                ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Offsets [T, V, 3] of `item` conditioned on speaker `condition`; with `encoders`, also the
        encoder outputs ("audio" Ha [T, 128] and/or "text" Hl [T, 64]) as float32 arrays."""
        inputs = NetworkInput(item.mel, item.text, condition, item.phones if self.bundle.config.n_phones
                              else None)
        return self.animator.offsets(inputs), self.animator.encoders(inputs) if encoders else {}


def prepare(
    bundle_path: str | os.PathLike | None,
    data_root: str | os.PathLike,
    split: str = "test-a",
    *,
    splits: Splits | None = None,
    cache_dir: str | os.PathLike | None = None,
    text_model_path: str | os.PathLike | None = None,
    device: str = "cpu",
    on_bad: str = "skip",
    reporter: Reporter = STDERR,
) -> Run:
    """Load the bundle and the features of a split's usable sequences, with the checks evaluate needs.

    `splits` defaults to the split the bundle was trained with (its provenance), else the community's
    with the bundle's speakers as training subjects. `reporter` (default: on stderr) draws the bars and
    hears of every skipped sequence (its notes).
    """
    check_split(split)
    animator = Animator(bundle_path, text_model=text_model_path, device=device)
    bundle = animator.bundle
    animator.device  # noqa: B018 - an unusable explicit device fails before the features are computed
    if splits is None:
        known = bundle.provenance.get("split")
        splits = Splits.from_dict(known) if known else Splits(train_subjects=tuple(bundle.speakers),
                                                                   test_subjects=())
    dataset = Dataset(data_root, cache_dir=cache_dir, on_bad=on_bad, reporter=reporter)
    cfg = bundle.config
    backend = animator.text_backend() if cfg.uses_text else None
    sequences = dataset.split(split, splits)
    if split != "test-b":
        strangers = sorted({s.subject for s in sequences} - set(bundle.speakers))
        if strangers:
            raise FacegenError(f"subjects {' '.join(strangers)} of split {split} are not speakers of the "
                               f"model ({', '.join(bundle.speakers)}): evaluate them as test-b")
    items = dataset.load(sequences, bundle.features, bundle.mel_filters, backend)
    if not items:
        raise FacegenError(f"no usable sequence of split {split} in {dataset.root}: check the files named "
                           "above")
    num_vertices = bundle.template.num_vertices
    if items[0].template.shape[0] != num_vertices:
        raise FacegenError(f"the dataset's meshes have {items[0].template.shape[0]} vertices but the model "
                           f"{num_vertices}: evaluate on a dataset with the model's topology")
    if cfg.n_phones:  # the phone stream: sequences without phone timings (or a transcript) are reported
        usable = []
        for it in items:
            try:
                it.phones = dataset.phones(it.seq, it.num_frames, bundle.features.fps)
                usable.append(it)
            except BadSequence as exc:
                dataset.bad(it.name, str(exc))
        items = usable
        if not items:
            raise FacegenError(f"no sequence of split {split} in {dataset.root} has phone timings or a "
                               "transcript for this model's phone stream: add text/ transcripts")
    lips = _region(dataset, bundle, LIPS, num_vertices)
    upper = _region(dataset, bundle, UPPER_FACE, num_vertices)
    bundle.model.eval()
    return Run(animator, dataset, split, items, lips, upper)


def evaluate(bundle_path: str | os.PathLike | None, data_root: str | os.PathLike, split: str = "test-a",
             **options) -> dict:
    """Evaluate a model bundle on a split of the dataset at `data_root` (see the module docstring).

    `options` are those of `prepare` (splits, cache_dir, text_model_path, device, on_bad, reporter);
    `splits` defaults to the split the bundle was trained with (its provenance), else the community's
    with the bundle's speakers as training subjects. Returns a JSON-ready dict: bundle, data, split,
    conditioning, metrics (pooled), units, per_sequence rows, skipped sequences.
    """
    run = prepare(bundle_path, data_root, split, **options)
    reporter = options.get("reporter", STDERR)
    bundle, dataset, items = run.bundle, run.dataset, run.items
    num_vertices = bundle.template.num_vertices
    pooled_rows: list[dict] = []
    per_sequence: list[dict] = []
    lip_rows: list[dict] = []
    geometry = _lipsync_geometry(bundle)
    bar = reporter.bar(items, desc=f"evaluate {split}", unit="seq", leave=False)
    for item in bar:
        conditions = run.conditions(item)
        gt = item.vertices().reshape(item.num_frames, num_vertices, 3)
        rows = []
        for c in conditions:
            offsets, _ = run.predict(item, c)
            pred = item.template[None] + offsets
            rows.append(sequence_metrics(pred, gt, item.template, run.lips, run.upper))
            if geometry is not None:
                lip_rows.append(_lipsync_row(item, pred, gt, geometry, bundle.features.fps))
        pooled_rows += rows
        mean = pool(rows)
        mean["fdd"] = float(np.mean([r["fdd"] for r in rows]))
        per_sequence.append({"name": item.name, "subject": item.subject,
                             "condition": bundle.speakers[conditions[0]] if len(conditions) == 1
                             else f"mean of {len(conditions)} speakers",
                             **{k: mean[k] for k in ("frames",) + METRICS}})
    metrics = pool(pooled_rows)
    return {
        "bundle": str(bundle.path),
        "data": str(dataset.root),
        "split": split,
        "sequences": len(items),
        "conditioning": (f"each of the {len(bundle.speakers)} training speakers "
                         f"({', '.join(bundle.speakers)}), averaged" if split == "test-b"
                         else "the sequence's own speaker"),
        "metrics": {k: metrics[k] for k in ("frames",) + METRICS},
        "lipsync": pool_lipsync(lip_rows) if lip_rows else None,
        "units": dict(UNITS),
        "per_sequence": per_sequence,
        "skipped": [list(s) for s in dataset.skipped],
    }


def _lipsync_geometry(bundle: Bundle):
    """The lip-sync measuring geometry of the bundle's face (None when it lacks the mouth regions)."""
    from facegen.lipsync import FaceGeometry

    try:
        return FaceGeometry.of(bundle.template)
    except FacegenError:
        return None


def _lipsync_row(item: Item, pred: np.ndarray, gt: np.ndarray, geometry, fps: float) -> dict:
    """Lip-sync metrics of one prediction; speech frames and p/b/m midpoints from the sequence's alignment."""
    import json

    from facegen.lipsync import bilabial_midpoints, lipsync_metrics, speech_mask

    speech = bilabials = None
    if item.seq.alignment is not None and item.seq.alignment.suffix.lower() == ".json":
        with contextlib.suppress(OSError, ValueError, KeyError, TypeError):
            data = json.loads(item.seq.alignment.read_text(encoding="utf-8"))
            timed = [(w["word"], w["start"], w["end"]) for w in data.get("words", [])]
            phones = [(p["phone"], p["start"], p["end"]) for p in data.get("phones", [])]
            speech = speech_mask(phones or timed, item.num_frames, fps) if (phones or timed) else None
            if phones:
                bilabials = bilabial_midpoints(phones, fps, data.get("alphabet", "cmu"))
    return lipsync_metrics(pred, gt, geometry, fps, speech=speech, bilabials=bilabials,
                           rest_pose=item.template)


def format_table(result: dict) -> str:
    """The result as a readable table (per sequence, then all)."""
    head = f"{'sequence':<12}{'frames':>7}  {'LVE':>10} {'FDD':>11} {'mean err':>10} {'upper err':>10} " \
           f"{'lower err':>10} {'lip err':>10}"

    def line(name: str, r: dict) -> str:
        return (f"{name:<12}{r['frames']:>7}  {r['lve']:>10.4e} {r['fdd']:>11.4e} {r['mean_error']:>10.4e} "
                f"{r['upper_error']:>10.4e} {r['lower_error']:>10.4e} {r['lip_error']:>10.4e}")

    title = (f"model {result['bundle']} on {result['data']}, split {result['split']}: {result['sequences']} "
             f"sequences, conditioned on {result['conditioning']}")
    lines = [title, "", head, "-" * len(head)]
    lines += [line(r["name"], r) for r in result["per_sequence"]]
    units = ("LVE, FDD: squared mesh units; errors: mean L2 distance per vertex in mesh units "
             "(lower face = all vertices outside the upper-face region)")
    lines += ["-" * len(head), line("all", result["metrics"]), "", units]
    if result.get("lipsync"):
        from facegen.lipsync import format_lipsync

        lines += ["", "lip sync (against the ground truth):", format_lipsync(result["lipsync"])]
    if result["skipped"]:
        lines.append(f"skipped {len(result['skipped'])} sequences: " +
                     ", ".join(f"{n} ({r})" for n, r in result["skipped"]))
    return "\n".join(lines)

