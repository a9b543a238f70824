"""The mismatch check on recorded speech: correct scripts refused, wrong ones accepted (issue 22).

The recorded library is Asterisk's English prompts (a professional voice, 8 kHz telephone band, ~550 lines of
0.4-73 s with their recording script; Debian: `apt-get install asterisk-core-sounds-en-wav`), read with its
script file as a user's CI would: every line animates with its script or is refused. `--language fr|es|it|ru`
reads Asterisk's Canadian French, Mexican Spanish, Italian or Russian prompts instead (`apt-get install
asterisk-core-sounds-fr-wav asterisk-core-sounds-fr`, and so on; recorded speech kept for the independent
check of issue 25: never tuned on) and aligns them with `--language`. Cases per line:

- correct: the line with its own script (stage directions such as "[beep]" or "(note: ...)" included, as
  scripts carry them); a script that is only a direction is counted apart (no words to align);
- shuffled: the line with the script of another line of >= 5 words (a swapped row);
- near miss: the script with one content word replaced by another word of the library (a typo-sized
  difference the check may let through; reported, not a target).

Each case runs `facegen.align.align` (the forced alignment every `animate` with a transcript runs; the model
and the writer do not change the outcome) and records accepted/refused with the reason and the check's two
scores. `--half odd` (the default) uses the lines at odd positions of the sorted list for development; `even`
is kept for the held-out figure; `all` both.

    python benchmarks/bench_mismatch.py [--language en|fr|es|it|ru] [--half odd|even|all] [--limit N]
                                        [--json out.json]
"""

from __future__ import annotations

import argparse
import gzip
import json
import sys
import time
from pathlib import Path

import numpy as np

SOUNDS = Path("/usr/share/asterisk/sounds/{}")
SCRIPT = Path("/usr/share/doc/asterisk-core-sounds-{0}/core-sounds-{0}.txt.gz")


def library(sounds: Path, script: Path) -> list[tuple[str, Path, str]]:
    """(name, wav, script line) for every line of the script whose recording exists, sorted by name."""
    opener = gzip.open if script.suffix == ".gz" else open
    lines = []
    with opener(script, "rt", encoding="utf-8", errors="replace") as f:
        for row in f:
            if row.startswith(";") or ":" not in row:
                continue
            name, _, text = row.partition(":")
            wav = sounds / f"{name.strip()}.wav"
            if wav.is_file() and text.strip():
                lines.append((name.strip(), wav, text.strip()))
    return sorted(lines)


def spoken_words(text: str) -> list[str]:
    """The words of a script line said aloud (its stage directions left out, as facegen does)."""
    from facegen.words import split_directions

    return split_directions(text)[0].split()


def snr_db(samples: np.ndarray, rate: int) -> float:
    """How far the loud 10 ms frames stand above the quiet ones (90th vs 10th percentile of frame energy)."""
    hop = max(1, rate // 100)
    frames = samples[:len(samples) // hop * hop].reshape(-1, hop).astype(np.float64)
    energy = (frames ** 2).mean(1) + 1e-12
    return float(10 * np.log10(np.percentile(energy, 90) / np.percentile(energy, 10)))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--language", default="en", help="the library's language: en, fr, es, it, ru")
    ap.add_argument("--align-as", metavar="CODE",
                    help="align in this language instead (e.g. English prompts as en-us-nyc: the espeak-ng "
                         "path every other language takes, on recordings not kept back)")
    ap.add_argument("--sounds", type=Path, help="the recordings' folder (default: Asterisk's)")
    ap.add_argument("--script", type=Path, help="the script file (default: Asterisk's)")
    ap.add_argument("--half", choices=("odd", "even", "all"), default="odd")
    ap.add_argument("--limit", type=int, default=0, help="at most this many lines (0: all)")
    ap.add_argument("--json", type=Path, help="write every case's outcome and scores here")
    ap.add_argument("--batch", type=Path, metavar="OUT",
                    help="also run the swapped rows through `facegen batch --on-mismatch warn` into OUT "
                         "(ARKit .json outputs) and count the lines its report.json flags")
    args = ap.parse_args(argv)
    args.sounds = args.sounds or Path(str(SOUNDS).format(args.language))
    args.script = args.script or Path(str(SCRIPT).format(args.language))
    if not args.script.is_file():
        print(f"{args.script} is missing: apt-get install asterisk-core-sounds-{args.language}-wav "
              f"asterisk-core-sounds-{args.language}", file=sys.stderr)
        return 2

    from facegen import align, transcript_match
    from facegen.audio import load_audio
    from facegen.errors import FacegenError

    lines = library(args.sounds, args.script)
    lines = lines[1::2] if args.half == "odd" else lines[0::2] if args.half == "even" else lines
    if args.limit:
        lines = lines[:args.limit]
    rng = np.random.default_rng(0)
    long_scripts = [text for _, _, text in lines if len(spoken_words(text)) >= 5]
    vocabulary = sorted({w.strip(".,!?;:\"'").lower() for t in long_scripts for w in spoken_words(t)
                         if len(w) > 3 and w.isalpha()})

    scores: list[tuple[float, float]] = []
    check = align.judge

    per_word: list[list[float]] = []

    def recording(loud, words, gaps, free, snr_db=0.0, **kw):
        scores.append(transcript_match.match_scores(loud, words, gaps, free))
        per_word.append([round(float(gaps[f:l + 1].mean() - free[f:l + 1].mean()), 2) for _, f, l in words])
        return check(loud, words, gaps, free, snr_db, **kw)

    align.judge = recording
    cases = []

    def run(kind: str, name: str, samples, rate, text: str) -> None:
        scores.clear()
        per_word.clear()
        start = time.perf_counter()
        try:
            align.align(samples, rate, text, language=args.align_as or args.language)
            outcome, why = "accepted", ""
        except FacegenError as exc:
            outcome, why = "refused", str(exc)
        seconds = time.perf_counter() - start
        unexplained, gap = scores[-1] if scores else (float("nan"), float("nan"))
        cases.append({"kind": kind, "line": name, "text": text, "outcome": outcome, "why": why[:160],
                      "unexplained": unexplained, "gap": gap, "word_gaps": per_word[-1] if per_word else [],
                      "snr_db": round(snr_db(samples, rate), 1), "seconds": round(seconds, 3),
                      "duration": round(len(samples) / rate, 2)})

    try:
        for i, (name, wav, text) in enumerate(lines):
            samples, rate = load_audio(wav)
            kind = "direction only" if not spoken_words(text) else "correct"
            run(kind, name, samples, rate, text)
            if len(spoken_words(text)) >= 5:
                others = [t for t in long_scripts if t != text]
                run("shuffled", name, samples, rate, others[int(rng.integers(len(others)))])
                words = text.split()
                content = [k for k, w in enumerate(words) if len(w.strip(".,!?;:")) > 3 and w.isalpha()]
                if content:
                    k = content[int(rng.integers(len(content)))]
                    words[k] = vocabulary[int(rng.integers(len(vocabulary)))]
                    run("near miss", name, samples, rate, " ".join(words))
            if (i + 1) % 25 == 0:
                print(f"  {i + 1}/{len(lines)} lines", file=sys.stderr, flush=True)
    finally:
        align.judge = check

    print(f"{len(lines)} lines ({args.half} half of {args.sounds})\n")
    print("| case | runs | accepted | refused |\n|---|---|---|---|")
    for kind in ("correct", "direction only", "shuffled", "near miss"):
        got = [c for c in cases if c["kind"] == kind]
        if got:
            ok = sum(c["outcome"] == "accepted" for c in got)
            no = len(got) - ok
            print(f"| {kind} | {len(got)} | {ok} ({ok / len(got):.1%}) | {no} ({no / len(got):.1%}) |")
    print("\ncorrect scripts refused:")
    for c in cases:
        if c["kind"] == "correct" and c["outcome"] == "refused":
            print(f"  {c['line']} ({c['duration']} s) {c['text'][:60]!r}: {c['why'][:110]}")
    print("\nwrong scripts accepted (shuffled):")
    for c in cases:
        if c["kind"] == "shuffled" and c["outcome"] == "accepted":
            print(f"  {c['line']} as {c['text'][:60]!r}: unexplained {c['unexplained']:.2f}, "
                  f"gap {c['gap']:.1f}")
    seconds = [c["seconds"] / max(c["duration"], 1e-3) for c in cases if c["kind"] == "correct"]
    print(f"\nalignment time: {np.median(seconds):.3f} s per second of audio (median of correct lines)")
    if args.json:
        args.json.write_text(json.dumps(cases, indent=1))
    if args.batch:
        swapped_in_batch(args.batch, [c for c in cases if c["kind"] == "shuffled"],
                         {name: wav for name, wav, _ in lines})
    return 0


def swapped_in_batch(out: Path, swapped: list[dict], wavs: dict) -> None:
    """The swapped rows as a batch manifest (each line's recording with another line's script), run with
    on_mismatch "warn": how many its report flags (written with a warning), refuses (no alignment at all) or
    passes unflagged, and the match scores of each group."""
    import csv

    from facegen.batch_run import run_manifest

    out.mkdir(parents=True, exist_ok=True)
    manifest = out.parent / f"{out.name}-swapped.csv"
    with open(manifest, "w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(["audio", "text", "output"])
        for k, case in enumerate(swapped):
            writer.writerow([wavs[case["line"]], case["text"], f"{k:03d}.json"])
    start = time.perf_counter()
    outcome = run_manifest(manifest, out, jobs=2, on_mismatch="warn", force=True)
    items = json.loads(outcome.report_json.read_text())["items"]
    flagged = [i for i in items if i["flagged"]]
    refused = [i for i in items if i["status"] == "error"]
    unflagged = [i for i in items if i["status"] == "passed" and not i["flagged"]]
    print(f"\nbatch --on-mismatch warn over {len(items)} swapped rows ({time.perf_counter() - start:.0f} s): "
          f"{len(flagged)} flagged, {len(refused)} refused (no alignment), {len(unflagged)} passed unflagged "
          f"({(len(flagged) + len(refused)) / max(len(items), 1):.1%} caught)")
    for name, group in (("flagged", flagged), ("unflagged", unflagged)):
        scores = [i["match"]["score"] for i in group if i.get("match")]
        if scores:
            print(f"  match scores {name}: median {np.median(scores):.2f} "
                  f"({min(scores):.2f}-{max(scores):.2f})")


if __name__ == "__main__":
    sys.exit(main())
