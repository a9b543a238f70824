"""Benchmark: a face that is alive, on recorded speech (issue 24) — blink rate, durations, share at pauses,
irregularity and how far the ARKit fit's eyeBlink closes; saccades per 4 s, their amplitudes and the share of
planning pauses (>= 0.5 s before speech) that end in a look away; the head's RMS angle in speech, its
largest angle and frame-to-frame step, its speed in speech over silence — on what `facegen animate` makes.

The recordings are about a minute each of Asterisk's recorded prompts with their script, in a shuffled loop
with pauses (bench_long.make_long; Debian: asterisk-core-sounds-en-wav), else espeak sentences. Blinks are
found in the fitted eyeBlinkLeft (frames above 0.1); pauses are the quiet audio of 0.2 s or more
(facegen.blinks.quiet_spans).

Targets: 10-30 blinks a minute during speech, each 100-400 ms, >= 60 % within 0.4 s of a pause, eyeBlink
>= 0.8 at the shut frame, intervals' coefficient of variation >= 0.3; >= 1 saccade per 4 s of speech,
amplitudes 1-15 degrees; head RMS 1-4 degrees in speech, never beyond 10, no step over 1.5, speed in
speech >= 2x silence.

    python benchmarks/bench_liveliness.py [--clips 3] [--seconds 60]
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
    pauses = quiet_spans(samples, rate)
    moves, here = anim.metadata["saccades"], (0.0, 0.0)
    amplitudes = []
    for _, _, yaw, pitch in moves:
        amplitudes.append(float(np.hypot(yaw - here[0], pitch - here[1])))
        here = (yaw, pitch)
    planning = [b for a, b in pauses if b - a >= 0.5 and 0 < b < len(samples) / rate - 0.3]
    averted = [b for b in planning if any(b - 0.3 <= s <= b and abs(y) >= 5.9 for s, _, y, _ in moves)]
    frames = len(anim.head)
    t = np.arange(frames) / anim.fps
    speaking = np.ones(frames, bool)
    for a, b in pauses:
        speaking[(t >= a) & (t < b)] = False
    speed = np.linalg.norm(np.diff(anim.head, axis=0), axis=1)
    head = {"head_rms": float(np.sqrt((anim.head[speaking] ** 2).sum(1).mean())),
            "head_max": float(np.abs(anim.head).max()),
            "head_step": float(np.abs(np.diff(anim.head, axis=0)).max()),
            "head_speed_ratio": float(speed[speaking[1:]].mean() / speed[~speaking[1:]].mean())}
    return {**head, "seconds": len(samples) / rate, "saccades_per_4s": 4 * len(moves) / (len(samples) / rate),
            "amplitudes": amplitudes, "averted": len(averted) / max(len(planning), 1),
            "blinks": stats.count, "per_minute": stats.per_minute,
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
          "interval CV | eyeBlink at the shut frame (least) | saccades per 4 s | amplitude deg min / "
          "median / max | planning pauses with a look away | head RMS deg in speech | head max deg | head "
          "largest step deg | head speed speech / silence |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as folder:
        for seed in range(args.clips):
            wav = Path(folder) / f"speech{seed}.wav"
            text = make_long(wav, args.seconds, seed=seed).read_text()
            m = measure(wav, text)
            d = m["durations_ms"]
            print(f"| {seed} | {m['seconds']:.1f} | {m['blinks']} | {m['per_minute']:.1f} | {min(d):.0f} / "
                  f"{np.median(d):.0f} / {max(d):.0f} | {m['near_pause']:.0%} | {m['interval_cv']:.2f} | "
                  f"{m['least_shut']:.2f} | {m['saccades_per_4s']:.1f} | {min(m['amplitudes']):.1f} / "
                  f"{np.median(m['amplitudes']):.1f} / {max(m['amplitudes']):.1f} | {m['averted']:.0%} | "
                  f"{m['head_rms']:.2f} | {m['head_max']:.2f} | {m['head_step']:.2f} | "
                  f"{m['head_speed_ratio']:.1f} |", flush=True)


if __name__ == "__main__":
    main()
