"""Evaluation: LVE and FDD against hand-computed values and the community's own formulas, and the
end-to-end evaluate() on a tiny dataset (test A with the own speaker, test B with every speaker)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from helpers import TOY_SPLITS, grid_face, make_bundle, make_dataset

from facegen.datasets.splits import Splits
from facegen.errors import FacegenError
from facegen.evaluate import evaluate, format_table, pool, sequence_metrics
from facegen.inference import rest_offsets
from facegen.runtime import SILENT, Reporter


def test_metrics_by_hand():
    # 2 frames, 4 vertices; lips = {0, 1}, upper face = {2, 3}
    template = np.zeros((4, 3))
    gt = np.zeros((2, 4, 3))
    pred = np.zeros((2, 4, 3))
    pred[0, 0] = [3, 0, 0]  # squared error 9 at a lip vertex in frame 0
    pred[0, 1] = [0, 1, 0]  # 1: the max over lips in frame 0 is 9
    pred[1, 1] = [0, 0, 2]  # 4: the max in frame 1
    gt[:, 2] = [[1, 0, 0], [0, 2, 0]]  # upper vertex 2 moves: squared norms 1 then 4 -> std 1.5
    gt[:, 3] = [[0, 0, 1], [0, 0, 1]]  # vertex 3 displaced but static: std 0
    pred[:, 2] = [[1, 0, 0], [1, 0, 0]]  # prediction static at squared norm 1: std 0
    pred[:, 3] = [[0, 0, 0], [0, 0, 2]]  # squared norms 0 then 4: std 2
    m = sequence_metrics(pred, gt, template, np.array([0, 1]), np.array([2, 3]))
    assert m["frames"] == 2
    assert m["lve"] == pytest.approx((9 + 4) / 2) and m["lve_sum"] == pytest.approx(13)
    assert m["fdd"] == pytest.approx(((1.5 - 0) + (0 - 2)) / 2)  # mean over vertices of std_gt - std_pred
    # L2 errors: frame 0: v0 3, v1 1, v2 0, v3 1; frame 1: v0 0, v1 2, v2 sqrt(5), v3 1
    d = np.array([[3, 1, 0, 1], [0, 2, np.sqrt(5), 1]])
    assert m["mean_error"] == pytest.approx(d.mean())
    assert m["upper_error"] == pytest.approx(d[:, 2:].mean())
    assert m["lower_error"] == pytest.approx(d[:, :2].mean())
    assert m["lip_error"] == pytest.approx(d[:, :2].mean())
    # pooling: LVE over all frames, FDD over sequences
    m2 = dict(m, frames=6, lve_sum=60.0, lve=10.0, fdd=1.0, mean_error=0.0, upper_error=0.0,
              lower_error=0.0, lip_error=0.0)
    pooled = pool([m, m2])
    assert pooled["lve"] == pytest.approx(73 / 8) and pooled["fdd"] == pytest.approx((-0.25 + 1.0) / 2)
    assert pooled["mean_error"] == pytest.approx(d.mean() * 2 / 8)


def _community_metrics(gts, preds, templates, mouth_map, upper_map):
    """CodeTalker's cal_metric.py, line for line (V generalised), as the reference."""
    vertices_gt_all, vertices_pred_all, motion_std_difference = [], [], []
    for vertices_gt, vertices_pred, template in zip(gts, preds, templates, strict=True):
        motion_pred = vertices_pred - template.reshape(1, -1, 3)
        motion_gt = vertices_gt - template.reshape(1, -1, 3)
        vertices_gt_all.extend(list(vertices_gt))
        vertices_pred_all.extend(list(vertices_pred))
        L2_dis_upper = np.array([np.square(motion_gt[:, v, :]) for v in upper_map])
        L2_dis_upper = np.transpose(L2_dis_upper, (1, 0, 2))
        L2_dis_upper = np.sum(L2_dis_upper, axis=2)
        L2_dis_upper = np.std(L2_dis_upper, axis=0)
        gt_motion_std = np.mean(L2_dis_upper)
        L2_dis_upper = np.array([np.square(motion_pred[:, v, :]) for v in upper_map])
        L2_dis_upper = np.transpose(L2_dis_upper, (1, 0, 2))
        L2_dis_upper = np.sum(L2_dis_upper, axis=2)
        L2_dis_upper = np.std(L2_dis_upper, axis=0)
        pred_motion_std = np.mean(L2_dis_upper)
        motion_std_difference.append(gt_motion_std - pred_motion_std)
    vertices_gt_all = np.array(vertices_gt_all)
    vertices_pred_all = np.array(vertices_pred_all)
    L2_dis_mouth_max = np.array([np.square(vertices_gt_all[:, v, :] - vertices_pred_all[:, v, :])
                                 for v in mouth_map])
    L2_dis_mouth_max = np.transpose(L2_dis_mouth_max, (1, 0, 2))
    L2_dis_mouth_max = np.sum(L2_dis_mouth_max, axis=2)
    L2_dis_mouth_max = np.max(L2_dis_mouth_max, axis=1)
    return np.mean(L2_dis_mouth_max), sum(motion_std_difference) / len(motion_std_difference)


def test_lve_and_fdd_equal_the_community_code():
    rng = np.random.default_rng(3)
    V = 50
    lips, upper = rng.choice(V, 12, replace=False), rng.choice(V, 15, replace=False)
    gts, preds, templates, rows = [], [], [], []
    for T in (7, 11, 4):
        template = rng.normal(size=(V, 3))
        gt = template + rng.normal(scale=0.1, size=(T, V, 3))
        pred = template + rng.normal(scale=0.1, size=(T, V, 3))
        gts.append(gt)
        preds.append(pred)
        templates.append(template)
        rows.append(sequence_metrics(pred, gt, template, lips, upper))
    lve, fdd = _community_metrics(gts, preds, templates, lips, upper)
    pooled = pool(rows)
    assert pooled["lve"] == pytest.approx(lve, rel=1e-12) and pooled["fdd"] == pytest.approx(fdd, rel=1e-12)
    assert pooled["frames"] == 22


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    return make_dataset(tmp_path_factory.mktemp("toy"), with_alignments=False)


@pytest.fixture(scope="module")
def bundle_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("bundle") / "m.safetensors"
    make_bundle(grid_face(), path, speakers=("F2", "F3"), modalities="audio", scale=0.01)
    return path


def test_evaluate_test_a_uses_each_sequence_own_speaker(toy, bundle_path):
    from facegen.bundle import load_bundle
    from facegen.datasets.biwi import Dataset
    from facegen.face.mesh import read_region

    result = evaluate(bundle_path, toy, "test-a", splits=TOY_SPLITS, reporter=SILENT)
    assert result["split"] == "test-a" and result["sequences"] == 4
    assert [r["name"] for r in result["per_sequence"]] == ["F2_e06", "F2_e07", "F3_e06", "F3_e07"]
    assert [r["condition"] for r in result["per_sequence"]] == ["F2", "F2", "F3", "F3"]
    json.dumps(result)  # JSON-ready
    # recompute one sequence by hand: prediction = subject's template + model offsets (speaker F3), the
    # offsets taken from the network's rest (inference.rest_offsets), as facegen animates
    bundle = load_bundle(bundle_path)
    ds = Dataset(toy, reporter=SILENT)
    item = ds.load(ds.sequences(["F3_e07"]), bundle.features, bundle.mel_filters)[0]
    with torch.inference_mode():
        off = bundle.model(torch.from_numpy(item.mel)[None], None, torch.tensor([[0.0, 1.0]]))[0].numpy()
    off = off - rest_offsets(bundle, 1).reshape(-1, 3)
    gt = item.vertices().reshape(-1, 200, 3)
    lips, upper = read_region(toy / "regions" / "lve.txt"), read_region(toy / "regions" / "fdd.txt")
    expect = sequence_metrics(item.template + off, gt, item.template, lips, upper)
    row = result["per_sequence"][3]
    for k in ("lve", "fdd", "mean_error", "upper_error", "lower_error", "lip_error"):
        assert row[k] == pytest.approx(expect[k], rel=1e-6)
    assert result["metrics"]["frames"] == sum(r["frames"] for r in result["per_sequence"])
    assert "LVE" in format_table(result) and "F3_e07" in format_table(result)


def test_evaluate_test_b_averages_over_every_training_speaker(toy, bundle_path):
    from facegen.bundle import load_bundle
    from facegen.datasets.biwi import Dataset
    from facegen.face.mesh import read_region

    result = evaluate(bundle_path, toy, "test-b", splits=TOY_SPLITS, reporter=SILENT)
    assert [r["name"] for r in result["per_sequence"]] == ["F1_e06", "F1_e07"]
    assert result["per_sequence"][0]["condition"] == "mean of 2 speakers"
    assert "each of the 2 training speakers" in result["conditioning"]
    bundle = load_bundle(bundle_path)
    ds = Dataset(toy, reporter=SILENT)
    items = ds.load(ds.sequences(["F1_e06", "F1_e07"]), bundle.features, bundle.mel_filters)
    lips, upper = read_region(toy / "regions" / "lve.txt"), read_region(toy / "regions" / "fdd.txt")
    rows = []
    for item in items:
        for s in range(2):
            spk = torch.zeros(1, 2)
            spk[0, s] = 1
            with torch.inference_mode():
                off = bundle.model(torch.from_numpy(item.mel)[None], None, spk)[0].numpy()
            off = off - rest_offsets(bundle, s).reshape(-1, 3)
            gt = item.vertices().reshape(-1, 200, 3)
            rows.append(sequence_metrics(item.template + off, gt, item.template, lips, upper))
    assert rows[0]["lve"] != pytest.approx(rows[1]["lve"])  # the speakers really differ
    expect = pool(rows)
    for k in ("lve", "fdd", "mean_error", "lip_error"):
        assert result["metrics"][k] == pytest.approx(expect[k], rel=1e-6)


def test_a_zero_model_scores_the_motion_itself(toy, tmp_path):
    path = tmp_path / "zero.safetensors"
    make_bundle(grid_face(), path, speakers=("F2", "F3"), modalities="audio", scale=0.0)
    result = evaluate(path, toy, "val", splits=TOY_SPLITS, reporter=SILENT)
    # predicting the template: LVE = mean over frames of the max lip displacement squared; the data's
    # lips move down by 0.04 * (1 + 0.2 k) * envelope; FDD = the truth's own upper-face dynamics (>= 0)
    from facegen.datasets.biwi import Dataset

    ds = Dataset(toy, reporter=SILENT)
    lve = []
    for name in ("F2_e05", "F3_e05"):
        v = np.load(toy / "vertices_npy" / f"{name}.npy").reshape(-1, 200, 3)
        d2 = np.square(v - ds.template(name[:2])).sum(-1)[:, :60].max(1)
        lve.append(d2[: result["per_sequence"][0]["frames"]])
    assert result["metrics"]["lve"] == pytest.approx(np.concatenate(lve).mean(), rel=1e-5)
    assert result["metrics"]["fdd"] >= 0


def test_evaluate_refuses_mismatches(toy, bundle_path, tmp_path):
    with pytest.raises(FacegenError, match="subjects F1 of split test-a are not speakers"):
        evaluate(bundle_path, toy, "test-a", reporter=Reporter.stderr(quiet=True),
                 splits=Splits(train_subjects=("F1",), test_subjects=(), train_sentences="1-4",
                               val_sentences="5", test_sentences="6-7"))
    with pytest.raises(FacegenError, match="unknown split"):
        evaluate(bundle_path, toy, "test", reporter=Reporter.stderr(quiet=True))
    other = make_bundle(grid_face(8, 5), tmp_path / "small.safetensors", speakers=("F2", "F3"),
                        modalities="audio")
    with pytest.raises(FacegenError, match="have 200 vertices but the model 40"):
        evaluate(other.path, toy, "test-a", splits=TOY_SPLITS, reporter=SILENT)
    narrow = make_bundle(grid_face(), tmp_path / "narrow.safetensors", speakers=("F2", "F3"), text_dim=100)
    with pytest.raises(FacegenError, match=r"gives 384-d features but the model was trained on 100-d "
                                           r"\(minilm\)"):
        evaluate(narrow.path, toy, "test-a", splits=TOY_SPLITS, reporter=SILENT)


def test_metrics_on_the_real_biwi_topology(biwi_template):
    """The community's regions on the real BIWI mesh: our LVE/FDD equal cal_metric.py's numbers."""
    rng = np.random.default_rng(5)
    lips, upper = biwi_template.regions["lips"], biwi_template.regions["upper_face"]
    template = biwi_template.vertices.astype(np.float64)
    gt = template + rng.normal(scale=1e-3, size=(6, len(template), 3))
    pred = template + rng.normal(scale=1e-3, size=(6, len(template), 3))
    ours = pool([sequence_metrics(pred, gt, template, lips, upper)])
    lve, fdd = _community_metrics([gt], [pred], [template], lips, upper)
    assert ours["lve"] == pytest.approx(lve, rel=1e-10) and ours["fdd"] == pytest.approx(fdd, rel=1e-10)
    assert len(np.setdiff1d(np.arange(len(template)), upper)) == len(template) - 7784  # lower face
