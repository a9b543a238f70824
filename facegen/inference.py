"""Inference: the network over a clip's features in bounded memory — decoder states, then frame streams.

Where the memory goes: per frame the network carries 128 mel bands, 384 text features, 8,385 fused
features and 256 decoder states, but outputs 3V = 70,110 numbers. A 10-minute clip (15,000 frames) has
4.2 GB of output and only 15 MB of decoder states. So the forward runs in two parts:

1. `decoder_states`: the encoders (convolutions, text LSTM) and the decoder BiLSTMs run over the whole
   clip at once, exactly as in one pass; the only wide step, tensor fusion + the decoder's first FC, runs
   in blocks of frames. Memory O(T x 256), time linear in T. Overlapping windows for the recurrences are
   not needed: their state is this small, and a whole-clip pass has no seams at all (block-wise output
   equals one pass to float rounding, ~1e-7 of the face size; tests/test_inference.py).
2. `FrameStream`: the output layer, frames = states @ W.T + (bias + template), computed block by block
   when a writer asks for frames (`blocks()`, indexing) into float32 arrays, with the template added in
   the same pass. Memory: one block (512 frames = 144 MB) at a time.

On the CPU the output layer runs through numpy's BLAS (OpenBLAS): on the AMD EPYC of the benchmarks it
is about twice as fast as torch's MKL sgemm for this shape (benchmarks/RESULTS.md). On CUDA both parts
run on the GPU and blocks are copied back.

Long clips in bounded memory need writers that read a FrameStream block by block: .npy does, and so does USD
points mode past 3,000 frames, as value clips (facegen.exchange.usd_clips: one layer per block of frames,
each saved and released; a single USD layer keeps every authored sample until it is saved).
"""

from __future__ import annotations

import contextlib
import weakref
from collections.abc import Iterator, Sequence

import numpy as np

from facegen.runtime import release_memory, threads

BLOCK_FRAMES = 512  # frames per output block (512 x 70,110 float32 = 144 MB; 256: 8% slower)
FUSION_FRAMES = 1024  # frames per block of tensor fusion + decoder FC (1024 x 8,385 float32 = 34 MB)
LAYER_FRAMES = 64  # frames a block's layers are added to at a time (64 x 70,110 float32 = 18 MB)
TURN_FRAMES = 512  # frames of eyeball points turned at a time in `project` (512 x 1,042 x 3 float64 = 13 MB)
LONG_FRAMES = 4096  # a longer clip runs the network this many frames at a time (`_long_states`)


def _model_on(bundle, device):
    model = bundle.model
    if next(model.parameters()).device != device:
        model.to(device)
    return model


# --------------------------------------------------------------------------------------------------
# the network in two parts


def decoder_states(bundle, mel: np.ndarray, text: np.ndarray | None, speaker: int, *, device=None,
                   fusion_frames: int = FUSION_FRAMES, phones: np.ndarray | None = None):
    """The decoder BiLSTM's states for one clip, [T, 2 * lstm_dim] float32 torch tensor on `device`.

    `mel` [T, n_mels], `text` [T, text_dim] or None (zeros when the model uses text), `phones` [T, P] one-hot
    (models with a phone stream; None: silence). Equal to the states of a one-pass forward: only the
    per-frame fusion and decoder FC run in blocks of `fusion_frames`.
    """
    return batch_decoder_states(bundle, [(mel, text, speaker, phones)], device=device,
                                fusion_frames=fusion_frames)[0]


def batch_decoder_states(bundle, clips: Sequence[tuple], *, device=None,
                         fusion_frames: int = FUSION_FRAMES) -> list:
    """Decoder states for several clips (mel, text, speaker[, phones]): encoders per clip, the BiLSTMs over
    one packed batch (each clip sees exactly its own frames, as alone). Returns one [T_i, H] tensor per
    clip."""
    import torch
    from torch.nn.utils.rnn import pack_sequence, unpack_sequence

    device = torch.device("cpu") if device is None else torch.device(device)
    model = _model_on(bundle, device)
    cfg = model.cfg
    states: list = [None] * len(clips)
    inputs, packed = [], []
    with torch.inference_mode(), _one_thread(device.type == "cpu"):
        for i, (mel, text, speaker, *rest) in enumerate(clips):
            T = int(mel.shape[0])
            phones = None
            if cfg.n_phones:
                if rest and rest[0] is not None:
                    phones = rest[0]
                else:
                    from facegen.phonetics import silence

                    phones = silence(T)
                if phones.shape != (T, cfg.n_phones):
                    raise ValueError(f"phones must be [{T}, {cfg.n_phones}], got {list(phones.shape)}")
            if cfg.uses_text and text is not None and text.shape != (T, cfg.text_dim):
                raise ValueError(f"text features must be [{T}, {cfg.text_dim}], got {list(text.shape)}")
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


class FrameStream:
    """Vertex positions [T, V, 3] float32 computed on demand from decoder states, block by block.

    Behaves like a read-only array for writers: `shape`, `dtype`, `len()`, indexing (`frames[i]`,
    `frames[a:b]`; frames are computed in blocks and the last block is kept, so reading frames in order
    costs one matrix product per block) and `np.asarray(frames)` (computes everything: T x V x 12 bytes).
    `blocks(n)` yields (first frame, [n, V, 3] array) without ever holding more than one block.
    """

    dtype = np.dtype(np.float32)
    ndim = 3

    def __init__(self, states, weight, base: np.ndarray, block_frames: int = BLOCK_FRAMES,
                 turns=None, layers: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        import torch

        self.turns = turns  # facegen.gaze.EyeTurns: the eyeballs turned after the affine output, or None
        self.scale = None  # (per-coordinate scales [3V], origin [3V]) of the network's motion, or None
        self.layers = layers  # (curves [T, K], offsets [K, 3V]) float32 added to the frames, or None
        self._torch = isinstance(states, torch.Tensor) and states.device.type != "cpu"
        if self._torch:
            self._states = states.float()
            self._weight = weight.detach().float()
            self._base = torch.as_tensor(base.reshape(-1), device=states.device)
        else:
            states = states.detach().cpu().numpy() if isinstance(states, torch.Tensor) else states
            self._states = np.ascontiguousarray(states, np.float32)
            w = weight.detach().cpu().numpy() if isinstance(weight, torch.Tensor) else weight
            self._weight = np.asarray(w, np.float32)
            self._base = np.ascontiguousarray(base, np.float32).reshape(-1)
        self.num_vertices = int(self._base.shape[0]) // 3
        self.block_frames = int(block_frames)
        self._cached: tuple[int, np.ndarray] | None = None
        self.blocks_computed = 0  # how many output blocks were computed (for tests and profiles)

    @property
    def shape(self) -> tuple[int, int, int]:
        return (int(self._states.shape[0]), self.num_vertices, 3)

    @property
    def nbytes(self) -> int:
        return int(np.prod(self.shape)) * 4

    def __len__(self) -> int:
        return self.shape[0]

    def compute(self, start: int, stop: int, out: np.ndarray | None = None) -> np.ndarray:
        """Frames start..stop-1 as [n, V, 3] float32 (written into `out` when given)."""
        n = stop - start
        if out is None:
            out = np.empty((n, self.num_vertices, 3), np.float32)
        flat = out.reshape(n, -1)
        if self._torch:
            import torch

            with torch.inference_mode():
                block = torch.addmm(self._base, self._states[start:stop], self._weight.T)
            flat[...] = block.cpu().numpy()
        else:
            np.matmul(self._states[start:stop], self._weight.T, out=flat)
            flat += self._base
        if self.scale is not None:  # origin + scales * (the network's frame - origin)
            scales, origin = self.scale
            flat -= origin
            flat *= scales
            flat += origin
        if self.layers is not None:  # LAYER_FRAMES at a time: no second block-sized array
            curves, offsets = self.layers
            for a in range(0, n, LAYER_FRAMES):
                flat[a:a + LAYER_FRAMES] += curves[start + a:min(start + a + LAYER_FRAMES, stop)] @ offsets
        if self.turns is not None:
            self.turns.apply(start, out)
        self.blocks_computed += 1
        return out

    def blocks(self, block_frames: int | None = None, start: int = 0,
               stop: int | None = None, ahead: bool = False) -> Iterator[tuple[int, np.ndarray]]:
        """(first frame, frames [n, V, 3]) for consecutive blocks of `block_frames`; each array is new.
        `ahead`: the next block is computed in a thread (numpy frees the GIL) as the caller uses this one."""
        size = block_frames or self.block_frames
        stop = len(self) if stop is None else min(stop, len(self))
        starts = range(start, stop, size)
        if not ahead or len(starts) < 2:
            for s in starts:
                yield s, self.compute(s, min(s + size, stop))
            return
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(1, thread_name_prefix="facegen-frames") as pool:
            coming = pool.submit(self.compute, starts[0], min(starts[0] + size, stop))
            for k, s in enumerate(starts):
                block = coming.result()
                if k + 1 < len(starts):
                    coming = pool.submit(self.compute, starts[k + 1], min(starts[k + 1] + size, stop))
                yield s, block
                del block

    def with_layers(self, curves: np.ndarray, offsets: np.ndarray) -> FrameStream:
        """This stream plus layers: frame t gains sum_k curves[t, k] * offsets[k] (`curves` [T, K], `offsets`
        [K, 3V]), e.g. blinks; `project`, `every` and the blocks see them as they see the network's motion
        (the network's weights are shared, not copied)."""
        curves = np.asarray(curves, np.float32).reshape(len(self), -1)
        offsets = np.asarray(offsets, np.float32).reshape(curves.shape[1], -1)
        if self.layers is not None:
            curves = np.concatenate([self.layers[0], curves], 1)
            offsets = np.concatenate([self.layers[1], offsets])
        return self._with(turns=self.turns, layers=(curves, offsets))

    def _with(self, states=None, turns=None, layers=None) -> FrameStream:
        """A stream on these weights (its states `states`, default these) with `turns` and `layers`."""
        out = FrameStream.__new__(FrameStream)
        out.__dict__.update(self.__dict__)
        out._states = self._states if states is None else states
        out.turns, out.layers, out._cached, out.blocks_computed = turns, layers, None, 0
        return out

    def with_scale(self, scales: np.ndarray, origin: np.ndarray) -> FrameStream:
        """This stream with the network's motion about `origin` ([V, 3], the template) scaled per vertex by
        `scales` [V] (facegen.strength); layers and turns added after it are not scaled."""
        if self.layers is not None or self.turns is not None:
            raise ValueError("scale a stream before adding layers or turns")
        out = self._with(turns=None, layers=None)
        out.scale = (np.repeat(np.asarray(scales, np.float32), 3),
                     np.ascontiguousarray(origin, np.float32).reshape(-1))
        return out

    def with_turns(self, turns) -> FrameStream:
        """This stream with its eyeballs turned by `turns` (facegen.gaze.EyeTurns)."""
        return self._with(turns=turns, layers=self.layers)

    def every(self, step: int) -> FrameStream:
        """The stream of every `step`-th frame (the same weights; its states a copy of theirs)."""
        return self._with(self._states[::step], None if self.turns is None else self.turns.every(step),
                          None if self.layers is None else (self.layers[0][::step], self.layers[1]))

    def project(self, basis: np.ndarray, origin: np.ndarray) -> np.ndarray:
        """(frames - origin) @ basis.T for every frame, [T, K] float64, for `basis` [K, 3V] and `origin` [3V],
        without computing a frame: the output layer is affine, so it is states @ (W.T basis.T) + (base -
        origin) basis.T, K numbers per frame from 2H instead of 3V (the ARKit fit's right-hand side)."""
        basis = np.asarray(basis, np.float32)
        weight, base = self._weight, self._base
        if self._torch:
            weight, base = weight.cpu().numpy(), base.cpu().numpy()
        on_net = basis if self.scale is None else basis * self.scale[0]  # what the network's motion meets
        through = np.zeros((weight.shape[1], len(basis)))
        for s in range(0, len(weight), 8192):  # in float64, a slice of W at a time
            through += weight[s:s + 8192].T.astype(np.float64) @ on_net[:, s:s + 8192].T.astype(np.float64)
        if self.scale is None:
            offset = (base.astype(np.float64) - np.asarray(origin, np.float64).reshape(-1)) @ basis.T.astype(
                np.float64)
        else:
            scaled_from = self.scale[1].astype(np.float64)
            to_origin = scaled_from - np.asarray(origin, np.float64).reshape(-1)
            offset = ((base.astype(np.float64) - scaled_from) @ on_net.T.astype(np.float64)
                      + to_origin @ basis.T.astype(np.float64))
        states = self._states.cpu().numpy() if self._torch else self._states
        out = np.empty((len(states), len(basis)))
        for s in range(0, len(states), 8192):
            out[s:s + 8192] = states[s:s + 8192].astype(np.float64) @ through + offset
        if self.layers is not None:
            curves, offsets = self.layers
            out += curves.astype(np.float64) @ (offsets.astype(np.float64) @ basis.T.astype(np.float64))
        if self.turns is not None:  # the eyeballs' turn, computed on their points only
            rows = (self.turns.indices[:, None] * 3 + np.arange(3)).reshape(-1)
            sub = basis[:, rows].T.astype(np.float64)
            for s in range(0, len(states), TURN_FRAMES):
                points = self.points(self.turns.indices, s, s + TURN_FRAMES)
                moved = self.turns.turn(s, points) - points
                out[s:s + TURN_FRAMES] += moved.reshape(len(points), -1) @ sub
        return out

    def points(self, indices: np.ndarray, start: int = 0, stop: int | None = None) -> np.ndarray:
        """The vertices `indices` in frames `start` to `stop` (None: the last), [n, k, 3] float64, from their
        rows of the output layer only, before the eyeballs' turn (the jaw read from the chin:
        facegen.face.parts; the turned points: `project`)."""
        rows = (np.asarray(indices, np.int64)[:, None] * 3 + np.arange(3)).reshape(-1)
        weight, base = self._weight, self._base
        if self._torch:
            weight, base = weight[rows].cpu().numpy(), base[rows].cpu().numpy()
        else:
            weight, base = weight[rows], base[rows]
        states = (self._states.cpu().numpy() if self._torch else self._states)[start:stop]
        flat = states.astype(np.float64) @ weight.T.astype(np.float64) + base.astype(np.float64)
        if self.scale is not None:
            scaled_from = self.scale[1][rows].astype(np.float64)
            flat = scaled_from + self.scale[0][rows] * (flat - scaled_from)
        if self.layers is not None:
            flat += self.layers[0][start:stop].astype(np.float64) @ self.layers[1][:, rows].astype(np.float64)
        return flat.reshape(len(states), -1, 3)

    def _block_of(self, i: int) -> tuple[int, np.ndarray]:
        first = (i // self.block_frames) * self.block_frames
        if self._cached is None or self._cached[0] != first:
            self._cached = (first, self.compute(first, min(first + self.block_frames, len(self))))
        return self._cached

    def __getitem__(self, key):
        rest = ()
        if isinstance(key, tuple):
            key, rest = key[0], key[1:]
        T = len(self)
        if isinstance(key, int | np.integer):
            i = int(key) + T if key < 0 else int(key)
            if not 0 <= i < T:
                raise IndexError(f"frame {key} is out of range for {T} frames")
            first, block = self._block_of(i)
            out = block[i - first]
        elif isinstance(key, slice):
            start, stop, step = key.indices(T)
            out = self.compute(start, max(start, stop))[::step] if step > 0 else np.asarray(self)[key]
        else:
            out = np.asarray(self)[key]
        return out[rest] if rest else out

    def __iter__(self) -> Iterator[np.ndarray]:
        for _, block in self.blocks():
            yield from block

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        out = np.empty(self.shape, np.float32)
        for s in range(0, len(self), self.block_frames):
            self.compute(s, min(s + self.block_frames, len(self)), out=out[s:s + self.block_frames])
        return out if dtype is None else out.astype(dtype, copy=False)

    def __repr__(self) -> str:
        return f"FrameStream(shape={self.shape}, block_frames={self.block_frames})"


def states_at_rate(states, fps_in: float, fps_out: float, frames: int):
    """Decoder states [T, H] (a tensor or an array) at another frame rate: output frame i, at time i/fps_out,
    lies linearly between the two network frames around it (the last one held past the end).

    The output layer is affine, so this is the linear interpolation of the vertices themselves, done on 256
    numbers per frame instead of 70,110: no overshoot, and a lip closure the network holds over two frames
    (80 ms at 25 fps; p/b/m closures last 70-120 ms) is still closed at any rate."""
    if frames == len(states) and fps_in == fps_out:
        return states
    if isinstance(states, np.ndarray):
        out = np.empty((frames, *states.shape[1:]), states.dtype)
    else:
        import torch

        out = torch.empty((frames, *states.shape[1:]), dtype=states.dtype, device=states.device)
    for s in range(0, frames, 8192):  # a block at a time: no [frames, H] temporaries for a long clip
        pos = np.minimum(np.arange(s, min(s + 8192, frames), dtype=np.float64) * (fps_in / fps_out),
                         len(states) - 1)
        lo = np.floor(pos).astype(np.int64)
        hi = np.minimum(lo + 1, len(states) - 1)
        w = (pos - lo).astype(np.float32)[:, None]
        if isinstance(states, np.ndarray):
            out[s:s + len(pos)] = states[lo] * (1 - w) + states[hi] * w
        else:
            wt = torch.from_numpy(w).to(states.device, states.dtype)
            lo_t, hi_t = torch.from_numpy(lo).to(states.device), torch.from_numpy(hi).to(states.device)
            out[s:s + len(pos)] = states[lo_t] * (1 - wt) + states[hi_t] * wt
    return out


REST_SECONDS = 3.0  # of quiet noise: the network's answer to silence (`rest_offsets`)
REST_DBFS = -50.0  # a quiet room (the network answers -60 to -30 dBFS alike; digital silence not)
_REST: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # model -> {speaker: offsets}


def rest_offsets(bundle, speaker: int = 0) -> np.ndarray:
    """The offsets [3V] float32 the network gives in silence for `speaker` (no words, quiet noise): its rest.

    The rig the network learns from rests exactly on the template, but a network only comes close: the
    shipped one holds the lips a fraction of a millimetre pursed in silence, which a 52-shape fit reads as
    mouthFunnel 0.06-0.14, mouthPucker, mouthPress (issue 24). `frame_stream` subtracts this, so silence
    is the template in every format, as an idle clip is. Computed once per model and speaker (~20 ms)."""
    from facegen.audio import mel_features

    cached = _REST.setdefault(bundle.model, {})
    if speaker not in cached:
        cfg = bundle.features
        noise = np.random.default_rng(0).standard_normal(int(REST_SECONDS * cfg.sample_rate))
        mel = mel_features((noise * 10 ** (REST_DBFS / 20)).astype(np.float32), cfg.sample_rate, cfg,
                           bundle.mel_filters)
        states = decoder_states(bundle, mel, None, speaker).float().cpu().numpy()
        weight, bias = bundle.model.output_layer()
        middle = states[len(states) // 3: 2 * len(states) // 3].mean(0)  # away from the clip's edges
        cached[speaker] = (weight.detach().cpu().float().numpy() @ middle
                           + bias.detach().cpu().float().numpy()).astype(np.float32)
    return cached[speaker]


def frame_stream(bundle, states, template: np.ndarray | None = None,
                 block_frames: int = BLOCK_FRAMES, *, speaker: int = 0) -> FrameStream:
    """Frames = template + offsets from decoder `states` (template None: offsets only), the offsets taken
    from the network's rest for `speaker` (`rest_offsets`)."""
    weight, bias = bundle.model.output_layer()
    base = bias.detach().cpu().numpy().astype(np.float32) - rest_offsets(bundle, speaker)
    if template is not None:
        base = base + np.asarray(template, np.float32).reshape(-1)
    return FrameStream(states, weight, base, block_frames)


def predict_frames(bundle, mel: np.ndarray, text: np.ndarray | None, speaker: int, *,
                   template: np.ndarray | None = None, device=None, block_frames: int = BLOCK_FRAMES,
                   phones: np.ndarray | None = None) -> FrameStream:
    """The clip's vertex positions (template + offsets; offsets alone when `template` is None) as a
    FrameStream: the decoder states are computed now, the output frames when they are read."""
    states = decoder_states(bundle, mel, text, speaker, device=device, phones=phones)
    return frame_stream(bundle, states, template, block_frames, speaker=speaker)
