"""Analysis figures: the correlation statistic against hand-made cases and a per-vertex reference, and
write_plots end to end on a model trained for 2 epochs on a tiny dataset (PNGs, JSON, skips)."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
from helpers import TOY_SPLITS, grid_face, make_bundle, make_dataset, train_toy

from facegen.bundle import load_bundle
from facegen.plots import (
    correlation_map,
    correlation_summary,
    principal_motion,
    upper_face_activation,
    word_frames,
    write_plots,
)
from facegen.runtime import SILENT
from facegen.words import Word

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def png_size(path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == PNG_SIGNATURE and data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def pixels(path) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(path).convert("RGB"))


# ------------------------------------------------------------------------------------------ statistic
def test_a_prediction_linear_in_one_text_feature_has_r_one_on_its_moving_vertices():
    rng = np.random.default_rng(0)
    n, d = 300, 16
    text = rng.normal(size=(n, d))
    offsets = np.zeros((n, 30, 3))
    directions = rng.normal(size=(10, 3))
    # vertices 0-9: offset = a_v * (2 * feature 5 + 1) along their own direction (different scales)
    offsets[:, :10] = (2 * text[:, 5] + 1)[:, None, None] * directions[None] * np.arange(1, 11)[None, :, None]
    offsets[:, 10:20] = rng.normal(size=(n, 10, 3))  # motion unrelated to the features
    offsets[:, 20:30] = 0.3  # displaced but static
    r = correlation_map(text, offsets)
    assert r.shape == (30,)
    np.testing.assert_allclose(r[:10], 1.0, atol=1e-9)
    assert r[10:20].max() < 0.35  # max over 16 independent features of |r| at n = 300: ~0.1-0.25
    assert np.isnan(r[20:30]).all()  # no motion: undefined
    # a little noise lowers r as the theory says: r = 1 / sqrt(1 + noise² / signal²)
    signal = 2 * text[:, 5]
    noisy = signal[:, None, None] * np.ones((1, 1, 3)) + rng.normal(scale=1.0, size=(n, 1, 3)) * [1, 0, 0]
    expect = abs(np.corrcoef(signal, noisy[:, 0] @ principal_axis(noisy[:, 0]))[0, 1])
    assert correlation_map(text, noisy)[0] == pytest.approx(expect, rel=1e-9)
    assert 0.8 < expect < 0.99
    text[:, 5] = 0.0  # a constant feature correlates with nothing
    r = correlation_map(text, offsets)
    assert r[:10].max() < 0.35 and np.isfinite(r[:20]).all()


def principal_axis(x: np.ndarray) -> np.ndarray:
    return np.linalg.eigh(np.cov(x.T, bias=True))[1][:, -1]


def test_region_means_leave_out_vertices_that_do_not_move():
    r = np.array([0.2, 0.4, np.nan, 0.9, np.nan])
    summary = correlation_summary({"text": r}, {"text": 64}, lips=np.array([0, 1, 2]), upper=np.array([4]))
    assert summary["text"]["lips"] == pytest.approx(0.3) and np.isnan(summary["text"]["upper_face"])
    assert summary["text"]["all"] == pytest.approx(0.5) and summary["text"]["dims"] == 64


def test_correlation_map_equals_a_per_vertex_reference_in_chunks():
    rng = np.random.default_rng(1)
    n, d, v = 80, 6, 23
    features = rng.normal(size=(n, d))
    mix = rng.normal(size=(d, v * 3))
    offsets = (np.tanh(features @ mix) + rng.normal(scale=0.5, size=(n, v * 3))).reshape(n, v, 3)
    fast = correlation_map(features.astype(np.float32), offsets.astype(np.float32), chunk=7)
    ref = np.array([max(abs(np.corrcoef(features[:, k], offsets[:, j] @ principal_axis(offsets[:, j]))[0, 1])
                        for k in range(d)) for j in range(v)])
    np.testing.assert_allclose(fast, ref, atol=1e-5)
    assert 0.2 < fast.min() and fast.max() <= 1.0


def test_principal_motion_follows_the_main_direction():
    t = np.linspace(0, 1, 50)
    direction = np.array([1.0, 2.0, 0.0]) / np.sqrt(5)
    signal = np.sin(7 * t)
    offsets = (signal[:, None] * direction)[:, None, :] + np.array([0.1, 0.2, 0.3])
    m = principal_motion(offsets)[:, 0]
    np.testing.assert_allclose(np.abs(m), np.abs(signal - signal.mean()), atol=1e-12)


def test_upper_face_activation_and_word_frames():
    offsets = np.zeros((3, 4, 3))
    offsets[1, 2] = [3, 4, 0]  # upper vertex 2 moves by 5 in frame 1
    np.testing.assert_allclose(upper_face_activation(offsets, np.array([2, 3])), [0, 2.5, 0])
    words = [Word("open", 0.1, 0.3), Word("wide", 0.3, 0.35), Word("now", 0.5, 0.7)]
    # 10 fps: frame centres 0.05, 0.15, 0.25, ... ; "wide" holds no centre
    np.testing.assert_array_equal(word_frames(words, 8, 10.0), [-1, 0, 0, -1, -1, 2, 2, -1])


# ----------------------------------------------------------------------------------------- end to end
@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    from helpers import make_tiny_gpt2

    gpt2 = make_tiny_gpt2(tmp_path_factory.mktemp("gpt2"), n_positions=64)
    toy = make_dataset(tmp_path_factory.mktemp("toy"), subjects=("F2", "F3"))  # with word alignments
    out = tmp_path_factory.mktemp("model") / "both.safetensors"
    result = train_toy(toy, out, epochs=2, modalities="both", text_backend=str(gpt2))
    return toy, out, result


def test_write_plots_draws_the_three_figures(trained, tmp_path):
    toy, bundle_path, result = trained
    history = load_bundle(bundle_path).provenance["history"]
    assert [h["epoch"] for h in history] == [1, 2]
    assert history[1]["val_loss"] == pytest.approx(result.history[1]["val_loss"], rel=1e-5)

    folder = tmp_path / "plots"
    written = write_plots(bundle_path, toy, folder, split="test-a", splits=TOY_SPLITS, reporter=SILENT)
    names = sorted(p.name for p in written)
    assert names == ["fig3_correlation.json", "fig3_correlation.png", "fig4_tsne.png", "loss_curves.png"]
    assert sorted(p.name for p in folder.iterdir()) == names  # nothing else (no temporary files)
    for name in ("fig3_correlation.png", "fig4_tsne.png", "loss_curves.png"):
        width, height = png_size(folder / name)
        assert 1000 <= width <= 1400 and 400 <= height <= 800, (name, width, height)
        image = pixels(folder / name)
        assert image.shape == (height, width, 3)
        assert image.std() > 20 and len(np.unique(image.reshape(-1, 3), axis=0)) > 50, name
        assert (folder / name).stat().st_size < 300_000
    report = json.loads((folder / "fig3_correlation.json").read_text())
    assert report["split"] == "test-a" and report["sequences"] == 4
    assert set(report["mean_abs_r"]) == {"audio", "text"}
    for values in report["mean_abs_r"].values():
        assert set(values) == {"lips", "upper_face", "all"}
        assert all(0.0 <= x <= 1.0 for x in values.values())
    assert report["mean_abs_r"]["audio"]["lips"] > 0.1  # the toy's lips follow the loudness
    # the face is painted: the left half of the correlation figure holds saturated colours
    fig3 = pixels(folder / "fig3_correlation.png").astype(int)
    spread = fig3.max(axis=2) - fig3.min(axis=2)
    assert (spread > 100).sum() > 5000


def test_audio_only_bundle_without_history_skips_fig4_and_curves(tmp_path, capsys):
    toy = make_dataset(tmp_path / "toy", subjects=("F2", "F3"), sentences=range(6, 8), with_alignments=False)
    bundle = make_bundle(grid_face(), tmp_path / "a.safetensors", speakers=("F2", "F3"), modalities="audio",
                         scale=0.01)
    written = write_plots(bundle.path, toy, tmp_path / "p", split="test-a", splits=TOY_SPLITS)
    assert sorted(p.name for p in written) == ["fig3_correlation.json", "fig3_correlation.png"]
    err = capsys.readouterr().err
    assert "fig4_tsne.png not drawn: the model has no text encoder" in err
    assert "loss_curves.png not drawn" in err and "no loss history" in err
    report = json.loads((tmp_path / "p" / "fig3_correlation.json").read_text())
    assert set(report["mean_abs_r"]) == {"audio"}
    width, _ = png_size(tmp_path / "p" / "fig3_correlation.png")
    assert 600 <= width < 1000  # one face only
