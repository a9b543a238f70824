"""Benchmark: one training epoch over a BIWI-sized split, on the CPU, with facegen's own training loop.

The split is the paper's: 192 sequences of ~4.7 s (here 90-145 frames at 25 fps, mean ~117), 23,370
vertices, the full paper-sized network (tensor fusion of audio and 384-d text features), Adam, one
sequence per step. Features are precomputed (random mel and text features, as the feature cache would
give them); targets are read every step from memory-mapped float32 .npy files on disk, as in training
(16 distinct files of ~40 MB, shared by the 192 sequences). The code timed is facegen.train's
train_epoch with the same settings as `facegen train` (deterministic algorithms, flushed denormals,
fused Adam).

    python benchmarks/bench_train.py                 # 1 warm-up step, then 1 timed epoch on 2 threads
    python benchmarks/bench_train.py --epochs 2 --threads 1 --modalities audio
    python benchmarks/bench_train.py --pca 64 --sequences 2000
        # the shipped model's setting: <= 3 min / epoch

Prints seconds per epoch and sequences per second (target: <= 60 s per epoch on 2 CPU cores), the CPU
time the epoch used, the time to write one checkpoint, and the load average before and after: on a
machine shared with other jobs the wall times are not comparable (with --threads 1 the CPU time is close
to what the epoch takes on one idle core). OpenMP threads wait passively (OMP_WAIT_POLICY=PASSIVE unless
set): with spinning threads, a 2-thread run on 2 busy cores was 3-5x slower than a 1-thread run.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # before torch loads its OpenMP runtime

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from facegen.datasets.biwi import Item, Sequence
from facegen.model import FaceModel, ModelConfig
from facegen.phonetics import PHONES
from facegen.train import CHECKPOINT, epoch_order, save_checkpoint, torch_settings, train_epoch
from facegen.train_data import Batch
from facegen.train_pca import CoefficientLoss

BIWI_VERTICES = 23370


def make_items(folder: Path, sequences: int, vertices: int, text_dim: int, files: int,
               seed: int) -> list[Item]:
    rng = np.random.default_rng(seed)
    lengths = rng.integers(90, 146, size=sequences)
    template = rng.normal(0, 0.05, size=(vertices, 3)).astype(np.float32)
    paths = []
    for i in range(files):
        path = folder / f"seq{i:02d}.npy"
        motion = template.reshape(1, -1) + rng.normal(0, 0.002, size=(145, vertices * 3)).astype(np.float32)
        np.save(path, motion)
        paths.append(path)
    items = []
    for i, t in enumerate(lengths):
        seq = Sequence(f"S{i % 6}_e{i:03d}", f"S{i % 6}", folder / "none.wav", paths[i % files])
        mel = rng.normal(-40, 15, size=(t, 128)).astype(np.float32)
        text = rng.normal(0, 1, size=(t, text_dim)).astype(np.float32)
        items.append(Item(seq, mel, text, int(t), template))
    return items


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sequences", type=int, default=192)
    ap.add_argument("--vertices", type=int, default=BIWI_VERTICES)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--epochs", type=int, default=1)
    ap.add_argument("--modalities", default="both", choices=("both", "audio", "text"))
    ap.add_argument("--fusion", default="tensor", choices=("tensor", "concat"))
    ap.add_argument("--text-dim", type=int, default=384)
    ap.add_argument("--files", type=int, default=16, help="distinct target .npy files on disk")
    ap.add_argument("--pca", type=int, default=0, metavar="K",
                    help="train the output layer in a K-dimensional basis (facegen train --output-layer pca "
                         "--basis K), with the shipped model's loss terms (lip 1, velocity 0.5, upper face "
                         "8) and the phone stream; targets are coefficients, as in training")
    args = ap.parse_args()

    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="facegen-bench-") as tmp:
        t0 = time.perf_counter()
        items = make_items(Path(tmp), args.sequences, args.vertices, args.text_dim, args.files, seed=0)
        frames = sum(it.num_frames for it in items)
        print(f"data: {len(items)} sequences, {frames} frames (mean {frames / len(items) / 25:.2f} s), "
              f"{args.vertices} vertices; made in {time.perf_counter() - t0:.1f} s")
        with torch_settings(args.threads):
            torch.manual_seed(0)
            cfg = ModelConfig(num_vertices=args.vertices, num_speakers=6, text_dim=args.text_dim,
                              modalities=args.modalities, fusion=args.fusion, output_basis=args.pca,
                              n_phones=len(PHONES) if args.pca else 0)
            model = FaceModel(cfg)
            coefficient_loss = None
            if args.pca:
                rng = np.random.default_rng(1)
                basis = np.linalg.qr(rng.normal(size=(3 * args.vertices, args.pca)))[0].astype(np.float32)
                model.set_basis(torch.from_numpy(basis), torch.zeros(3 * args.vertices))
                lips, upper = np.arange(0, args.vertices, 60), np.arange(7, args.vertices, 5)
                coefficient_loss = CoefficientLoss(basis, lips, 1.0, 0.5, upper=upper, upper_weight=8.0)
            print(f"model: {args.modalities} ({args.fusion}), {sum(p.numel() for p in model.parameters()):,} "
                  f"parameters; torch {torch.__version__}, {torch.get_num_threads()} threads")
            optimizer = torch.optim.Adam(model.parameters(), lr=1e-4, fused=True)
            device = torch.device("cpu")
            batches = [Batch(it, i % 6, 6, device) for i, it in enumerate(items)]
            for b in batches if args.pca else []:
                rng = np.random.default_rng(len(b.item.mel))
                b.coefficients = torch.from_numpy(rng.normal(0, 0.01, (b.item.num_frames,
                                                                       args.pca)).astype(np.float32))
                b.phones = torch.nn.functional.one_hot(torch.from_numpy(rng.integers(0, len(PHONES),
                                                                                     b.item.num_frames)),
                                                       len(PHONES)).float()[None]
            train_epoch(model, optimizer, batches, [0, 1], coefficient_loss=coefficient_loss)  # warm-up
            times = []
            for epoch in range(args.epochs):
                t0, c0 = time.perf_counter(), time.process_time()
                loss = train_epoch(model, optimizer, batches, epoch_order(0, epoch, len(batches)),
                                   coefficient_loss=coefficient_loss)
                times.append(time.perf_counter() - t0)
                cpu = time.process_time() - c0
                print(f"epoch {epoch + 1}: {times[-1]:.1f} s, {len(batches) / times[-1]:.2f} sequences/s, "
                      f"{frames / times[-1]:.0f} frames/s, loss {loss:.3e}; CPU time {cpu:.1f} s "
                      f"({cpu / times[-1]:.2f} cores busy on average)")
            t0 = time.perf_counter()
            best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
            save_checkpoint(Path(tmp) / CHECKPOINT, model, best_state, optimizer, {"epoch": args.epochs})
            print(f"checkpoint: {time.perf_counter() - t0:.1f} s "
                  f"({(Path(tmp) / CHECKPOINT).stat().st_size / 1e6:.0f} MB)")
        best = min(times)
        load_after = os.getloadavg()
        print(f"load average (1 min) {load_before[0]:.1f} before, {load_after[0]:.1f} after, on "
              f"{os.cpu_count()} CPUs; OMP_WAIT_POLICY={os.environ.get('OMP_WAIT_POLICY')}")
        target = 180 * len(batches) / 2000 if args.pca else 60  # pca: <= 3 min per 2,000 sequences
        print(f"seconds/epoch {best:.1f}  sequences/s {len(batches) / best:.2f}  "
              f"({'within' if best <= target else 'OVER'} the {target:.0f} s target)")


if __name__ == "__main__":
    main()
