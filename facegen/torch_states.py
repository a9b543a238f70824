"""Decoder states by the torch network (facegen.model): inference on a CUDA device, or on torch's CPU when a
caller passes torch.device("cpu"). On the CPU facegen.inference otherwise runs facegen.numpy_network, which
gives the same states without importing torch; training uses the torch network directly.
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence

import numpy as np

from facegen.runtime import release_memory, threads

LONG_FRAMES = 4096  # a longer clip runs the network this many frames at a time (`_long_states`)


def _model_on(bundle, device):
    model = bundle.model
    if next(model.parameters()).device != device:
        model.to(device)
    return model



def batch_states(bundle, clips: Sequence[tuple], device, fusion_frames: int) -> list:
    """Decoder states of several clips (mel, text, speaker, phones; checked by facegen.inference) on the
    torch `device`: encoders per clip, the BiLSTMs over one packed batch (each clip sees exactly its own
    frames, as alone). One [T_i, H] tensor per clip."""
    import torch
    from torch.nn.utils.rnn import pack_sequence, unpack_sequence

    device = torch.device(device)
    model = _model_on(bundle, device)
    cfg = model.cfg
    states: list = [None] * len(clips)
    inputs, packed = [], []
    with torch.inference_mode(), _one_thread(device.type == "cpu"):
        for i, (mel, text, speaker, phones) in enumerate(clips):
            T = int(mel.shape[0])
            spk = model.speaker_one_hot(speaker).to(device)
            if T > LONG_FRAMES:
                states[i] = _long_states(model, mel, text, spk, phones, fusion_frames)
                continue
            text_t = phones_t = None
            if cfg.n_phones:
                phones_t = _tensor(phones, device)
            mel_t = _tensor(mel, device)
            if cfg.uses_text:
                text_t = _tensor(np.zeros((T, cfg.text_dim), np.float32) if text is None else text, device)
            inputs.append(model.decoder_input(mel_t, text_t, spk, block_frames=fusion_frames,
                                              phones=phones_t)[0])
            packed.append(i)
        if len(inputs) == 1:
            states[packed[0]] = model.decoder_states(inputs[0][None])[0]
        elif inputs:
            found = unpack_sequence(model.decoder_states(pack_sequence(inputs, enforce_sorted=False)))
            for i, clip_states in zip(packed, found, strict=True):
                states[i] = clip_states
        return states


def _tensor(array: np.ndarray, device):
    """A [1, T, D] float32 tensor of a [T, D] array on `device` (a view on the CPU)."""
    import torch

    return torch.from_numpy(np.ascontiguousarray(array, np.float32))[None].to(device)


def _long_states(model, mel: np.ndarray, text: np.ndarray | None, spk, phones: np.ndarray | None,
                 fusion_frames: int):
    """The decoder states of a clip longer than LONG_FRAMES, computed LONG_FRAMES frames at a time: each
    call into torch is short (a signal can stop the run between them) and nothing of the length of the clip
    exists but the decoder's input and two layers of its states. The same network: the convolutions see
    their receptive field past each piece's edges; the LSTMs carry their state from piece to piece (the
    backward directions from the end of the clip back); equal to one pass to float rounding
    (tests/test_long_audio.py)."""
    import torch

    cfg, device = model.cfg, spk.device
    T, step, halo = len(mel), LONG_FRAMES, cfg.receptive_field
    x = torch.empty(T, cfg.decoder_dim, device=device)
    text_state = None
    for s in range(0, T, step):
        e = min(s + step, T)
        enc = {}
        if model.audio is not None:
            a, b = max(0, s - halo), min(T, e + halo)
            mel_t = (_tensor(mel[a:b], device) - model.mel_mean) / model.mel_std
            phones_t = _tensor(phones[a:b], device) if phones is not None else None
            enc["audio"] = model.audio(mel_t, spk, phones_t)[:, s - a:e - a]
        if model.text is not None:
            words = np.zeros((e - s, cfg.text_dim), np.float32) if text is None else text[s:e]
            hidden = model.text.fc2(model.text.act(model.text.fc1(_tensor(words, device))))
            enc["text"], text_state = model.text.lstm(hidden, text_state)
        for f in range(0, e - s, fusion_frames):
            part = {k: v[:, f:f + fusion_frames] for k, v in enc.items()}
            x[s + f:s + f + fusion_frames] = model.act(model.fc_in(model.fuse(part, spk)))[0]
    for layer in range(cfg.lstm_layers):
        x = _bidirectional(model, layer, x, step)
    release_memory()  # the pieces' blocks, freed: while the frames are written the heap holds no holes
    return x


def _bidirectional(model, layer: int, x, step: int):
    """One layer of the decoder BiLSTM over x [T, D], `step` frames at a time: [T, 2 * lstm_dim]. The forward
    direction runs first; the backward direction then walks from the end, and a piece of x it has read is
    needed no more, so where x is as wide as the output (every layer after the first) the output is written
    into x's own memory, the forward direction kept in a buffer of half its width until then. At most 1.5
    times the output's size is held (2 hours: 276 MB, not 460)."""
    import torch

    H, T = model.cfg.lstm_dim, len(x)

    def lstm_of(suffix: str):
        lstm = torch.nn.LSTM(x.shape[1], H, batch_first=True).to(x.device)
        for name in ("weight_ih", "weight_hh", "bias_ih", "bias_hh"):
            getattr(lstm, f"{name}_l0").copy_(getattr(model.lstm, f"{name}_l{layer}{suffix}"))
        return lstm

    in_place = x.shape[1] == 2 * H
    out = x if in_place else torch.empty(T, 2 * H, device=x.device)
    forward = torch.empty(T, H, device=x.device) if in_place else out[:, :H]
    lstm, state = lstm_of(""), None
    for s in range(0, T, step):
        y, state = lstm(x[s:s + step][None], state)
        forward[s:s + step] = y[0]
    lstm, state = lstm_of("_reverse"), None
    for s in reversed(range(0, T, step)):
        y, state = lstm(x[s:s + step].flip(0)[None], state)
        out[s:s + step, H:] = y[0].flip(0)  # rows s.. of x are read: this piece's output may replace them
        if in_place:
            out[s:s + step, :H] = forward[s:s + step]
    return out


def _one_thread(enabled: bool) -> contextlib.AbstractContextManager:
    """One torch thread for the decoder states: thousands of small sequential LSTM steps gain little from
    a second thread (0.095 s vs 0.11-0.13 s for 1500 frames, idle 2-core EPYC) but lose 4-6x when its
    OpenMP threads sleep between steps (OMP_WAIT_POLICY=PASSIVE) or the cores are busy. The output
    layer, where the work is, runs on numpy's BLAS threads, which this does not touch."""
    return threads(1 if enabled else None, ("torch",))


