import pytest
import torch

from facegen.model import FaceModel, ModelConfig, one_hot, tensor_fusion


def test_paper_dimensions():
    cfg = ModelConfig(num_vertices=23370, num_speakers=6, text_dim=768)
    m = FaceModel(cfg)
    convs = m.audio.convs
    assert [c.dilation[0] for c in convs] == [1, 2, 4, 8]
    assert all(c.out_channels == 128 and c.kernel_size == (3,) for c in convs)
    assert m.audio.fc.in_features == 128 + 6 and m.audio.fc.out_features == 128
    assert (m.text.fc1.in_features, m.text.fc1.out_features, m.text.fc2.out_features) == (768, 128, 64)
    assert m.text.lstm.hidden_size == 64 and not m.text.lstm.bidirectional
    assert m.fc_in.in_features == 129 * 65 and m.fc_in.out_features == 128
    assert m.lstm.num_layers == 2 and m.lstm.bidirectional and m.lstm.hidden_size == 128
    assert m.fc_out.out_features == 70110
    assert cfg.receptive_field == 15


def test_tensor_fusion_is_the_outer_product_with_ones():
    ha, hl = torch.randn(2, 5, 4), torch.randn(2, 5, 3)
    f = tensor_fusion(ha, hl).view(2, 5, 5, 4)
    assert torch.allclose(f[..., :4, :3], ha[..., :, None] * hl[..., None, :])
    assert torch.allclose(f[..., 4, :3], hl) and torch.allclose(f[..., :4, 3], ha)
    assert torch.all(f[..., 4, 3] == 1)


@pytest.mark.parametrize("modalities,fusion", [("both", "tensor"), ("both", "concat"), ("audio", "tensor"),
                                               ("text", "tensor")])
def test_ablation_variants_run_and_start_at_the_template(modalities, fusion):
    cfg = ModelConfig(num_vertices=50, num_speakers=3, text_dim=16, modalities=modalities, fusion=fusion)
    m = FaceModel(cfg)
    out = m(torch.randn(1, 40, 128), torch.randn(1, 40, 16), one_hot(1, 3))
    assert out.shape == (1, 40, 50, 3)
    assert torch.count_nonzero(out) == 0  # zero-initialised output layer: template at start
    torch.nn.init.normal_(m.fc_out.weight)
    a = m(torch.randn(1, 40, 128), torch.randn(1, 40, 16), one_hot(0, 3))
    assert a.abs().sum() > 0


def test_speaker_changes_output_and_conv_keeps_length():
    torch.manual_seed(0)
    m = FaceModel(ModelConfig(num_vertices=10, num_speakers=4, text_dim=8))
    torch.nn.init.normal_(m.fc_out.weight)
    mel, txt = torch.randn(1, 7, 128), torch.randn(1, 7, 8)
    a, b = m(mel, txt, one_hot(0, 4)), m(mel, txt, one_hot(3, 4))
    assert a.shape[1] == 7 and not torch.allclose(a, b)


def test_bad_config_refused():
    with pytest.raises(ValueError):
        ModelConfig(num_vertices=1, num_speakers=1, modalities="video")


def test_pca_output_folds_into_the_papers_layer_and_phones_join_the_audio():
    cfg = ModelConfig(num_vertices=50, num_speakers=2, text_dim=8, output_basis=4, n_phones=5, audio_dim=16,
                      text_hidden=16, text_dim_out=8, decoder_dim=16, lstm_dim=16)
    m = FaceModel(cfg).eval()
    torch.manual_seed(0)
    q, _ = torch.linalg.qr(torch.randn(150, 4))
    m.set_basis(q, torch.randn(150))
    torch.nn.init.normal_(m.fc_out.weight)
    mel, text, spk = torch.randn(1, 20, 128), torch.randn(1, 20, 8), m.speaker_one_hot(1)
    phones = torch.nn.functional.one_hot(torch.randint(0, 5, (1, 20)), 5).float()
    out = m(mel, text, spk, phones)
    coef = m.coefficients(mel, text, spk, phones)
    assert coef.shape == (1, 20, 4) and m.fc_out.out_features == 4
    torch.testing.assert_close(out.reshape(1, 20, -1), coef @ q.T + m.basis_mean, atol=1e-5, rtol=0)
    full = m.folded()
    assert full.cfg.output_basis == 0 and full.fc_out.out_features == 150
    torch.testing.assert_close(full(mel, text, spk, phones), out, atol=1e-5, rtol=0)
    other = phones.roll(3, dims=1)
    assert (m(mel, text, spk, other) - out).abs().max() > 1e-4  # the phones change the output
