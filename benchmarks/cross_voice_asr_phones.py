"""Benchmark: the phone-stream model on the held-out synthesiser with the phones a user gets — pocketsphinx's
phone alignment of the transcript on the (augmented) test audio — instead of the synthesiser's own phone
timings that `facegen evaluate` reads from the corpus.

    python benchmarks/cross_voice_asr_phones.py CORPUS BUNDLE [--test-sentences 11993-12208] [--limit N]
"""

from __future__ import annotations

import argparse
import json

import numpy as np


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("corpus")
    parser.add_argument("bundle")
    parser.add_argument("--test-sentences", default="11993-12208")
    parser.add_argument("--limit", type=int)
    args = parser.parse_args(argv)

    from facegen.align import align_phones
    from facegen.audio import load_audio
    from facegen.datasets.splits import Splits
    from facegen.errors import FacegenError
    from facegen.evaluate import _lipsync_geometry, _lipsync_row, pool, prepare, sequence_metrics
    from facegen.lipsync import format_lipsync, pool_lipsync
    from facegen.phonetics import phone_frames
    from facegen.runtime import SILENT

    splits = Splits(train_subjects=("F2", "F3", "F4", "M3", "M4", "M5"), test_subjects=(),
                    train_sentences="49-1776", val_sentences="1777-1992", test_sentences=args.test_sentences)
    run = prepare(args.bundle, args.corpus, "test-a", splits=splits, reporter=SILENT)
    geometry = _lipsync_geometry(run.bundle)
    fps = run.bundle.features.fps
    rows, lip_rows, failed = [], [], 0
    for item in run.items[: args.limit]:
        samples, sr = load_audio(item.seq.wav)
        try:
            _, phones = align_phones(samples, sr, item.seq.text.read_text())
        except FacegenError:
            failed += 1  # a user would get the recognised words' phones or silence; counted apart
            continue
        item.phones = phone_frames(phones, item.num_frames, fps)
        gt = item.vertices().reshape(item.num_frames, -1, 3)
        pred = item.template[None] + run.predict(item, run.conditions(item)[0])[0]
        rows.append(sequence_metrics(pred, gt, item.template, run.lips, run.upper))
        lip_rows.append(_lipsync_row(item, pred, gt, geometry, fps))
    metrics, lipsync = pool(rows), pool_lipsync(lip_rows)
    print(f"{len(rows)} sequences ({failed} whose transcript pocketsphinx could not align were left out); "
          f"LVE {metrics['lve']:.3e}, upper-face error {metrics['upper_error']:.3e}")
    print(format_lipsync(lipsync))
    print(json.dumps({"sequences": len(rows), "failed": failed, "lve": metrics["lve"],
                      "upper_error": metrics["upper_error"],
                      "lipsync": {k: v for k, v in lipsync.items() if not isinstance(v, np.generic)}}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
