"""The network's forward pass in numpy: what inference runs on the CPU, without importing torch.

torch's import takes 0.9-1.6 s on the benchmark machine: more than half of `facegen animate` on a 5 s clip
(the whole inference is 0.02 s of it). So on the CPU the decoder states are computed here, from the bundle's
float32 weights (`Bundle.weights`, the same state dict facegen.model's FaceModel loads), with the arithmetic
of facegen.model written out: the dilated temporal convolutions as three shifted matrix products, the LSTMs
step by step (both directions of a layer in one loop), the tensor fusion and the decoder's first FC in blocks
of frames. The states equal torch's to float rounding (~2e-6 on the shipped model's 1,500-frame clip;
tests/test_numpy_network.py compares every configuration). torch stays for training and for a CUDA device.

Memory is bounded as in facegen.inference: only the fusion is wide (8,385 numbers a frame) and it runs
`fusion_frames` frames at a time; everything else is [T, <= 256].
"""

from __future__ import annotations

import numpy as np

from facegen.model_config import ModelConfig

STEP_FRAMES = 1024  # frames whose LSTM input projections are made at once (1024 x 512 float32 = 2 MB)


def _leaky(x: np.ndarray, slope: float) -> np.ndarray:
    return np.where(x > 0, x, x * np.float32(slope))


def _linear(w: dict[str, np.ndarray], name: str, x: np.ndarray) -> np.ndarray:
    return x @ w[name + ".weight"].T + w[name + ".bias"]


def _conv(w: dict[str, np.ndarray], name: str, x: np.ndarray, dilation: int) -> np.ndarray:
    """torch's Conv1d (stride 1, padding keeping T frames) over x [T, C_in]: [T, C_out]."""
    kernel = w[name + ".weight"]  # [C_out, C_in, k]
    k, T = kernel.shape[2], len(x)  # odd: the model's residuals need T frames out
    pad = dilation * (k - 1) // 2
    padded = np.pad(x, ((pad, pad), (0, 0)))
    out = w[name + ".bias"] + padded[:T] @ kernel[:, :, 0].T
    for j in range(1, k):
        out += padded[j * dilation:j * dilation + T] @ kernel[:, :, j].T
    return out


def _lstm(w: dict[str, np.ndarray], x: np.ndarray, names: list[tuple[str, bool]]) -> np.ndarray:
    """LSTMs over x [T, D] (torch's gate order i, f, g, o) run side by side, one step of each at a time:
    `names` (weight name prefix such as "lstm." and suffix such as "l0_reverse", whether it reads the frames
    from the end). Returns [T, len(names) * H], each one's hidden states in its columns, in frame order. The
    input projections are made STEP_FRAMES frames at a time: nothing of the clip's length but x and the
    output (a 2-hour clip's [T, 4H] projections would be 0.37 GB a direction)."""
    D, T = len(names), len(x)
    w_ih = [w[f"{prefix}weight_ih_{suffix}"].T for prefix, suffix, _ in names]
    bias = [w[f"{prefix}bias_ih_{suffix}"] + w[f"{prefix}bias_hh_{suffix}"] for prefix, suffix, _ in names]
    w_hh = np.stack([w[f"{prefix}weight_hh_{suffix}"].T for prefix, suffix, _ in names], 0)  # [D, H, 4H]
    H = w_hh.shape[1]
    h = np.zeros((D, 1, H), np.float32)
    c = np.zeros((D, H), np.float32)
    out = np.empty((T, D * H), np.float32)
    rows = [np.arange(T - 1, -1, -1) if reverse else np.arange(T) for _, _, reverse in names]
    for s in range(0, T, STEP_FRAMES):
        steps = [row[s:s + STEP_FRAMES] for row in rows]
        z_in = np.stack([x[r] @ wi + b for r, wi, b in zip(steps, w_ih, bias, strict=True)], 0)  # [D, n, 4H]
        for t in range(len(steps[0])):
            z = z_in[:, t] + np.matmul(h, w_hh)[:, 0]
            g = 0.5 + 0.5 * np.tanh(0.5 * z)  # the sigmoid, without exp's overflow
            c = g[:, H:2 * H] * c + g[:, :H] * np.tanh(z[:, 2 * H:3 * H])
            h = (g[:, 3 * H:] * np.tanh(c))[:, None]
            for d in range(D):
                out[steps[d][t], d * H:(d + 1) * H] = h[d, 0]
    return out


def _bidirectional(w: dict[str, np.ndarray], layer: int, x: np.ndarray) -> np.ndarray:
    """Layer `layer` of the decoder BiLSTM over x [T, D]: [T, 2H] (forward states, then backward)."""
    return _lstm(w, x, [("lstm.", f"l{layer}", False), ("lstm.", f"l{layer}_reverse", True)])


def _audio(w: dict[str, np.ndarray], cfg: ModelConfig, mel: np.ndarray, speaker: np.ndarray,
           phones: np.ndarray | None) -> np.ndarray:
    """The audio encoder: standardised mel [T, n_mels] (and phones [T, P]) → Ha [T, audio_dim]."""
    h = _conv(w, "audio.inp", mel, 1) if cfg.n_mels != cfg.conv_channels else mel
    if cfg.n_phones:
        if phones is None:
            raise ValueError("this model needs per-frame phones")
        h = h + phones @ w["audio.phones.weight"][:, :, 0].T
    for i, d in enumerate(cfg.dilations):
        h = h + _leaky(_conv(w, f"audio.convs.{i}", h, d), cfg.leaky_slope)
    h = np.concatenate([h, np.broadcast_to(speaker, (len(h), len(speaker)))], axis=1)
    return _leaky(_linear(w, "audio.fc", h), cfg.leaky_slope)


def _text(w: dict[str, np.ndarray], cfg: ModelConfig, text: np.ndarray) -> np.ndarray:
    """The text encoder: text features [T, text_dim] → Hl [T, text_dim_out]."""
    h = _linear(w, "text.fc2", _leaky(_linear(w, "text.fc1", text), cfg.leaky_slope))
    return _lstm(w, h, [("text.lstm.", "l0", False)])


def _fuse(cfg: ModelConfig, ha: np.ndarray | None, hl: np.ndarray | None, speaker: np.ndarray) -> np.ndarray:
    if cfg.modalities == "audio":
        return ha
    if cfg.modalities == "text":
        return np.concatenate([hl, np.broadcast_to(speaker, (len(hl), len(speaker)))], axis=1)
    if cfg.fusion == "concat":
        return np.concatenate([ha, hl], axis=1)
    one = np.ones((len(ha), 1), np.float32)  # [Ha;1] ⊗ [Hl;1] per frame (facegen.model.tensor_fusion)
    a, lang = np.concatenate([ha, one], axis=1), np.concatenate([hl, one], axis=1)
    return (a[:, :, None] * lang[:, None, :]).reshape(len(ha), -1)


def decoder_states(weights: dict[str, np.ndarray], cfg: ModelConfig, mel: np.ndarray, text: np.ndarray | None,
                   speaker: int, phones: np.ndarray | None, fusion_frames: int) -> np.ndarray:
    """The decoder BiLSTM's states [T, 2 * lstm_dim] float32 of one clip: mel [T, n_mels], text [T, text_dim]
    (None: zeros), phones [T, P] one-hot (models with the phone stream), as FaceModel.decoder_states of
    FaceModel.decoder_input computes them."""
    T = len(mel)
    one_hot = np.zeros(cfg.num_speakers, np.float32)
    one_hot[speaker] = 1.0
    ha = hl = None
    if cfg.uses_audio:
        mel = (np.asarray(mel, np.float32) - weights["mel_mean"]) / weights["mel_std"]
        ha = _audio(weights, cfg, mel, one_hot, None if phones is None else np.asarray(phones, np.float32))
    if cfg.uses_text:
        hl = _text(weights, cfg, np.zeros((T, cfg.text_dim), np.float32) if text is None
                   else np.asarray(text, np.float32))
    x = np.empty((T, cfg.decoder_dim), np.float32)
    for s in range(0, T, fusion_frames):
        part = slice(s, s + fusion_frames)
        fused = _fuse(cfg, None if ha is None else ha[part], None if hl is None else hl[part], one_hot)
        x[part] = _leaky(_linear(weights, "fc_in", fused), cfg.leaky_slope)
    for layer in range(cfg.lstm_layers):
        x = _bidirectional(weights, layer, x)
    return x


def weight_shapes(cfg: ModelConfig) -> dict[str, tuple[int, ...]]:
    """The state dict's names and shapes for `cfg`, with the plain FC 3V output layer: what a bundle must hold
    (checked on load without torch; tests compare it with FaceModel's own state dict)."""
    shapes: dict[str, tuple[int, ...]] = {"mel_mean": (cfg.n_mels,), "mel_std": (cfg.n_mels,)}

    def linear(name: str, n_in: int, n_out: int, bias: bool = True) -> None:
        shapes[name + ".weight"] = (n_out, n_in)
        if bias:
            shapes[name + ".bias"] = (n_out,)

    def lstm(prefix: str, n_in: int, hidden: int, layers: int, directions: tuple[str, ...]) -> None:
        for layer in range(layers):
            for d in directions:
                width = n_in if layer == 0 else hidden * len(directions)
                shapes[f"{prefix}weight_ih_l{layer}{d}"] = (4 * hidden, width)
                shapes[f"{prefix}weight_hh_l{layer}{d}"] = (4 * hidden, hidden)
                shapes[f"{prefix}bias_ih_l{layer}{d}"] = (4 * hidden,)
                shapes[f"{prefix}bias_hh_l{layer}{d}"] = (4 * hidden,)

    C = cfg.conv_channels
    if cfg.uses_audio:
        if cfg.n_mels != C:
            shapes["audio.inp.weight"], shapes["audio.inp.bias"] = (C, cfg.n_mels, 1), (C,)
        for i, _ in enumerate(cfg.dilations):
            shapes[f"audio.convs.{i}.weight"], shapes[f"audio.convs.{i}.bias"] = (C, C, cfg.kernel_size), (C,)
        if cfg.n_phones:
            shapes["audio.phones.weight"] = (C, cfg.n_phones, 1)
        linear("audio.fc", C + cfg.num_speakers, cfg.audio_dim)
    if cfg.uses_text:
        linear("text.fc1", cfg.text_dim, cfg.text_hidden)
        linear("text.fc2", cfg.text_hidden, cfg.text_dim_out)
        lstm("text.lstm.", cfg.text_dim_out, cfg.text_dim_out, 1, ("",))
    if cfg.modalities == "both":
        fused = ((cfg.audio_dim + 1) * (cfg.text_dim_out + 1) if cfg.fusion == "tensor"
                 else cfg.audio_dim + cfg.text_dim_out)
    else:
        fused = cfg.audio_dim if cfg.modalities == "audio" else cfg.text_dim_out + cfg.num_speakers
    linear("fc_in", fused, cfg.decoder_dim)
    lstm("lstm.", cfg.decoder_dim, cfg.lstm_dim, cfg.lstm_layers, ("", "_reverse"))
    linear("fc_out", 2 * cfg.lstm_dim, 3 * cfg.num_vertices)
    return shapes


def check_weights(weights: dict[str, np.ndarray], cfg: ModelConfig) -> None:
    """ValueError naming what is missing, unexpected or of the wrong shape in a state dict for `cfg`."""
    want = weight_shapes(cfg)
    missing, extra = sorted(want.keys() - weights.keys()), sorted(weights.keys() - want.keys())
    wrong = sorted(k for k in want.keys() & weights.keys() if tuple(weights[k].shape) != want[k])
    for what, names in (("missing", missing), ("unexpected", extra), ("of the wrong shape", wrong)):
        if names:
            raise ValueError(f"weights {what}: {', '.join(names[:3])}{' ...' if len(names) > 3 else ''}")
