"""Calibration of the aligner's mismatch check (facegen.transcript_match.judge and its bound on the
median word score gap, facegen.transcript_match.word_gap_bound).

The 20 sentences of benchmarks/bench_batch.py (Flite, Festival and espeak-ng voices in turn) are aligned
against their own transcript and against the next sentence's, clean and with pink, white and babble noise at
10 and 5 dB SNR (7 conditions: 140 matching and 140 wrong runs). For each run it records whether an alignment
exists, the share of loud frames outside words and the median word's score gap; it prints the gaps of the runs
that align and, for a few bounds around the shipped one, how many matching and wrong transcripts would be
refused end to end (no alignment, too much unexplained speech, or a gap above the bound).

    python benchmarks/calibrate_mismatch.py [--clips 20]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
CONDITIONS = [("clean", None)] + [(f"{kind} {snr} dB", (kind, snr)) for snr in (10, 5)
                                  for kind in ("pink", "white", "babble")]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clips", type=int, default=20)
    parser.add_argument("--json", type=Path, help="write every run's scores (and the clip's SNR) here")
    args = parser.parse_args(argv)

    import csv

    from bench_batch import make_clips
    from bench_mismatch import snr_db

    from facegen import align, transcript_match
    from facegen.audio import load_audio
    from facegen.errors import FacegenError
    from facegen.synth.augment import add_noise, make_noise
    from facegen.transcript_match import NOISY_WORD_GAP

    folder = Path(tempfile.mkdtemp(prefix="facegen-calibrate-"))
    make_clips(folder, args.clips)
    with open(folder / "lines.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    seen: list[tuple[float, float]] = []
    per_word: list[list[float]] = []
    check = align.judge

    def recording(loud, words, gaps, free, snr_db=0.0):
        seen.append(transcript_match.match_scores(loud, words, gaps, free))
        per_word.append([round(float(gaps[f:l + 1].mean() - free[f:l + 1].mean()), 2) for _, f, l in words])
        return check(loud, words, gaps, free, snr_db)

    align.judge = recording
    results = {"matching": [], "wrong": []}  # (condition, None = no alignment | (unexplained, gap), error)
    dump = []
    for i, row in enumerate(rows):
        audio, rate = load_audio(folder / row["audio"])
        for name, noise in CONDITIONS:
            rng = np.random.default_rng(1000 * i + CONDITIONS.index((name, noise)))
            heard = audio if noise is None else add_noise(audio, noise[1], make_noise(audio, noise[0], rng))
            for kind, text in (("matching", row["text"]), ("wrong", rows[(i + 1) % len(rows)]["text"])):
                seen.clear()
                per_word.clear()
                try:
                    align.align(heard, rate, text)
                    error = None
                except FacegenError as exc:
                    error = str(exc)
                results[kind].append((name, seen[0] if seen else None, error))
                dump.append({"kind": kind, "condition": name, "line": row["audio"],
                             "snr_db": snr_db(heard, rate),
                             "unexplained": seen[0][0] if seen else float("nan"),
                             "gap": seen[0][1] if seen else float("nan"),
                             "word_gaps": per_word[0] if per_word else [], "why": error or "",
                             "outcome": "refused" if error else "accepted"})
    align.judge = check
    if args.json:
        import json

        args.json.write_text(json.dumps(dump, indent=1))

    for kind, runs in results.items():
        gaps = [r[1][1] for r in runs if r[1] is not None and r[1][0] <= transcript_match.MAX_UNEXPLAINED]
        none = sum(r[1] is None for r in runs)
        outside = sum(r[1] is not None and r[1][0] > transcript_match.MAX_UNEXPLAINED for r in runs)
        print(f"{kind}: {len(runs)} runs; no alignment {none}, too much speech outside words {outside}; "
              f"score gaps of the rest {min(gaps):.0f} to {max(gaps):.0f} (median {np.median(gaps):.0f})")
        refused = [r for r in runs if r[2] is not None]
        print(f"  refused with the shipped bounds: {len(refused)}/{len(runs)}"
              + "".join(f"\n    {name}: {error[:110]}" for name, _, error in refused if kind == "matching"))
    print("refused by condition (matching, wrong): " + ", ".join(
        f"{name} {sum(r[2] is not None for r in results['matching'] if r[0] == name)}/"
        f"{sum(r[2] is not None for r in results['wrong'] if r[0] == name)}" for name, _ in CONDITIONS))
    print("bound  matching refused  wrong refused")
    for bound in range(int(NOISY_WORD_GAP) - 6, int(NOISY_WORD_GAP) + 7, 2):
        most = transcript_match.MAX_UNEXPLAINED
        counts = [sum(r[1] is None or r[1][0] > most or r[1][1] > bound for r in runs)
                  for runs in results.values()]
        print(f"{bound:5d}  {counts[0]:8d}/{len(results['matching'])}  "
              f"{counts[1]:8d}/{len(results['wrong'])}")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    raise SystemExit(main())
