"""Benchmark: blinks on recorded speech (issue 24) — rate, durations, share at pauses, irregularity and how
far the ARKit fit's eyeBlink closes, measured on what `facegen animate` writes.

The recordings are about a minute each of Asterisk's recorded prompts with their script, in a shuffled loop
with pauses (bench_long.make_long; Debian: asterisk-core-sounds-en-wav), else espeak sentences. Blinks are
found in the fitted eyeBlinkLeft (frames above 0.1); pauses are the quiet audio of 0.2 s or more
(facegen.blinks.quiet_spans).

Targets: 10-30 blinks a minute during speech, each 100-400 ms, >= 60 % within 0.4 s of a pause, eyeBlink
>= 0.8 at the shut frame, intervals' coefficient of variation >= 0.3.

    python benchmarks/bench_blinks.py [--clips 3] [--seconds 60]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def measure(wav: Path, text: str) -> dict:
    import soundfile as sf

    import facegen
    from facegen.arkit.solve import fit_arkit
    from facegen.blinks import blink_stats, quiet_spans

    anim = facegen.animate(wav, text=text)
    fit = fit_arkit(anim)
    samples, rate = sf.read(wav, dtype="float32")
    lid = fit.weights[:, fit.names.index("eyeBlinkLeft")]
    stats = blink_stats(lid, anim.fps, quiet_spans(samples, rate))
    times = anim.metadata["blinks"]["times"]
    shut = [lid[int(a * anim.fps):int((a + d) * anim.fps) + 2].max() for a, d in times]
    return {"seconds": len(samples) / rate, "blinks": stats.count, "per_minute": stats.per_minute,
            "durations_ms": [1000 * d for d in stats.durations], "near_pause": stats.near_pause,
            "interval_cv": stats.interval_cv, "least_shut": float(min(shut)) if shut else None}


def main() -> None:
    from bench_long import make_long

    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--clips", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=60.0)
    args = parser.parse_args()
    print("| clip | s | blinks | per minute | duration ms min / median / max | within 0.4 s of a pause | "
          "interval CV | eyeBlink at the shut frame (least) |")
    print("|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as folder:
        for seed in range(args.clips):
            wav = Path(folder) / f"speech{seed}.wav"
            text = make_long(wav, args.seconds, seed=seed).read_text()
            m = measure(wav, text)
            d = m["durations_ms"]
            print(f"| {seed} | {m['seconds']:.1f} | {m['blinks']} | {m['per_minute']:.1f} | {min(d):.0f} / "
                  f"{np.median(d):.0f} / {max(d):.0f} | {m['near_pause']:.0%} | {m['interval_cv']:.2f} | "
                  f"{m['least_shut']:.2f} |", flush=True)


if __name__ == "__main__":
    main()
