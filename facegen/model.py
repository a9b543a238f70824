"""The joint audio-text network of the paper (Fan et al., "Joint Audio-Text Model for Expressive
Speech-Driven 3D Facial Animation"), in one place.

    mel [T,128] ─► audio encoder: 4 dilated temporal convs (128 filters, kernel 3, dilations 1,2,4,8,
                   LeakyReLU, residual) ─► concat one-hot speaker ─► FC 128            = Ha [T,128]
    text [T,D]  ─► text encoder: FC 128, LeakyReLU, FC 64, LSTM 64                      = Hl [T,64]
    fusion:        tensor: [Ha;1] ⊗ [Hl;1] (129 × 65 = 8385 per frame)  |  concat: [Ha;Hl]
    decoder:       FC 128 ─► BiLSTM 128 ─► BiLSTM 128 ─► FC 3V = vertex offsets; output = template + offsets

Choices where the paper is silent or ambiguous (stated once, here):
- "128 filters of size 3×3": the convolutions are temporal (1-D over frames) with the 128 mel bands as
  input channels, so a "3×3" filter is read as kernel 3 in time (Conv1d, kernel_size=3); padding equal to
  the dilation keeps T frames. Residual: h ← h + LeakyReLU(conv(h)) for every layer (input has 128 bands,
  so the first residual needs no projection).
- LeakyReLU slope 0.2 everywhere; the FC 128 after the speaker concat and the decoder's first FC are
  followed by LeakyReLU too (the paper lists only layers).
- The text encoder's LSTM is unidirectional, as written. The 2 decoder BiLSTMs have 128 units per
  direction (256 outputs).
- Mel dB features are standardised per band with statistics of the training set, stored as buffers in the
  model (the paper does not say); text features are used as given.
- Text-only ablation: the speaker one-hot is concatenated to Hl (there is no audio encoder to carry it).
- The last FC starts at zero, so an untrained model outputs the template (as FaceFormer does).

Extensions (off by default, so the default configuration is the paper's network):
- `output_basis` = K > 0: the last FC 3V is trained in a K-dimensional PCA basis B [3V, K] (orthonormal
  columns) of the training motion with mean m: offsets = B (W h + b) + m. That is exactly the paper's FC 3V
  restricted to rank K; `folded()` turns it into the plain FC 3V (weight B W, bias B b + m) that bundles
  store, so inference never sees the difference. Training can then compare coefficients (B'(y - m)) instead
  of 3V numbers per frame: the same loss up to a constant when B is orthonormal, ~8x cheaper per step.
- `n_phones` = P > 0: a per-frame phone one-hot (P classes, from forced alignment) joins the audio encoder's
  input: a 1x1 convolution of it is added to the standardised mel bands (the same as appending it to the
  bands with the mel part of the first layer fixed to identity, so the mel path stays the paper's).
"""

from __future__ import annotations

import torch
from torch import nn
from torch.nn.utils.rnn import PackedSequence

from facegen.model_config import ModelConfig


class AudioEncoder(nn.Module):
    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        self.inp = (
            nn.Identity() if cfg.n_mels == cfg.conv_channels else nn.Conv1d(cfg.n_mels, cfg.conv_channels, 1)
        )
        self.convs = nn.ModuleList(
            nn.Conv1d(cfg.conv_channels, cfg.conv_channels, cfg.kernel_size, dilation=d,
                      padding=d * (cfg.kernel_size - 1) // 2)
            for d in cfg.dilations
        )
        self.phones = nn.Conv1d(cfg.n_phones, cfg.conv_channels, 1, bias=False) if cfg.n_phones else None
        self.act = nn.LeakyReLU(cfg.leaky_slope)
        self.fc = nn.Linear(cfg.conv_channels + cfg.num_speakers, cfg.audio_dim)

    def forward(self, mel: torch.Tensor, speaker: torch.Tensor,
                phones: torch.Tensor | None = None) -> torch.Tensor:
        """mel [B,T,n_mels] (standardised), speaker one-hot [B,S], phones [B,T,P] one-hot (when the
        model uses them) → Ha [B,T,audio_dim]."""
        h = self.inp(mel.transpose(1, 2))
        if self.phones is not None:
            if phones is None:
                raise ValueError("this model needs per-frame phones")
            h = h + self.phones(phones.transpose(1, 2))
        for conv in self.convs:
            h = h + self.act(conv(h))
        h = h.transpose(1, 2)
        spk = speaker[:, None, :].expand(-1, h.shape[1], -1)
        return self.act(self.fc(torch.cat([h, spk], dim=-1)))


class TextEncoder(nn.Module):
    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        self.fc1 = nn.Linear(cfg.text_dim, cfg.text_hidden)
        self.act = nn.LeakyReLU(cfg.leaky_slope)
        self.fc2 = nn.Linear(cfg.text_hidden, cfg.text_dim_out)
        self.lstm = nn.LSTM(cfg.text_dim_out, cfg.text_dim_out, batch_first=True)

    def forward(self, text: torch.Tensor) -> torch.Tensor:
        """text [B,T,text_dim] → Hl [B,T,text_dim_out]."""
        h, _ = self.lstm(self.fc2(self.act(self.fc1(text))))
        return h


def tensor_fusion(ha: torch.Tensor, hl: torch.Tensor) -> torch.Tensor:
    """[Ha;1] ⊗ [Hl;1] per frame, flattened: [B,T,(A+1)(L+1)] (Zadeh et al. 2017)."""
    one = ha.new_ones(ha.shape[:-1] + (1,))
    a = torch.cat([ha, one], dim=-1)
    lang = torch.cat([hl, one], dim=-1)
    return (a.unsqueeze(-1) * lang.unsqueeze(-2)).flatten(-2)


class FaceModel(nn.Module):
    """Predicts per-frame vertex offsets [B,T,V,3] from mel and text features and a speaker."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.register_buffer("mel_mean", torch.zeros(cfg.n_mels))
        self.register_buffer("mel_std", torch.ones(cfg.n_mels))
        self.audio = AudioEncoder(cfg) if cfg.uses_audio else None
        self.text = TextEncoder(cfg) if cfg.uses_text else None
        if cfg.modalities == "both":
            fused = ((cfg.audio_dim + 1) * (cfg.text_dim_out + 1) if cfg.fusion == "tensor"
                     else cfg.audio_dim + cfg.text_dim_out)
        elif cfg.modalities == "audio":
            fused = cfg.audio_dim
        else:
            fused = cfg.text_dim_out + cfg.num_speakers
        self.fc_in = nn.Linear(fused, cfg.decoder_dim)
        self.act = nn.LeakyReLU(cfg.leaky_slope)
        self.lstm = nn.LSTM(cfg.decoder_dim, cfg.lstm_dim, num_layers=cfg.lstm_layers,
                            batch_first=True, bidirectional=True)
        K = cfg.output_basis
        self.fc_out = nn.Linear(2 * cfg.lstm_dim, K or 3 * cfg.num_vertices)
        nn.init.zeros_(self.fc_out.weight)
        nn.init.zeros_(self.fc_out.bias)
        if K:
            self.register_buffer("basis", torch.zeros(3 * cfg.num_vertices, K))
            self.register_buffer("basis_mean", torch.zeros(3 * cfg.num_vertices))

    def encode(self, mel: torch.Tensor | None, text: torch.Tensor | None,
               speaker: torch.Tensor, phones: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
        """The encoders' outputs (used by forward and by the correlation analysis)."""
        out: dict[str, torch.Tensor] = {}
        if self.audio is not None:
            out["audio"] = self.audio((mel - self.mel_mean) / self.mel_std, speaker, phones)
        if self.text is not None:
            out["text"] = self.text(text)
        return out

    def fuse(self, enc: dict[str, torch.Tensor], speaker: torch.Tensor) -> torch.Tensor:
        if self.cfg.modalities == "audio":
            return enc["audio"]
        if self.cfg.modalities == "text":
            spk = speaker[:, None, :].expand(-1, enc["text"].shape[1], -1)
            return torch.cat([enc["text"], spk], dim=-1)
        if self.cfg.fusion == "tensor":
            return tensor_fusion(enc["audio"], enc["text"])
        return torch.cat([enc["audio"], enc["text"]], dim=-1)

    def speaker_one_hot(self, index: int, batch: int = 1) -> torch.Tensor:
        """The speaker input: a [batch, num_speakers] one-hot of speaker `index`."""
        return one_hot(index, self.cfg.num_speakers, batch)

    def decoder_input(self, mel: torch.Tensor | None, text: torch.Tensor | None, speaker: torch.Tensor,
                      block_frames: int | None = None, phones: torch.Tensor | None = None) -> torch.Tensor:
        """Encoders, fusion and the decoder's first FC: [B,T,decoder_dim]. With `block_frames`, the wide
        per-frame part (tensor fusion + FC) runs that many frames at a time (bounded memory, same values)."""
        enc = self.encode(mel, text, speaker, phones)
        if block_frames is None:
            return self.act(self.fc_in(self.fuse(enc, speaker)))
        T = next(iter(enc.values())).shape[1]
        return torch.cat([self.act(self.fc_in(self.fuse({k: v[:, s:s + block_frames] for k, v in enc.items()},
                                                            speaker)))
                          for s in range(0, T, block_frames)], dim=1)

    def decoder_states(self, x: torch.Tensor | PackedSequence) -> torch.Tensor | PackedSequence:
        """The decoder BiLSTM over decoder inputs [B,T,decoder_dim] (or a packed batch of clips of different
        lengths): states [B,T,2*lstm_dim], the only per-frame input of the output layer."""
        return self.lstm(x)[0]

    def forward(self, mel: torch.Tensor | None, text: torch.Tensor | None,
                speaker: torch.Tensor, phones: torch.Tensor | None = None) -> torch.Tensor:
        """mel [B,T,n_mels], text [B,T,text_dim], speaker one-hot [B,S] (phones [B,T,P]) → offsets
        [B,T,V,3]."""
        out = self.fc_out(self.decoder_states(self.decoder_input(mel, text, speaker, phones=phones)))
        if self.cfg.output_basis:
            out = out @ self.basis.T + self.basis_mean
        return out.view(out.shape[0], out.shape[1], self.cfg.num_vertices, 3)

    def coefficients(self, mel: torch.Tensor | None, text: torch.Tensor | None,
                     speaker: torch.Tensor, phones: torch.Tensor | None = None) -> torch.Tensor:
        """The output in the PCA basis, [B,T,K] (models with `output_basis` only): offsets = basis @ c +
        mean."""
        if not self.cfg.output_basis:
            raise ValueError("coefficients() needs a model with output_basis > 0")
        return self.fc_out(self.decoder_states(self.decoder_input(mel, text, speaker, phones=phones)))

    def set_basis(self, basis: torch.Tensor, mean: torch.Tensor) -> None:
        """Set the PCA basis [3V, K] (orthonormal columns) and mean [3V] of the output offsets."""
        with torch.no_grad():
            self.basis.copy_(basis)
            self.basis_mean.copy_(mean)

    def output_layer(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The output layer as the paper's plain FC 3V, (weight [3V, 2 * lstm_dim], bias [3V]): offsets =
        states @ weight.T + bias. A model with a PCA output (`output_basis`) gives it folded through its basis
        (weight B W, bias B b + m); what inference reads, whichever way the model was trained."""
        if not self.cfg.output_basis:
            return self.fc_out.weight, self.fc_out.bias
        with torch.no_grad():
            return self.basis @ self.fc_out.weight, self.basis @ self.fc_out.bias + self.basis_mean

    def folded(self) -> FaceModel:
        """The same network with the plain FC 3V output layer (`output_layer`): what bundles store."""
        if not self.cfg.output_basis:
            return self
        cfg = ModelConfig.from_dict({**self.cfg.to_dict(), "output_basis": 0})
        full = FaceModel(cfg)
        state = {k: v for k, v in self.state_dict().items() if not k.startswith(("fc_out.", "basis"))}
        state["fc_out.weight"], state["fc_out.bias"] = self.output_layer()
        full.load_state_dict(state)
        return full.to(self.basis.device).train(self.training)


def one_hot(index: int, num_speakers: int, batch: int = 1) -> torch.Tensor:
    """A [batch, num_speakers] one-hot of speaker `index` (the model's speaker input)."""
    v = torch.zeros(batch, num_speakers)
    v[:, index] = 1.0
    return v
