"""Inference: the network over a clip's features in bounded memory — decoder states, then frame streams.

Where the memory goes: per frame the network carries 128 mel bands, 384 text features, 8,385 fused
features and 256 decoder states, but outputs 3V = 70,110 numbers. A 10-minute clip (15,000 frames) has
4.2 GB of output and only 15 MB of decoder states. So the forward runs in two parts:

1. `decoder_states`: the encoders (convolutions, text LSTM) and the decoder BiLSTMs run over the whole
   clip at once, exactly as in one pass; the only wide step, tensor fusion + the decoder's first FC, runs
   in blocks of frames. Memory O(T x 256), time linear in T. Overlapping windows for the recurrences are
   not needed: their state is this small, and a whole-clip pass has no seams at all (block-wise output
   equals one pass to float rounding, ~1e-7 of the face size; tests/test_inference.py). On the CPU this is
   facegen.numpy_network (numpy: torch's import would cost more than the whole inference of a short
   clip); on a CUDA device facegen.torch_states (the torch network, clips packed into one batch).
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

import weakref
from collections.abc import Iterator, Sequence

import numpy as np

BLOCK_FRAMES = 512  # frames per output block (512 x 70,110 float32 = 144 MB; 256: 8% slower)
FUSION_FRAMES = 1024  # frames per block of tensor fusion + decoder FC (1024 x 8,385 float32 = 34 MB)
LAYER_FRAMES = 64  # frames a block's layers are added to at a time (64 x 70,110 float32 = 18 MB)
TURN_FRAMES = 512  # frames of eyeball points turned at a time in `project` (512 x 1,042 x 3 float64 = 13 MB)


# --------------------------------------------------------------------------------------------------
# the network in two parts


def decoder_states(bundle, mel: np.ndarray, text: np.ndarray | None, speaker: int, *, device=None,
                   fusion_frames: int = FUSION_FRAMES, phones: np.ndarray | None = None):
    """The decoder BiLSTM's states for one clip, [T, 2 * lstm_dim] float32 (see batch_decoder_states).

    `mel` [T, n_mels], `text` [T, text_dim] or None (zeros when the model uses text), `phones` [T, P] one-hot
    (models with a phone stream; None: silence). Equal to the states of a one-pass forward: only the
    per-frame fusion and decoder FC run in blocks of `fusion_frames`.
    """
    return batch_decoder_states(bundle, [(mel, text, speaker, phones)], device=device,
                                fusion_frames=fusion_frames)[0]


def batch_decoder_states(bundle, clips: Sequence[tuple], *, device=None,
                         fusion_frames: int = FUSION_FRAMES) -> list:
    """Decoder states for several clips (mel, text, speaker[, phones]), each as if alone: float32 arrays
    [T_i, H] on the CPU (`device` None or "cpu": facegen.numpy_network, torch is not imported), tensors on a
    torch `device` (a torch.device, even the CPU's: facegen.torch_states, the clips' BiLSTMs packed)."""
    cfg = bundle.config
    clips = [(mel, text, speaker, _phones_of(cfg, mel, text, rest[0] if rest else None))
             for mel, text, speaker, *rest in clips]
    if device is None or device == "cpu":
        from facegen.numpy_network import decoder_states as states_of

        weights = bundle.weights
        return [states_of(weights, cfg, mel, text, speaker, phones, fusion_frames)
                for mel, text, speaker, phones in clips]
    from facegen.torch_states import batch_states

    return batch_states(bundle, clips, device, fusion_frames)


def _phones_of(cfg, mel: np.ndarray, text: np.ndarray | None, phones: np.ndarray | None) -> np.ndarray | None:
    """A clip's inputs checked against the model: its phones (silence when the model takes them and none are
    given; None when it does not), ValueError for a wrong shape."""
    T = int(mel.shape[0])
    if cfg.uses_text and text is not None and text.shape != (T, cfg.text_dim):
        raise ValueError(f"text features must be [{T}, {cfg.text_dim}], got {list(text.shape)}")
    if not cfg.n_phones:
        return None
    if phones is None:
        from facegen.phonetics import silence

        phones = silence(T)
    if phones.shape != (T, cfg.n_phones):
        raise ValueError(f"phones must be [{T}, {cfg.n_phones}], got {list(phones.shape)}")
    return phones


def _is_tensor(x) -> bool:
    """Whether x is a torch tensor (without importing torch: nothing made one if it is not imported)."""
    import sys

    torch = sys.modules.get("torch")
    return torch is not None and isinstance(x, torch.Tensor)


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
        self.turns = turns  # facegen.gaze.EyeTurns: the eyeballs turned after the affine output, or None
        self.scale = None  # (per-coordinate scales [3V], origin [3V]) of the network's motion, or None
        self.layers = layers  # (curves [T, K], offsets [K, 3V]) float32 added to the frames, or None
        self._torch = _is_tensor(states) and states.device.type != "cpu"
        if self._torch:
            import torch

            self._states = states.float()
            self._weight = torch.as_tensor(weight, device=states.device).float()
            self._base = torch.as_tensor(base.reshape(-1), device=states.device)
        else:
            states = states.detach().cpu().numpy() if _is_tensor(states) else states
            self._states = np.ascontiguousarray(states, np.float32)
            w = weight.detach().cpu().numpy() if _is_tensor(weight) else weight
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
_REST: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # bundle -> {speaker: offsets}


def rest_offsets(bundle, speaker: int = 0) -> np.ndarray:
    """The offsets [3V] float32 the network gives in silence for `speaker` (no words, quiet noise): its rest.

    The rig the network learns from rests exactly on the template, but a network only comes close: the
    shipped one holds the lips a fraction of a millimetre pursed in silence, which a 52-shape fit reads as
    mouthFunnel 0.06-0.14, mouthPucker, mouthPress (issue 24). `frame_stream` subtracts this, so silence
    is the template in every format, as an idle clip is. Computed once per model and speaker (~20 ms)."""
    from facegen.audio import mel_features

    cached = _REST.setdefault(bundle, {})
    if speaker not in cached:
        cfg = bundle.features
        noise = np.random.default_rng(0).standard_normal(int(REST_SECONDS * cfg.sample_rate))
        mel = mel_features((noise * 10 ** (REST_DBFS / 20)).astype(np.float32), cfg.sample_rate, cfg,
                           bundle.mel_filters)
        states = decoder_states(bundle, mel, None, speaker)
        weights = bundle.weights
        middle = states[len(states) // 3: 2 * len(states) // 3].mean(0)  # away from the clip's edges
        cached[speaker] = (weights["fc_out.weight"] @ middle + weights["fc_out.bias"]).astype(np.float32)
    return cached[speaker]


def frame_stream(bundle, states, template: np.ndarray | None = None,
                 block_frames: int = BLOCK_FRAMES, *, speaker: int = 0) -> FrameStream:
    """Frames = template + offsets from decoder `states` (template None: offsets only), the offsets taken
    from the network's rest for `speaker` (`rest_offsets`)."""
    weights = bundle.weights
    weight, bias = weights["fc_out.weight"], weights["fc_out.bias"]
    base = bias - rest_offsets(bundle, speaker)
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
