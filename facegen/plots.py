"""The paper's analysis figures for a model on a dataset split, as PNGs (`facegen evaluate --plots DIR`).

- **fig3_correlation.png** (the paper's Fig. 3) and **fig3_correlation.json**: how strongly each vertex's
  predicted motion follows the audio-encoder features Ha and the text-encoder features Hl, painted on
  the template (front view, blue = low, red = high; grey: vertices the model never moves). The statistic
  is `correlation_map`: per vertex, the largest |Pearson r| between one encoder feature and the vertex's
  motion along its main direction. The JSON holds its mean over the moving vertices of the lip region
  (lve.txt), of the upper-face region (fdd.txt) and of the whole mesh, per modality.
- **fig4_tsne.png** (the paper's Fig. 4): t-SNE of the per-frame text-encoder outputs of every sentence of
  one subject of the split (left; each sentence named at its most central point), coloured by the frame's
  upper-face activation — our stand-in for the paper's AU5 (upper lid raiser) intensity: the mean over
  the upper-face vertices of the predicted displacement norm ‖offset‖ from the subject's neutral face, in
  mesh units. Right: one sentence of that subject, its frames joined in time order, each word written at
  its middle frame (word timings from the dataset's alignments, else its transcript aligned once and
  cached), and frames that belong to no word marked with crosses. Not drawn for audio-only models.
- **loss_curves.png**: training and validation loss per epoch from the bundle's provenance ("history",
  written by facegen.train), log scale. Not drawn when the bundle has no history (older bundles).

Data: every usable sequence of the split, predicted as facegen.evaluate does (its own speaker's one-hot;
test B, whose subjects the model never saw, with the first training speaker only), frames of all
sequences concatenated. The subject and sentence of Fig. 4 are the split's first (in split order).
"""

from __future__ import annotations

import json
import os
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from facegen.atomic import atomic_path
from facegen.datasets.biwi import Item
from facegen.datasets.splits import Splits
from facegen.errors import FacegenError
from facegen.plot_basics import FIG_WIDTH, plot_loss_curves, pyplot, save_figure
from facegen.runtime import SILENT, STDERR, Reporter, silent, threads

if TYPE_CHECKING:
    from facegen.evaluate import Run

FACE_SIZE = 560  # pixels of each rendered face
CORRELATION_CMAP = "jet"  # blue (low) → red (high), as in the paper
ACTIVATION_CMAP = "viridis"  # purple (low) → yellow (high), as in the paper
STATIC = 1e-6  # a vertex whose motion std is below this fraction of the largest one does not move
STATIC_GREY = (0.62, 0.62, 0.62)  # sRGB of vertices that do not move in Fig. 3


# ------------------------------------------------------------------------------------------ statistics
def _standardise(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Columns of x [N, K] to zero mean and unit (population) variance, float64; constant columns → 0.

    Returns (z, std)."""
    x = np.asarray(x, np.float64)
    x = x - x.mean(axis=0)
    std = x.std(axis=0)
    moving = std > STATIC * max(float(std.max(initial=0.0)), 1e-300)
    z = np.zeros_like(x)
    z[:, moving] = x[:, moving] / std[moving]
    return z, std


def principal_motion(offsets: np.ndarray) -> np.ndarray:
    """Each vertex's motion along its main direction: offsets [N, V, 3] → [N, V] float64.

    The main direction of a vertex is the first principal axis of its offsets over the N frames (the
    eigenvector of the largest eigenvalue of their 3 × 3 covariance); the result is the centred offset
    projected on it (its sign is arbitrary, which |r| ignores).
    """
    x = np.asarray(offsets, np.float64)
    x = x - x.mean(axis=0)
    cov = np.einsum("nvi,nvj->vij", x, x) / max(x.shape[0], 1)
    axis = np.linalg.eigh(cov)[1][:, :, -1]  # [V, 3]: eigh sorts eigenvalues ascending
    return np.einsum("nvi,vi->nv", x, axis)


def correlation_map(features: np.ndarray, offsets: np.ndarray, chunk: int = 2048) -> np.ndarray:
    """Per-vertex strength of the linear relation between encoder features and predicted motion, [V].

    features [N, D] (one row per frame), offsets [N, V, 3] (the predicted offsets of the same frames).
    For vertex v, m_v = its offsets projected on its main motion direction (`principal_motion`); the
    value is max over d of |Pearson r(features[:, d], m_v)| over the N frames, in [0, 1]: 1 when one
    feature dimension alone predicts the vertex's motion linearly. Vertices that do not move (motion std
    below STATIC × the largest, e.g. parts the model never animates) get NaN; constant feature dimensions
    count as r = 0.

    Vectorised: with Z_f [N, D] and Z_m [N, V] the standardised columns, r = Z_fᵀ Z_m / N, one matrix
    product per chunk of vertices (float64; memory ~ N × chunk × 3 × 8 bytes).

    The max over D dimensions rises a little with D even for unrelated signals (about sqrt(2 ln D / N)
    for independent noise: 0.06 for D = 128, N = 2,800), so compare modalities region by region rather
    than in absolute terms.
    """
    features = np.asarray(features)
    offsets = np.asarray(offsets)
    if features.ndim != 2 or offsets.ndim != 3 or offsets.shape[2] != 3 or len(features) != len(offsets):
        raise ValueError(f"need features [N, D] and offsets [N, V, 3], got {features.shape} and "
                         f"{offsets.shape}")
    n, num_vertices = offsets.shape[:2]
    out = np.full(num_vertices, np.nan)
    if n < 2 or features.shape[1] == 0:
        return out
    zf, _ = _standardise(features)
    motion_std = np.zeros(num_vertices)
    for lo in range(0, num_vertices, chunk):
        m = principal_motion(offsets[:, lo:lo + chunk])
        m -= m.mean(axis=0)
        std = m.std(axis=0)
        motion_std[lo:lo + chunk] = std
        zm = m / np.where(std > 0, std, 1.0)
        out[lo:lo + chunk] = np.abs(zf.T @ zm / n).max(axis=0)
    out = np.clip(out, 0.0, 1.0)
    out[motion_std <= STATIC * max(float(motion_std.max()), 1e-300)] = np.nan
    return out


def upper_face_activation(offsets: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Per frame, the mean over the upper-face vertices of ‖offset‖: [T] (the analogue of AU5)."""
    return np.linalg.norm(np.asarray(offsets)[:, upper], axis=2).mean(axis=1)


def word_frames(words: Sequence, num_frames: int, fps: float) -> np.ndarray:
    """The word index of each frame [T] (-1: no word): frame t belongs to the word whose [start, end)
    holds its centre (t + 0.5) / fps (facegen.text's rule)."""
    owner = np.full(num_frames, -1, np.int64)
    centres = (np.arange(num_frames) + 0.5) / fps
    for i, w in enumerate(words):
        owner[(centres >= w.start) & (centres < w.end)] = i
    return owner


# ---------------------------------------------------------------------------------------- predictions
@dataclass
class Predictions:
    """The split's sequences run through the model, one row per frame once concatenated."""

    items: list[Item]
    offsets: list[np.ndarray] = field(default_factory=list)  # per sequence [T, V, 3] float32
    encoded: dict[str, list[np.ndarray]] = field(default_factory=dict)  # modality → per sequence [T, D]
    activation: list[np.ndarray] = field(default_factory=list)  # per sequence [T]

    @property
    def frames(self) -> int:
        return sum(len(a) for a in self.activation)


def predict_split(run: Run, reporter: Reporter = SILENT) -> Predictions:
    """Offsets, encoder outputs and upper-face activation of every sequence of a facegen.evaluate.Run (a bar
    when `reporter` draws bars)."""
    out = Predictions(items=list(run.items))
    for item in reporter.bar(run.items, desc="plots", unit="seq", leave=False):
        offsets, enc = run.predict(item, run.conditions(item)[0], encoders=True)
        out.offsets.append(offsets.astype(np.float32, copy=False))
        for k, v in enc.items():
            out.encoded.setdefault(k, []).append(v)
        out.activation.append(upper_face_activation(offsets, run.upper))
    return out


# -------------------------------------------------------------------------------------------- drawing
def _face_image(template, values: np.ndarray, cmap) -> np.ndarray:
    """The template's front view painted with cmap(values), cropped to the face plus a small margin."""
    from facegen.render import render_image

    colors = np.asarray(cmap(np.clip(np.nan_to_num(values), 0.0, 1.0))[:, :3], np.float32)
    colors[~np.isfinite(values)] = STATIC_GREY
    image = render_image(template.vertices, template.faces, size=FACE_SIZE, views=("front",), colors=colors)
    face = np.abs(image.astype(np.int16) - image[0, 0]).max(axis=2) > 8  # the corner is background
    if not face.any():
        return image
    rows, cols = np.flatnonzero(face.any(axis=1)), np.flatnonzero(face.any(axis=0))
    pad = FACE_SIZE // 40
    return image[max(rows[0] - pad, 0):rows[-1] + pad + 1, max(cols[0] - pad, 0):cols[-1] + pad + 1]


def plot_correlation(maps: dict[str, np.ndarray], template, path: Path, title: str,
                     summary: dict[str, dict[str, float]]) -> Path:
    """Fig. 3: one painted face per modality (audio left, text right) and a shared |r| colour bar."""
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    plt = pyplot()
    cmap = colormaps[CORRELATION_CMAP]
    names = [m for m in ("audio", "text") if m in maps]
    width = FIG_WIDTH if len(names) == 2 else FIG_WIDTH * 0.58
    fig, axes = plt.subplots(1, len(names), figsize=(width, 7.2), squeeze=False,
                             gridspec_kw={"wspace": 0.04})
    label = {"audio": "audio encoder features Ha", "text": "text encoder features Hl"}
    for ax, name in zip(axes[0], names, strict=True):
        ax.imshow(_face_image(template, maps[name], cmap))
        s = summary[name]
        ax.set_title(f"{label[name]} ({s['dims']}-d)\nmean |r|: lips {s['lips']:.2f}, "
                     f"upper face {s['upper_face']:.2f}, all {s['all']:.2f}", fontsize=11)
        ax.set_xticks([])
        ax.set_yticks([])
        still = int(np.count_nonzero(~np.isfinite(maps[name])))
        ax.set_xlabel("front view" + (f"; grey: {still} vertices that do not move" if still else ""),
                      fontsize=9)
    bar = fig.colorbar(ScalarMappable(Normalize(0.0, 1.0), cmap), ax=axes[0].tolist(), fraction=0.035,
                       pad=0.02)
    bar.set_label("max over feature dimensions of |Pearson r| with the vertex's motion")
    fig.suptitle(title, fontsize=12)
    fig.subplots_adjust(left=0.01, right=0.86 if len(names) == 2 else 0.8, top=0.84, bottom=0.04)
    return save_figure(fig, path)


def plot_tsne(points: np.ndarray, activation: np.ndarray, sentence_of: np.ndarray, names: list[str],
              chosen: int, words: list[str], owner: np.ndarray, path: Path, title: str,
              right_title: str) -> Path:
    """Fig. 4: points [N, 2] coloured by activation [N]; left all sentences (names at their medians),
    right sentence `chosen` with its word labels (`owner` [T]: word index per frame of it, -1 none)."""
    from matplotlib import colormaps
    from matplotlib.colors import Normalize
    from matplotlib.lines import Line2D

    plt = pyplot()
    cmap = colormaps[ACTIVATION_CMAP]
    norm = Normalize(float(activation.min()), float(activation.max()) or 1.0)
    fig, (left, right) = plt.subplots(1, 2, figsize=(FIG_WIDTH, 6.4))
    sc = left.scatter(points[:, 0], points[:, 1], c=activation, cmap=cmap, norm=norm, s=9, linewidths=0)
    for k, name in enumerate(names):
        mine = points[sentence_of == k]
        mid = mine[np.argmin(np.square(mine - np.median(mine, axis=0)).sum(axis=1))]  # the most central
        left.annotate(name.split("_")[-1], mid, fontsize=9, color="0.15", ha="center", va="center",
                      bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "0.6", "alpha": 0.8})
    left.set_title(f"all {len(names)} sentences (each labelled at its most central point)", fontsize=10)

    mine = points[sentence_of == chosen]
    act = activation[sentence_of == chosen]
    right.plot(mine[:, 0], mine[:, 1], color="0.8", lw=0.8, zorder=1)
    spoken = owner >= 0
    right.scatter(mine[spoken, 0], mine[spoken, 1], c=act[spoken], cmap=cmap, norm=norm, s=28,
                  linewidths=0, zorder=2)
    right.scatter(mine[~spoken, 0], mine[~spoken, 1], c=act[~spoken], cmap=cmap, norm=norm, s=34,
                  marker="x", linewidths=1.2, zorder=2)
    right.margins(0.06)
    middle = (mine[:, 0].min() + mine[:, 0].max()) / 2
    for i, word in enumerate(words):
        frames = np.flatnonzero(owner == i)
        if len(frames):
            p = mine[frames[len(frames) // 2]]
            east = p[0] < middle  # labels point towards the middle, so none leaves the axes
            right.annotate(word, p, xytext=(5 if east else -5, 4), textcoords="offset points", fontsize=9,
                           ha="left" if east else "right", zorder=3,
                           bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.7})
    right.legend(handles=[Line2D([], [], marker="o", ls="", color="0.4", label="frame inside a word"),
                          Line2D([], [], marker="x", ls="", color="0.4", label="frame without a word")],
                 loc="best", fontsize=8)
    right.set_title(right_title, fontsize=10)
    for ax in (left, right):
        ax.set_xlabel("t-SNE 1")
        ax.set_ylabel("t-SNE 2")
    bar = fig.colorbar(sc, ax=[left, right], fraction=0.03, pad=0.02)
    bar.set_label("upper-face activation: mean ‖offset‖ of upper-face vertices (mesh units)")
    fig.suptitle(title, fontsize=12)
    fig.subplots_adjust(left=0.06, right=0.86, top=0.81, bottom=0.09, wspace=0.2)
    return save_figure(fig, path)


# ----------------------------------------------------------------------------------------------- API
def correlation_summary(maps: dict[str, np.ndarray], dims: dict[str, int], lips: np.ndarray,
                        upper: np.ndarray) -> dict[str, dict[str, float]]:
    """Mean |r| over the moving vertices (see `correlation_map`) of the lip region, the upper-face region
    and the whole mesh, per modality (NaN for a region that does not move)."""
    def mean(r: np.ndarray) -> float:
        r = r[np.isfinite(r)]
        return float(r.mean()) if r.size else float("nan")

    return {m: {"lips": mean(r[lips]), "upper_face": mean(r[upper]), "all": mean(r), "dims": int(dims[m])}
            for m, r in maps.items()}


def tsne(features: np.ndarray, seed: int = 0) -> np.ndarray:
    """2-D t-SNE (scikit-learn, PCA initialisation) of features [N, D]; perplexity 30 or less for small N."""
    from sklearn.manifold import TSNE

    n = len(features)
    perplexity = float(min(30.0, max(2.0, (n - 1) / 3)))
    # one thread: scikit-learn's OpenMP Barnes-Hut loop crawls when its threads compete for the cores
    # (400 points: 3 s on one thread, 15 s on two on a busy 2-core machine)
    with threads(1, ("blas", "openmp")):
        return TSNE(2, perplexity=perplexity, init="pca", random_state=seed).fit_transform(
            np.asarray(features, np.float64))


def _words(dataset, item: Item) -> list:
    from facegen.audio import load_audio

    samples, sr = load_audio(item.seq.wav)
    return list(dataset.words(item.seq, samples, sr))


def write_plots(
    bundle: str | os.PathLike | None,
    data: str | os.PathLike,
    plots_dir: str | os.PathLike,
    *,
    split: str = "test-a",
    splits: Splits | None = None,
    text_model_path: str | os.PathLike | None = None,
    device: str = "cpu",
    cache_dir: str | os.PathLike | None = None,
    reporter: Reporter = STDERR,
) -> list[Path]:
    """Write the figures of the module docstring for model `bundle` on `split` of dataset `data` into
    `plots_dir` (created if needed); return the files written. Figures that cannot be drawn (no text
    modality, no loss history) are skipped with a message to `reporter.progress` (default: on stderr)."""
    from facegen.evaluate import prepare  # torch: only when figures are drawn

    out_dir = Path(plots_dir)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise FacegenError(f"cannot create the plots folder {out_dir} ({exc.strerror}): choose another "
                           "plots folder", param="plots_dir") from exc
    run = prepare(bundle, data, split, splits=splits, cache_dir=cache_dir, text_model_path=text_model_path,
                  device=device, reporter=reporter.noting(silent))  # evaluate reports skipped sequences
    pred = predict_split(run, reporter=reporter)
    name = Path(run.bundle.path).name if run.bundle.path else "default model"
    where = f"split {split} of {run.dataset.root.name}: {len(pred.items)} sequences, {pred.frames} frames"
    written: list[Path] = []

    # Fig. 3
    offsets = np.concatenate(pred.offsets)
    pred.offsets.clear()  # [frames, V, 3] float32: ~0.7 GB for 2,400 BIWI frames; keep one copy
    maps, dims = {}, {}
    for modality, chunks in pred.encoded.items():
        features = np.concatenate(chunks)
        maps[modality] = correlation_map(features, offsets)
        dims[modality] = features.shape[1]
    del offsets
    summary = correlation_summary(maps, dims, run.lips, run.upper)
    written.append(plot_correlation(maps, run.bundle.template, out_dir / "fig3_correlation.png",
                                    f"Correlation of encoder features with predicted vertex motion\n"
                                    f"{name}, {where}", summary))
    report = {
        "bundle": str(run.bundle.path), "data": str(run.dataset.root), "split": split,
        "sequences": len(pred.items), "frames": pred.frames,
        "statistic": "per vertex: max over encoder feature dimensions of |Pearson r| between the feature and "
                     "the predicted offset projected on the vertex's first principal axis of motion, over "
                     "all frames of the split; regions: mean over their vertices that move (null: none "
                     "moves)",
        "regions": {"lips": len(run.lips), "upper_face": len(run.upper),
                    "all": int(run.bundle.template.num_vertices)},
        "moving_vertices": {m: int(np.isfinite(r).sum()) for m, r in maps.items()},
        "mean_abs_r": {m: {k: (v if np.isfinite(v) else None) for k, v in s.items() if k != "dims"}
                       for m, s in summary.items()},
        "skipped": [list(s) for s in run.dataset.skipped],
    }
    json_path = out_dir / "fig3_correlation.json"
    with atomic_path(json_path) as tmp:
        tmp.write_text(json.dumps(report, indent=2))
    written.append(json_path)

    # Fig. 4
    if "text" in pred.encoded:
        written.append(_fig4(run, pred, out_dir / "fig4_tsne.png", name, split, reporter))
    else:
        reporter.progress("fig4_tsne.png not drawn: the model has no text encoder (audio only)")

    # loss curves
    history = run.bundle.provenance.get("history")
    if history:
        best = run.bundle.provenance.get("best_epoch")
        title = f"Training of {name} ({len(history)} epochs" + (f", best epoch {best})" if best else ")")
        written.append(plot_loss_curves(history, out_dir / "loss_curves.png", title))
    else:
        reporter.progress(f"loss_curves.png not drawn: {name} has no loss history in its provenance (bundles "
                          "trained before facegen 0.1 do not store it; the training's loss.csv is in its "
                          "checkpoint folder)")
    return written


def _fig4(run: Run, pred: Predictions, path: Path, name: str, split: str, reporter: Reporter) -> Path:
    subject = pred.items[0].subject
    picks = [i for i, it in enumerate(pred.items) if it.subject == subject]
    features = np.concatenate([pred.encoded["text"][i] for i in picks])
    activation = np.concatenate([pred.activation[i] for i in picks])
    sentence_of = np.concatenate([np.full(len(pred.activation[i]), k) for k, i in enumerate(picks)])
    points = tsne(features)
    chosen = pred.items[picks[0]]
    try:
        words = _words(run.dataset, chosen)
    except Exception as exc:  # noqa: BLE001 - without timings the figure is still useful, unlabelled
        reporter.progress(f"no word timings for {chosen.name} ({exc}): fig4 right panel without words")
        words = []
    owner = word_frames(words, chosen.num_frames, run.bundle.features.fps)
    text = textwrap.shorten(" ".join(w.text for w in words), 110, placeholder=" ...")
    text = "\n".join(textwrap.wrap(f"\u201c{text}\u201d", 60))
    return plot_tsne(points, activation, sentence_of, [pred.items[i].name for i in picks], 0,
                     [w.text for w in words], owner, path,
                     f"t-SNE of the text encoder outputs Hl, one point per frame: subject {subject}, "
                     f"split {split}\n{name}",
                     f"one sentence, {chosen.name}:\n{text}" if text else f"one sentence, {chosen.name}")
