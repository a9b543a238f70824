"""Inference: the network on a clip's features — device choice, bounded-memory forward, frame streams,
batches of clips, and stage profiles (FACEGEN_PROFILE=1).

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

Long clips in bounded memory need writers that read a FrameStream block by block (.npy can; a USD layer
keeps every authored `points` sample in memory until it is saved — 1.04 x the frames' size, measured —
so a points .usdc of 10 minutes needs ~4.4 GB whatever the inference does).
"""

from __future__ import annotations

import contextlib
import json
import os
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from facegen.errors import FacegenError
from facegen.runtime import Say, select_device, silent

BLOCK_FRAMES = 512  # frames per output block (512 x 70,110 float32 = 144 MB; 256: 8% slower)
FUSION_FRAMES = 1024  # frames per block of tensor fusion + decoder FC (1024 x 8,385 float32 = 34 MB)
def _model_on(bundle, device):
    model = bundle.model
    if next(model.parameters()).device != device:
        model.to(device)
    return model


# --------------------------------------------------------------------------------------------------
# the network in two parts


def decoder_states(bundle, mel: np.ndarray, text: np.ndarray | None, speaker: int, *, device=None,
                   fusion_frames: int = FUSION_FRAMES):
    """The decoder BiLSTM's states for one clip, [T, 2 * lstm_dim] float32 torch tensor on `device`.

    `mel` [T, n_mels], `text` [T, text_dim] or None (zeros when the model uses text). Equal to the states
    of a one-pass forward: only the per-frame fusion and decoder FC run in blocks of `fusion_frames`.
    """
    return batch_decoder_states(bundle, [(mel, text, speaker)], device=device, fusion_frames=fusion_frames)[0]


def batch_decoder_states(bundle, clips: Sequence[tuple[np.ndarray, np.ndarray | None, int]], *, device=None,
                         fusion_frames: int = FUSION_FRAMES) -> list:
    """Decoder states for several clips (mel, text, speaker): encoders per clip, the BiLSTMs over one
    packed batch (each clip sees exactly its own frames, as alone). Returns one [T_i, H] tensor per clip."""
    import torch
    from torch.nn.utils.rnn import pack_sequence, unpack_sequence

    from facegen.model import one_hot

    device = torch.device("cpu") if device is None else torch.device(device)
    model = _model_on(bundle, device)
    cfg = model.cfg
    inputs = []
    with torch.inference_mode(), _one_thread(device.type == "cpu"):
        for mel, text, speaker in clips:
            T = int(mel.shape[0])
            mel_t = torch.from_numpy(np.ascontiguousarray(mel, np.float32))[None].to(device)
            text_t = None
            if cfg.uses_text:
                if text is None:
                    text = np.zeros((T, cfg.text_dim), np.float32)
                if text.shape != (T, cfg.text_dim):
                    raise ValueError(f"text features must be [{T}, {cfg.text_dim}], got {list(text.shape)}")
                text_t = torch.from_numpy(np.ascontiguousarray(text, np.float32))[None].to(device)
            spk = one_hot(speaker, cfg.num_speakers).to(device)
            enc = model.encode(mel_t, text_t, spk)
            x = torch.empty(T, cfg.decoder_dim, device=device)
            for s in range(0, T, fusion_frames):
                part = {k: v[:, s:s + fusion_frames] for k, v in enc.items()}
                x[s:s + fusion_frames] = model.act(model.fc_in(model.fuse(part, spk)))[0]
            inputs.append(x)
        if len(inputs) == 1:
            return [model.lstm(inputs[0][None])[0][0]]
        packed, _ = model.lstm(pack_sequence(inputs, enforce_sorted=False))
        return list(unpack_sequence(packed))


@contextlib.contextmanager
def _one_thread(enabled: bool) -> Iterator[None]:
    """One torch thread for the decoder states: thousands of small sequential LSTM steps gain little from
    a second thread (0.095 s vs 0.11-0.13 s for 1500 frames, idle 2-core EPYC) but lose 4-6x when its
    OpenMP threads sleep between steps (OMP_WAIT_POLICY=PASSIVE) or the cores are busy. The output
    layer, where the work is, runs on numpy's BLAS threads, which this does not touch."""
    import torch

    threads = torch.get_num_threads()
    if enabled and threads > 1:
        torch.set_num_threads(1)
    try:
        yield
    finally:
        if torch.get_num_threads() != threads:
            torch.set_num_threads(threads)


class FrameStream:
    """Vertex positions [T, V, 3] float32 computed on demand from decoder states, block by block.

    Behaves like a read-only array for writers: `shape`, `dtype`, `len()`, indexing (`frames[i]`,
    `frames[a:b]`; frames are computed in blocks and the last block is kept, so reading frames in order
    costs one matrix product per block) and `np.asarray(frames)` (computes everything: T x V x 12 bytes).
    `blocks(n)` yields (first frame, [n, V, 3] array) without ever holding more than one block.
    """

    dtype = np.dtype(np.float32)
    ndim = 3

    def __init__(self, states, weight, base: np.ndarray, block_frames: int = BLOCK_FRAMES) -> None:
        import torch

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
        self.blocks_computed += 1
        return out

    def blocks(self, block_frames: int | None = None, start: int = 0,
               stop: int | None = None) -> Iterator[tuple[int, np.ndarray]]:
        """(first frame, frames [n, V, 3]) for consecutive blocks of `block_frames`; each array is new."""
        size = block_frames or self.block_frames
        stop = len(self) if stop is None else min(stop, len(self))
        for s in range(start, stop, size):
            yield s, self.compute(s, min(s + size, stop))

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

    def materialize(self) -> np.ndarray:
        return np.asarray(self)

    def factors(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(states [T, H], weight [3V, H], base [3V]) with frames.reshape(T, -1) == states @ weight.T + base.

        Every frame lies in an H-dimensional (256) affine subspace, so a PCA of the frames (morph targets
        for .glb / USD blendshapes) can be computed exactly from these in O((T + V) x H) memory."""
        if self._torch:
            return (self._states.cpu().numpy(), self._weight.cpu().numpy(), self._base.cpu().numpy())
        return self._states, self._weight, self._base

    def __repr__(self) -> str:
        return f"FrameStream(shape={self.shape}, block_frames={self.block_frames})"


def frame_stream(bundle, states, template: np.ndarray | None = None,
                 block_frames: int = BLOCK_FRAMES) -> FrameStream:
    """Frames = template + offsets from decoder `states` (template None: offsets only)."""
    fc = bundle.model.fc_out
    base = fc.bias.detach().cpu().numpy().astype(np.float32)
    if template is not None:
        base = base + np.asarray(template, np.float32).reshape(-1)
    return FrameStream(states, fc.weight, base, block_frames)


def predict_frames(bundle, mel: np.ndarray, text: np.ndarray | None, speaker: int, *,
                   template: np.ndarray | None = None, device=None,
                   block_frames: int = BLOCK_FRAMES) -> FrameStream:
    """The clip's vertex positions (template + offsets; offsets alone when `template` is None) as a
    FrameStream: the decoder states are computed now, the output frames when they are read."""
    states = decoder_states(bundle, mel, text, speaker, device=device)
    return frame_stream(bundle, states, template, block_frames)


def predict_offsets(bundle, mel: np.ndarray, text: np.ndarray | None, speaker: int, *,
                    device=None) -> np.ndarray:
    """Run the network: mel [T,n_mels], text [T,D] or None → offsets [T,V,3] float32 (all in memory)."""
    return np.asarray(predict_frames(bundle, mel, text, speaker, device=device))


# --------------------------------------------------------------------------------------------------
# many clips


@dataclass
class Job:
    """One clip to animate: the audio, where its words come from, the speaker, the output file."""

    audio: Path
    output: Path
    text: str | None = None
    alignment: Path | None = None
    speaker: str | None = None
    no_text: bool = False


@dataclass
class JobResult:
    job: Job
    files: list[Path] = field(default_factory=list)
    error: str | None = None
    frames: int = 0
    seconds: float = 0.0

    @property
    def ok(self) -> bool:
        return self.error is None


MANIFEST_COLUMNS = ("audio", "text", "text_file", "alignment", "speaker", "output")


def read_manifest(path: str | os.PathLike, outdir: str | os.PathLike | None = None,
                  default_ext: str = ".usdc") -> list[Job]:
    """Jobs from a CSV (header: audio, text | text_file | alignment, speaker, output) or a JSON manifest
    (a list of objects with those keys, or {"jobs": [...]}).

    Relative audio/text_file/alignment paths are relative to the manifest's folder; relative outputs to
    `outdir` (default: the manifest's folder). A missing output is the audio's name with `default_ext`.
    A row with neither text nor alignment has its words recognised (as `facegen animate` without --text).
    """
    import csv

    from facegen.exchange import format_module

    path = Path(path)
    try:
        raw = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise FacegenError(f"cannot read manifest {path} ({exc}): pass a UTF-8 CSV or JSON file") from exc
    if raw.lstrip().startswith(("[", "{")):
        try:
            data = json.loads(raw)
        except json.JSONDecodeError as exc:
            raise FacegenError(f"manifest {path} is not valid JSON ({exc}): fix it") from exc
        rows = data.get("jobs") if isinstance(data, dict) else data
        if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
            raise FacegenError(f'manifest {path} must be a list of objects or {{"jobs": [...]}}')
    else:
        rows = list(csv.DictReader(raw.splitlines()))
    base = path.parent
    out_base = Path(outdir) if outdir is not None else base
    jobs = []
    for n, row in enumerate(rows, 1):
        row = {str(k).strip().lower(): (str(v).strip() if v is not None else "") for k, v in row.items() if k}
        unknown = sorted(set(row) - set(MANIFEST_COLUMNS))
        if unknown:
            raise FacegenError(f"manifest {path}: unknown column(s) {', '.join(unknown)}: use "
                               f"{', '.join(MANIFEST_COLUMNS)}")
        if not row.get("audio"):
            raise FacegenError(f"manifest {path}, row {n}: no audio file given")
        audio = base / row["audio"]
        text = row.get("text") or None
        if row.get("text_file"):
            try:
                text = (base / row["text_file"]).read_text(encoding="utf-8")
            except (OSError, UnicodeDecodeError) as exc:
                raise FacegenError(f"manifest {path}, row {n}: cannot read {row['text_file']} ({exc})") from exc
        alignment = base / row["alignment"] if row.get("alignment") else None
        if text and alignment:
            raise FacegenError(f"manifest {path}, row {n}: give text or alignment, not both")
        output = row.get("output") or Path(row["audio"]).with_suffix(default_ext).name
        try:
            format_module(output)
        except FacegenError as exc:
            raise FacegenError(f"manifest {path}, row {n}: {exc}") from None
        jobs.append(Job(audio=audio, output=out_base / output, text=text, alignment=alignment,
                        speaker=row.get("speaker") or None))
    if not jobs:
        raise FacegenError(f"manifest {path} lists no clips")
    return jobs


def animate_many(jobs: Iterable[Job], *, bundle=None, device: str = "auto", text_model: str | None = None,
                 batch_size: int = 16, window: int = 64, say: Say = silent,
                 warn: Say = silent) -> Iterator[tuple[Job, object]]:
    """Animate many clips with the model and text backend loaded once: yields (job, Animation) or
    (job, FacegenError) for every job, in the input order within windows of `window` jobs.

    Within a window, clips are sorted by length and run through the decoder BiLSTMs `batch_size` at a
    time (packed: each clip's result equals its own single run). The frames of each Animation are a
    FrameStream (computed when the writer reads them).
    """
    from facegen.animate import finish_animation, prepare_clip
    from facegen.bundle import Bundle, load_bundle

    if not isinstance(bundle, Bundle):
        bundle = load_bundle(bundle)
    dev = select_device(device, warn)
    pending: list[Job] = []

    def run(window_jobs: list[Job]) -> Iterator[tuple[Job, object]]:
        prepared: dict[int, object] = {}
        for i, job in enumerate(window_jobs):
            try:
                prepared[i] = prepare_clip(job.audio, bundle=bundle, text=job.text, alignment=job.alignment,
                                           no_text=job.no_text, speaker=job.speaker, text_model=text_model,
                                           warn=warn)
            except FacegenError as exc:
                prepared[i] = exc
        ready = sorted((i for i, c in prepared.items() if not isinstance(c, FacegenError)),
                       key=lambda i: prepared[i].num_frames)
        for b in range(0, len(ready), batch_size):
            ids = ready[b:b + batch_size]
            clips = [prepared[i] for i in ids]
            states = batch_decoder_states(bundle, [(c.mel, c.text_features, c.speaker) for c in clips],
                                          device=dev)
            for i, clip, st in zip(ids, clips, states, strict=True):
                prepared[i] = finish_animation(bundle, clip, frame_stream(bundle, st, clip.mesh.vertices))
        for i, job in enumerate(window_jobs):
            yield job, prepared[i]

    for job in jobs:
        pending.append(job)
        if len(pending) >= window:
            yield from run(pending)
            pending = []
    if pending:
        yield from run(pending)


def run_batch(jobs: Sequence[Job], *, bundle=None, device: str = "auto", text_model: str | None = None,
              batch_size: int = 16, say: Say = silent, warn: Say = silent) -> list[JobResult]:
    """Animate every job and write its output (format from the extension); a clip that fails is
    reported in its JobResult and the others go on. Returns one JobResult per job, in order."""
    from facegen.exchange import write_animation

    results = []
    start = time.perf_counter()
    for n, (job, anim) in enumerate(animate_many(jobs, bundle=bundle, device=device, text_model=text_model,
                                                 batch_size=batch_size, warn=warn), 1):
        t0 = time.perf_counter()
        if isinstance(anim, FacegenError):
            results.append(JobResult(job, error=str(anim)))
        else:
            try:
                job.output.parent.mkdir(parents=True, exist_ok=True)
                files = write_animation(anim, job.output, audio_source=job.audio)
                results.append(JobResult(job, files=files, frames=anim.num_frames,
                                         seconds=time.perf_counter() - t0))
            except FacegenError as exc:
                results.append(JobResult(job, error=str(exc)))
        r = results[-1]
        say(f"[{n}/{len(jobs)}] {job.output}: " + (f"{r.frames} frames" if r.ok else f"error: {r.error}")
            + f" ({time.perf_counter() - start:.1f} s)")
    return results
