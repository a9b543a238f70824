"""Other frame rates: does `--fps` keep the lips? (issue 22: p/b/m closure at 24 and 30 fps >= 95 % of 25
fps's, frame counts exact.)

Sentences rich in p, b and m, spoken by the installed synthetic voices (Flite, Festival, espeak-ng in turn),
are animated once per frame rate with the built-in model (the transcript force-aligned, as for recorded
lines). For each rate: the frame count against round(duration x fps), and the bilabial closure rate — the
share of the p/b/m phones (their midpoints, from the same forced alignment's phones) at which the lip aperture
is under lipsync.CLOSED_MM — with the median aperture at those midpoints.

    python benchmarks/bench_fps.py [--rates 24,25,30,60] [--clips 6]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

import numpy as np

SENTENCES = (
    "Bob probably paid a big bill for the maple boat.",
    "My mom made a plum pie by the pub in May.",
    "Please bring me both pumpkins, maybe a bamboo broom.",
    "Pam bumped the bumper of a blue bus by the mall.",
    "A poem about a mapped map may baffle Ben and Bess.",
    "Big bombs, pop music and maple pudding made me beam.",
    "The mob bought plump apples from a humble embassy.",
    "Maybe Bill will bring the bubble bath to my apartment.",
)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rates", default="24,25,30,60")
    ap.add_argument("--clips", type=int, default=6)
    args = ap.parse_args(argv)
    rates = [float(r) for r in args.rates.split(",")]

    from facegen.align import align_phones
    from facegen.animator import Animator
    from facegen.audio import num_frames, write_wav
    from facegen.lipsync import CLOSED_MM, aperture, bilabial_midpoints
    from facegen.synth.voices import available_voices, synthesize

    voices = available_voices()
    by_engine = {e: [v for v in voices if v.engine == e] for e in ("flite", "festival", "espeak")}
    order = [v for group in zip(*[g for g in by_engine.values() if g], strict=False) for v in group]
    animator = Animator()
    closed: dict[float, list[float]] = {r: [] for r in rates}
    gaps: dict[float, list[float]] = {r: [] for r in rates}
    exact = {r: 0 for r in rates}
    with tempfile.TemporaryDirectory() as tmp:
        for i, text in enumerate(SENTENCES[:args.clips]):
            voice = order[i % len(order)]
            utt = synthesize(text, voice)
            wav = Path(tmp) / f"line{i}.wav"
            write_wav(utt.audio, utt.sample_rate, wav)
            _, phones = align_phones(utt.audio, utt.sample_rate, text)
            line = []
            for rate in rates:
                anim = animator.animate(wav, text=text, fps=rate)
                exact[rate] += anim.num_frames == num_frames(utt.duration, rate)
                mids = bilabial_midpoints(phones, rate, alphabet="cmu")
                mids = mids[mids < anim.num_frames]
                mm = aperture(anim.vertices, anim.mesh) * 10  # cm -> mm
                closed[rate] += list((mm[mids] < CLOSED_MM).astype(float))
                gaps[rate] += list(mm[mids])
                line.append(f"{rate:g} fps {np.mean(mm[mids] < CLOSED_MM):.0%}")
            print(f"  {voice.name:26s} {len(mids):2d} p/b/m  " + ", ".join(line), flush=True)
    base = 25.0 if 25.0 in rates else rates[0]
    print(f"\n{'fps':>5s}  {'frames exact':>12s}  {'p/b/m closed':>12s}  {'vs 25 fps':>9s}  "
          f"{'median aperture (mm)':>20s}")
    for rate in rates:
        share = float(np.mean(closed[rate]))
        versus = share / max(float(np.mean(closed[base])), 1e-9)
        print(f"{rate:5g}  {exact[rate]:>7d}/{args.clips:<4d}  {share:12.1%}  {versus:9.1%}  "
              f"{statistics.median(gaps[rate]):20.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
