"""Inference on the CPU without torch (facegen.numpy_network): the same decoder states and frames as the torch
network for every configuration a bundle can hold; bundles load without torch and build it only when asked;
`facegen.animate` and `facegen animate` run without importing torch."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from helpers import grid_face

from facegen import inference
from facegen.audio import FeatureConfig, mel_filters
from facegen.bundle import Bundle, load_bundle, save_bundle
from facegen.model import FaceModel, ModelConfig
from facegen.numpy_network import check_weights, weight_shapes

REPO = Path(__file__).resolve().parents[1]
CPU = torch.device("cpu")

CONFIGS = {
    "default": {},
    "phones": {"n_phones": 40},
    "audio only": {"modalities": "audio"},
    "text only": {"modalities": "text"},
    "concat": {"fusion": "concat"},
    "80 mel bands, kernel 5, 3 layers": {"n_mels": 80, "kernel_size": 5, "lstm_layers": 3},
    "pca output": {"output_basis": 4},
}


def random_bundle(config: dict, seed: int = 0) -> Bundle:
    """A small network of `config` with every weight random (the real ones start the output layer at zero)."""
    torch.manual_seed(seed)
    template = grid_face(6, 5)
    dims = {"audio_dim": 16, "text_hidden": 16, "text_dim_out": 8, "decoder_dim": 16, "lstm_dim": 16,
            "text_dim": 24}
    cfg = ModelConfig(num_vertices=template.num_vertices, num_speakers=3, **{**dims, **config})
    model = FaceModel(cfg)
    with torch.no_grad():
        for p in model.parameters():
            p.normal_(0, 0.15)
        model.mel_mean.fill_(-50.0)
        model.mel_std.fill_(20.0)
        if cfg.output_basis:
            model.set_basis(torch.linalg.qr(torch.randn(3 * cfg.num_vertices, cfg.output_basis))[0],
                            0.01 * torch.randn(3 * cfg.num_vertices))
    feats = FeatureConfig(n_mels=cfg.n_mels)
    return Bundle(model.eval(), features=feats, mel_filters=mel_filters(feats), text_backend="minilm",
                  speakers=["a", "b", "c"], template=template)


def inputs(cfg: ModelConfig, T: int, seed: int = 1):
    rng = np.random.default_rng(seed)
    mel = (rng.standard_normal((T, cfg.n_mels)) * 10 - 50).astype(np.float32)
    text = rng.standard_normal((T, cfg.text_dim)).astype(np.float32)
    phones = (np.eye(cfg.n_phones, dtype=np.float32)[rng.integers(0, cfg.n_phones, T)] if cfg.n_phones
              else None)
    return mel, text, phones


@pytest.mark.parametrize("name", CONFIGS)
def test_numpy_states_equal_torch_states(name):
    bundle = random_bundle(CONFIGS[name])
    cfg = bundle.config
    mel, text, phones = inputs(cfg, 157)
    want = inference.decoder_states(bundle, mel, text, 2, phones=phones, device=CPU).numpy()
    got = inference.decoder_states(bundle, mel, text, 2, phones=phones, fusion_frames=50)  # in 4 blocks
    assert isinstance(got, np.ndarray) and got.dtype == np.float32 and got.shape == (157, 2 * cfg.lstm_dim)
    assert np.abs(want).max() > 0.1  # the states are not all near zero (saturated or dead): a real comparison
    np.testing.assert_allclose(got, want, atol=2e-5)
    # and the frames: the output layer folded from a PCA basis too
    frames = np.asarray(inference.frame_stream(bundle, got, bundle.template.vertices, speaker=2))
    with torch.inference_mode():
        offsets = bundle.model(torch.from_numpy(mel)[None], torch.from_numpy(text)[None],
                               bundle.model.speaker_one_hot(2),
                               None if phones is None else torch.from_numpy(phones)[None])[0].numpy()
    rest = inference.rest_offsets(bundle, 2).reshape(-1, 3)
    np.testing.assert_allclose(frames, bundle.template.vertices + offsets - rest, atol=1e-4)


def test_no_text_means_zeros_and_a_speaker_changes_the_states():
    bundle = random_bundle({})
    mel, text, _ = inputs(bundle.config, 60)
    zeros = np.zeros_like(text)
    np.testing.assert_array_equal(inference.decoder_states(bundle, mel, None, 0),
                                  inference.decoder_states(bundle, mel, zeros, 0))
    assert np.abs(inference.decoder_states(bundle, mel, text, 0)
                  - inference.decoder_states(bundle, mel, text, 1)).max() > 1e-3


@pytest.mark.parametrize("name", CONFIGS)
def test_weight_shapes_are_the_torch_models(name):
    cfg = ModelConfig(num_vertices=10, num_speakers=3, **CONFIGS[name])
    folded = FaceModel(cfg).folded()
    assert weight_shapes(folded.cfg) == {k: tuple(v.shape)
                                         for k, v in folded.state_dict().items()}


def test_a_loaded_bundle_builds_torch_only_when_asked(tmp_path):
    original = random_bundle(CONFIGS["pca output"])
    save_bundle(original, tmp_path / "m.safetensors")
    bundle = load_bundle(tmp_path / "m.safetensors")
    assert bundle._model is None and bundle.config.output_basis == 0  # stored folded
    for name, value in original.weights.items():
        np.testing.assert_allclose(bundle.weights[name], value, atol=1e-6, err_msg=name)
    model = bundle.model  # built from the weights, sharing their memory
    assert isinstance(model, FaceModel) and not model.training
    assert np.shares_memory(model.fc_out.weight.detach().numpy(), bundle.weights["fc_out.weight"])


def test_weights_of_the_wrong_shape_are_refused(tmp_path):
    cfg = ModelConfig(num_vertices=10, num_speakers=3)
    weights = {k: np.zeros(s, np.float32) for k, s in weight_shapes(cfg).items()}
    check_weights(weights, cfg)
    with pytest.raises(ValueError, match="missing: fc_out.bias"):
        check_weights({k: v for k, v in weights.items() if k != "fc_out.bias"}, cfg)
    with pytest.raises(ValueError, match="wrong shape: fc_in.weight"):
        check_weights({**weights, "fc_in.weight": np.zeros((3, 3), np.float32)}, cfg)


def test_the_python_api_animates_without_torch():
    """`facegen.animate` with the built-in model imports no torch (nor does `facegen animate`:
    tests/test_fast_start.py)."""
    wav, txt = REPO / "examples" / "excellent_room.wav", REPO / "examples" / "excellent_room.txt"
    script = (f"import sys, facegen; a = facegen.animate({str(wav)!r}, text=open({str(txt)!r}).read()); "
              "print(len(a.vertices), 'torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         env={**os.environ, "HF_HUB_OFFLINE": "1"}, check=True)
    frames, torch_imported = out.stdout.split()
    assert int(frames) == 110 and torch_imported == "False"
