"""Benchmark: the small stages whose speed tests used to assert (they are not timed tests any more).

Targets (2 CPU cores): rig.pose of 125 frames (5 s) on the procedural face < 1 s; MiniLM word vectors of a
720-word transcript < 20 s; per-frame text features of 10 minutes (1,500 words, 15,000 frames) < 3 s; the
2,400 generated corpus sentences < 1 s.

    python benchmarks/bench_parts.py [--runs 3]
"""

from __future__ import annotations

import argparse

import numpy as np
from run import best_of  # benchmarks/run.py (this folder is on sys.path when run as a script)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args(argv)

    from facegen.audio import FeatureConfig
    from facegen.face.rig import Rig
    from facegen.face.template import load_template
    from facegen.text import frame_features, load_text_backend

    rig = Rig(load_template())
    weights = np.random.default_rng(0).random((125, len(rig.channels))).astype(np.float32)
    rig.pose(weights[:5])
    rows = [("rig.pose, 125 frames", best_of(lambda: rig.pose(weights), args.runs), 1.0)]

    minilm = load_text_backend("minilm")
    words = ("we walked along the quiet river at dawn while the city slept " * 60).split()
    rows.append(("MiniLM, 720 words", best_of(lambda: minilm.word_vectors(words), args.runs), 20.0))

    rng = np.random.default_rng(1)
    starts = np.sort(rng.uniform(0, 600, 1500))
    from facegen.words import Word

    spans = [Word("w", s, s + d) for s, d in zip(starts, rng.uniform(0.05, 0.6, 1500), strict=True)]
    vectors = rng.normal(size=(1500, 384)).astype(np.float32)
    config = FeatureConfig(fps=25.0)
    rows.append(("text frames, 10 min", best_of(lambda: frame_features(spans, vectors, 15_000, config),
                                                args.runs),
                 3.0))

    from facegen.synth.sentences import generated_sentences

    seeds = iter(range(100, 100 + args.runs))  # a new seed each run: nothing cached
    rows.append(("2,400 sentences", best_of(lambda: generated_sentences(seed=next(seeds)), args.runs), 1.0))

    failed = 0
    for name, seconds, target in rows:
        ok = seconds <= target
        failed += not ok
        print(f"{name:24s} {seconds:7.3f} s  (target <= {target:g} s) {'ok' if ok else 'SLOW'}")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
