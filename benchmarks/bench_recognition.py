"""Recognition without a transcript, and how sure it is: on a real recorded prompt library (Asterisk's
English prompts, 8 kHz telephone speech; Debian: `apt-get install asterisk-core-sounds-en-wav
asterisk-core-sounds-en`), each line is recognised (facegen.recognition.hear) and its words compared with
the recording script's (a longest-matching-blocks alignment of the two word sequences): the share of
recognised words that are right, and at each confidence bound the share kept, their precision, the right
words lost and the wrong ones kept. The shipped bound is recognition.SURE: words below it do not drive the
upper face.

    python benchmarks/bench_recognition.py --half odd --limit 70   # what SURE was chosen on
    python benchmarks/bench_recognition.py --half even --limit 70  # the check
"""

from __future__ import annotations

import argparse
import difflib
import json
import re
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_mismatch import SCRIPT, SOUNDS, library, spoken_words

BOUNDS = (0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)


def right_words(heard: list[str], said: list[str]) -> list[bool]:
    """Which recognised words are the script's (in order: the matching blocks of the two sequences)."""
    blocks = difflib.SequenceMatcher(a=heard, b=said, autojunk=False).get_matching_blocks()
    right = [False] * len(heard)
    for block in blocks:
        for k in range(block.size):
            right[block.a + k] = True
    return right


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--half", choices=("odd", "even", "all"), default="odd")
    ap.add_argument("--limit", type=int, default=70, help="at most this many lines (0: all)")
    ap.add_argument("--json", type=Path, help="write every line's words, confidences and verdicts here")
    args = ap.parse_args(argv)
    if not SCRIPT.is_file():
        print(f"{SCRIPT} is missing: apt-get install asterisk-core-sounds-en-wav asterisk-core-sounds-en",
              file=sys.stderr)
        return 2
    from facegen.audio import load_audio
    from facegen.recognition import SURE, hear

    lines = library(SOUNDS, SCRIPT)
    lines = lines if args.half == "all" else lines[0::2] if args.half == "odd" else lines[1::2]
    lines = lines[:args.limit] if args.limit else lines
    rows, seconds, audio = [], 0.0, 0.0
    for name, wav, script in lines:
        samples, rate = load_audio(wav)
        if len(samples) / rate < 0.5:
            continue
        start = time.perf_counter()
        found = hear(samples, rate)
        seconds += time.perf_counter() - start
        audio += len(samples) / rate
        heard = [w.text.lower() for w in found.words]
        said = [re.sub(r"[^a-z']", "", w.lower()) for w in spoken_words(script)]
        rows.append({"line": name, "script": script, "heard": heard, "confidences": found.confidences,
                     "right": right_words(heard, said)})
    right = np.array([r for row in rows for r in row["right"]], bool)
    conf = np.array([c for row in rows for c in row["confidences"]])
    print(f"{len(rows)} lines ({args.half} half), {len(right)} recognised words, {right.mean():.0%} "
          f"right; recognition at {audio / max(seconds, 1e-9):.1f}x real time\n")
    print("| bound | words kept | right among kept | right words lost | wrong words kept |")
    print("|---|---|---|---|---|")
    for bound in BOUNDS:
        keep = conf >= bound
        mark = " (shipped)" if bound == SURE else ""
        print(f"| {bound:.1f}{mark} | {keep.mean():.0%} | {right[keep].mean() if keep.any() else 0:.0%} | "
              f"{int((right & ~keep).sum())}/{int(right.sum())} | "
              f"{int((~right & keep).sum())}/{int((~right).sum())} |")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
