"""Matplotlib figures as PNG files: the headless backend, atomic saving (a palette for large figures), and
the loss-curve plot that training writes (loss.png) and `facegen evaluate --plots` redraws from a bundle.
"""

from __future__ import annotations

import io
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from facegen.atomic import atomic_path

FIG_WIDTH = 12.0  # inches at DPI: 1200 px
DPI = 100
MAX_PNG_BYTES = 280_000  # larger figures are stored with a 256-colour palette


def pyplot():
    """matplotlib.pyplot on the headless Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    return plt


def save_figure(fig, path: Path) -> Path:
    """Save a matplotlib figure as PNG atomically; above MAX_PNG_BYTES, with a dithered 256-colour palette
    (about half the size: a 1200 x 720 figure of two shaded faces takes 150 KB instead of 340 KB)."""
    from PIL import Image  # matplotlib's own dependency

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    pyplot().close(fig)
    data = buf.getvalue()
    if len(data) > MAX_PNG_BYTES:
        image = Image.open(io.BytesIO(data)).convert("RGB")
        palette = image.quantize(256, method=Image.Quantize.FASTOCTREE)
        small = io.BytesIO()  # dithered: no banding in shaded faces and colour bars
        image.quantize(palette=palette, dither=Image.Dither.FLOYDSTEINBERG).save(small, format="png",
                                                                                 optimize=True)
        data = small.getvalue()
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return path


def plot_loss_curves(history: Sequence[dict], path: str | os.PathLike, title: str | None = None,
                     figsize: tuple[float, float] = (FIG_WIDTH, 5.0)) -> Path:
    """Training and validation loss (MSE) per epoch, log y axis, the best validation epoch marked.

    `history`: rows with epoch, train_loss and val_loss (NaN or None without a validation split)."""
    from matplotlib.ticker import MaxNLocator

    plt = pyplot()
    epochs = [int(h["epoch"]) for h in history]

    def values(key: str) -> np.ndarray:
        return np.array([np.nan if h.get(key) is None else float(h[key]) for h in history])

    train, val = values("train_loss"), values("val_loss")
    fig, ax = plt.subplots(figsize=figsize)
    marker = "." if len(epochs) < 30 else None
    ax.plot(epochs, train, label="training", marker=marker)
    if np.isfinite(val).any():
        ax.plot(epochs, val, label="validation", marker=marker)
        best = int(np.nanargmin(val))
        ax.plot([epochs[best]], [val[best]], "o", mfc="none", mec="C3", ms=10,
                label=f"best validation (epoch {epochs[best]}: {val[best]:.3g})")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("epoch")
    ax.set_ylabel("loss: MSE of vertex offsets (mesh units²)")
    ax.set_yscale("log")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    if title:
        ax.set_title(title, fontsize=11)
    fig.tight_layout()
    return save_figure(fig, Path(path))
