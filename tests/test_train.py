"""Training on a tiny dataset: the loss goes down, resume equals an uninterrupted run, runs are
deterministic, checkpoints and curves are written, bad setups are refused with clear messages."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
import torch
from helpers import SMALL, TOY_SPLITS, make_dataset, train_toy
from safetensors import safe_open

from facegen.bundle import load_bundle, read_metadata
from facegen.datasets.splits import Splits
from facegen.errors import FacegenError
from facegen.runtime import SILENT, select_device
from facegen.train import CHECKPOINT, default_checkpoint_dir, epoch_order


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    return make_dataset(tmp_path_factory.mktemp("toy"), with_alignments=False)




def _weights(path):
    from safetensors.torch import load_file

    return load_file(str(path))


def test_training_lowers_the_loss_and_writes_bundle_checkpoint_and_curves(toy, tmp_path):
    out = tmp_path / "model.safetensors"
    result = train_toy(toy, out, epochs=8)
    losses = [h["train_loss"] for h in result.history]
    val = [h["val_loss"] for h in result.history]
    assert len(result.history) == 8 and result.epochs_run == 8
    assert losses[-1] < 0.5 * losses[0] and min(val) < 0.5 * val[0]
    assert result.best_epoch == int(np.argmin(val)) + 1 and result.best_loss == pytest.approx(min(val))
    assert result.train_sequences == 8 and result.val_sequences == 2

    bundle = load_bundle(out)
    assert bundle.speakers == ["F2", "F3"] and bundle.text_backend == "none"
    assert bundle.config.modalities == "audio" and bundle.template.num_vertices == 200
    assert set(bundle.template.regions) == {"lips", "upper_face"}
    prov = bundle.provenance
    assert prov["data"] == toy.name and prov["epochs"] == 8 and prov["best_epoch"] == result.best_epoch
    assert prov["split"]["train_sentences"] == "1-4" and prov["train_seconds"] > 0
    assert prov["metrics"]["val_loss"] == pytest.approx(min(val))
    # mel statistics come from the training features
    assert bundle.model.mel_mean.abs().sum() > 0 and bool((bundle.model.mel_std >= 1.0).all())

    ckpt = default_checkpoint_dir(out)
    assert ckpt == tmp_path / "model.ckpt" and (ckpt / CHECKPOINT).is_file()
    with open(ckpt / "loss.csv") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["epoch"]) for r in rows] == list(range(1, 9))
    assert float(rows[0]["train_loss"]) == pytest.approx(losses[0], rel=1e-5)
    assert (ckpt / "loss.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(tmp_path.glob(".*"))  # no temporary files left behind


def test_resume_continues_and_equals_an_uninterrupted_run(toy, tmp_path):
    first = train_toy(toy, tmp_path / "a.safetensors", epochs=2)
    assert first.epochs_run == 2
    resumed = train_toy(toy, tmp_path / "a.safetensors", epochs=3, resume=True)
    assert resumed.epochs_run == 1 and resumed.epochs == 3
    straight = train_toy(toy, tmp_path / "b.safetensors", epochs=3)
    assert [h["train_loss"] for h in resumed.history] == [h["train_loss"] for h in straight.history]
    assert [h["val_loss"] for h in resumed.history] == [h["val_loss"] for h in straight.history]
    a, b = _weights(tmp_path / "a.safetensors"), _weights(tmp_path / "b.safetensors")
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    ca = _weights(tmp_path / "a.ckpt" / CHECKPOINT)
    cb = _weights(tmp_path / "b.ckpt" / CHECKPOINT)
    assert all(torch.equal(ca[k], cb[k]) for k in ca if not k.startswith("rng"))
    # nothing left to do: resuming a finished run only rewrites the bundle
    again = train_toy(toy, tmp_path / "a.safetensors", epochs=3, resume=True)
    assert again.epochs_run == 0 and again.best_epoch == straight.best_epoch


def test_two_runs_with_the_same_seed_are_identical(toy, tmp_path):
    train_toy(toy, tmp_path / "x.safetensors", epochs=1, seed=7)
    train_toy(toy, tmp_path / "y.safetensors", epochs=1, seed=7)
    train_toy(toy, tmp_path / "z.safetensors", epochs=1, seed=8)
    x, y, z = (_weights(tmp_path / f"{n}.safetensors") for n in "xyz")
    assert all(torch.equal(x[k], y[k]) for k in x)
    assert not torch.equal(x["model.fc_out.weight"], z["model.fc_out.weight"])
    assert list(epoch_order(7, 3, 10)) == list(epoch_order(7, 3, 10))
    assert list(epoch_order(7, 3, 10)) != list(epoch_order(7, 4, 10))


def test_text_modalities_train_with_a_text_backend(tmp_path_factory, tmp_path):
    from helpers import make_tiny_gpt2

    folder = make_tiny_gpt2(tmp_path_factory.mktemp("gpt2"), n_positions=64)
    toy = make_dataset(tmp_path / "d", subjects=("F2", "F3"), sentences=range(1, 6))
    for modalities, fusion in (("both", "tensor"), ("both", "concat"), ("text", "tensor")):
        out = tmp_path / f"{modalities}-{fusion}.safetensors"
        result = train_toy(toy, out, epochs=1, modalities=modalities, fusion=fusion, text_backend=str(folder))
        assert math.isfinite(result.best_loss)
        meta = read_metadata(out)
        assert meta["text_backend"] == {"id": str(folder), "dim": 32}
        assert meta["model_config"]["modalities"] == modalities and meta["model_config"]["fusion"] == fusion


def test_half_bundle_and_batches(toy, tmp_path):
    result = train_toy(toy, tmp_path / "h.safetensors", epochs=1, precision="fp16", batch_size=3)
    assert math.isfinite(result.best_loss)
    assert _weights(tmp_path / "h.safetensors")["model.fc_out.weight"].dtype == torch.float16
    assert load_bundle(tmp_path / "h.safetensors").model.fc_out.weight.dtype == torch.float32


def test_a_nan_loss_stops_training_and_keeps_the_last_checkpoint(toy, tmp_path):
    out = tmp_path / "n.safetensors"
    train_toy(toy, out, epochs=1)
    with pytest.raises(FacegenError, match=r"loss became (nan|inf) at epoch 2 on F[23]_e0\d.*last good "
                                           r"checkpoint \(epoch 1\)"):
        train_toy(toy, out, epochs=3, resume=True, lr=1e38)
    with safe_open(str(tmp_path / "n.ckpt" / CHECKPOINT), framework="pt") as f:
        assert json.loads(f.metadata()["facegen_checkpoint"])["epoch"] == 1


def test_bad_setups_are_refused(toy, tmp_path):
    train_toy(toy, tmp_path / "s.safetensors", epochs=1)
    with pytest.raises(FacegenError, match="different setup .*seed"):
        train_toy(toy, tmp_path / "s.safetensors", epochs=2, seed=5, resume=True)
    with pytest.raises(FacegenError, match="unknown modalities"):
        train_toy(toy, tmp_path / "m.safetensors", modalities="video")
    with pytest.raises(FacegenError, match="output folder .* does not exist"):
        train_toy(toy, tmp_path / "no" / "m.safetensors")
    with pytest.raises(FacegenError, match="no usable training sequence"):
        train_toy(toy, tmp_path / "m.safetensors", splits=Splits(train_subjects=("M9",), test_subjects=()),
               reporter=SILENT)


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has CUDA")
def test_device_choice_without_cuda(toy, tmp_path):
    assert select_device("auto") == torch.device("cpu")  # quietly: the CPU is the normal case
    assert select_device("cpu") == torch.device("cpu")
    with pytest.raises(FacegenError, match="no CUDA GPU"):
        train_toy(toy, tmp_path / "c.safetensors", device="cuda")
    with pytest.raises(FacegenError, match="unknown device"):
        select_device("tpu")


def test_pca_output_layer_trains_in_coefficients_and_folds_into_the_papers_layer(toy, tmp_path):
    out = tmp_path / "pca.safetensors"
    result = train_toy(toy, out, epochs=6, output="pca", basis=6, lip_weight=1.0, velocity_weight=0.5,
                       patience=3)
    losses = [h["train_loss"] for h in result.history]
    assert losses[-1] < 0.6 * losses[0]
    bundle = load_bundle(out)
    assert bundle.config.output_basis == 0 and bundle.model.fc_out.out_features == 600  # the paper's FC 3V
    prov = bundle.provenance
    assert prov["output"] == "pca" and prov["basis"] == 6 and 0.9 < prov["basis_variance"] <= 1.0
    # the folded layer's offsets lie in the 6-dimensional basis: rank <= 6 over many frames
    from facegen.model import one_hot

    item_mel = torch.randn(1, 80, 128) * 10 - 50
    with torch.no_grad():
        offsets = bundle.model(item_mel, None, one_hot(0, 2))[0].reshape(80, -1)
    centred = offsets - offsets.mean(0)
    singular = torch.linalg.svdvals(centred.double())
    assert singular[6] < 1e-4 * singular[0]  # float32 rounding only beyond the basis


def test_pca_options_are_checked_before_work(toy, tmp_path):
    with pytest.raises(FacegenError, match="need the pca output layer"):
        train_toy(toy, tmp_path / "m.safetensors", lip_weight=1.0)
    with pytest.raises(FacegenError, match="a basis of 5000 needs more training frames"):
        train_toy(toy, tmp_path / "m.safetensors", output="pca", basis=5000)
    with pytest.raises(FacegenError, match="unknown output layer"):
        train_toy(toy, tmp_path / "m.safetensors", output="half")


def test_the_bundle_records_its_config_and_features(toy, tmp_path):
    """The provenance holds the TrainConfig's settings, the header the feature settings (the text smoothing
    window included); a checkpoint written before the window was a setting resumes (it had the default)."""
    from facegen.train_config import TrainConfig

    out = tmp_path / "c.safetensors"
    train_toy(toy, out, epochs=1, seed=4, lr=2e-3, batch_size=2)
    meta = read_metadata(out)
    settings = {k: meta["provenance"][k] for k in ("seed", "lr", "batch_size", "output", "split")}
    assert settings == {"seed": 4, "lr": 2e-3, "batch_size": 2, "output": "full",
                        "split": TrainConfig(splits=TOY_SPLITS).splits.to_dict()}
    assert meta["feature_config"]["text_window"] == [8, 7]
    assert "basis" not in meta["provenance"] and "patience" not in meta["provenance"]

    from safetensors.torch import load_file, save_file

    path = default_checkpoint_dir(out) / CHECKPOINT
    with safe_open(str(path), framework="pt") as f:
        old = json.loads(f.metadata()["facegen_checkpoint"])
    del old["signature"]["feature_config"]["text_window"]
    save_file(load_file(str(path)), str(path), metadata={"facegen_checkpoint": json.dumps(old)})
    resumed = train_toy(toy, out, epochs=2, seed=4, lr=2e-3, batch_size=2, resume=True)
    assert resumed.epochs_run == 1 and resumed.epochs == 2
    with pytest.raises(FacegenError, match="unknown precision"):
        train_toy(toy, tmp_path / "p.safetensors", precision="fp8")


def test_init_starts_from_a_bundle_and_refuses_another_network(toy, tmp_path):
    """Fine-tuning (--init): the run starts where the bundle is — before a step its predictions are the
    bundle's (full layer as is, a PCA layer projected into the new basis) — and a bundle of another network
    is refused in one line."""
    from facegen.model import one_hot
    from facegen.train_init import warm_start

    first = tmp_path / "first.safetensors"
    train_toy(toy, first, epochs=3, output="pca", basis=6)
    mel = torch.randn(1, 60, 128) * 10 - 50
    bundle = load_bundle(first)
    with torch.no_grad():
        want = bundle.model(mel, None, one_hot(0, 2))
    # a 1e-12 learning rate: the fine-tuned model is still the bundle (the basis refitted on the same data)
    again = tmp_path / "again.safetensors"
    train_toy(toy, again, epochs=1, lr=1e-12, output="pca", basis=6, init=str(first))
    tuned = load_bundle(again)
    with torch.no_grad():
        got = tuned.model(mel, None, one_hot(0, 2))
    assert torch.allclose(got, want, atol=1e-5 * float(want.abs().max()))
    assert tuned.provenance["init"] == str(first)
    assert torch.equal(tuned.model.mel_mean, bundle.model.mel_mean)  # the bundle's normalisation is kept
    # a full output layer takes the weights as they are
    from facegen.model import FaceModel

    model = FaceModel(bundle.config)
    warm_start(model, str(first), bundle.features)
    assert all(torch.equal(a, b) for a, b in zip(model.state_dict().values(),
                                                 bundle.model.state_dict().values(), strict=True))
    with pytest.raises(FacegenError, match="another network than this run's .*lstm_dim"):
        train_toy(toy, tmp_path / "other.safetensors", init=str(first),
                  model_options={**SMALL, "lstm_dim": 4})


def test_text_free_lips_keep_the_words_off_the_lips(tmp_path_factory, tmp_path):
    """--text-free-lips: from a model whose words move its lips, fine-tuning with it brings the lips with the
    words and with zero text features nearer each other than fine-tuning without it; the option needs a pca
    model of audio and text."""
    from helpers import make_tiny_gpt2

    from facegen.bundle import save_bundle
    from facegen.train_config import TrainConfig
    from facegen.train_data import load_train_data, make_batches

    folder = make_tiny_gpt2(tmp_path_factory.mktemp("gpt2"), n_positions=64)
    toy = make_dataset(tmp_path / "d", subjects=("F2", "F3"), sentences=range(1, 6))
    with pytest.raises(FacegenError, match="text-free lips need a model of audio and text"):
        train_toy(toy, tmp_path / "a.safetensors", output="pca", basis=6, text_free_lips=1.0)
    with pytest.raises(FacegenError, match="need the pca output layer"):
        train_toy(toy, tmp_path / "a.safetensors", modalities="both", text_backend=str(folder),
                  text_free_lips=1.0)
    options = {"modalities": "both", "text_backend": str(folder), "output": "pca", "basis": 6,
               "lip_weight": 1.0}
    train_toy(toy, tmp_path / "base.safetensors", epochs=2, **options)
    base = load_bundle(tmp_path / "base.safetensors")
    with torch.no_grad():  # the words now move the whole face, lips too
        base.model.text.fc2.weight.mul_(20.0)
    save_bundle(base, tmp_path / "wordy.safetensors")
    config = TrainConfig(modalities="both", text_backend=str(folder), splits=TOY_SPLITS)
    data = load_train_data(toy, config, toy / ".cache", str(folder), "fail", SILENT)
    batches = make_batches(data, config, None, torch.device("cpu"))[0]
    lips = torch.from_numpy(np.asarray(base.template.regions["lips"], np.int64))

    def words_on_lips(path) -> float:  # the mean lip displacement the words make, over the lips' own motion
        model = load_bundle(path).model
        gap = moved = 0.0
        with torch.no_grad():
            for b in batches:
                shape = (b.mel.shape[1], -1, 3)
                both = model(b.mel, b.text, b.speaker)[0].reshape(shape)[:, lips]
                free = model(b.mel, torch.zeros_like(b.text), b.speaker)[0].reshape(shape)[:, lips]
                gap += float((both - free).norm(dim=-1).mean())
                moved += float((both - both.mean(0)).norm(dim=-1).mean())
        return gap / moved

    share = {"wordy": words_on_lips(tmp_path / "wordy.safetensors")}
    for weight in (0.0, 4.0):
        out = tmp_path / f"free{weight}.safetensors"
        train_toy(toy, out, epochs=3, init=str(tmp_path / "wordy.safetensors"), text_free_lips=weight,
                  **options)
        share[weight] = words_on_lips(out)
        if weight:
            assert read_metadata(out)["provenance"]["text_free_lips"] == weight
            with pytest.raises(FacegenError, match="text_free_lips"):  # not resumed with another weight
                train_toy(toy, out, epochs=4, init=str(tmp_path / "wordy.safetensors"), resume=True,
                          **options)
    assert share["wordy"] > 0.05, share  # the perturbation did put the words on the lips
    assert share[4.0] < 0.5 * share[0.0], share
