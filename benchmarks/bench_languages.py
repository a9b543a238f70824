"""Benchmark: forced alignment and the mismatch check in 25 languages (issue 25), on synthetic speech whose
word times are known.

Each sentence of benchmarks/language_sentences.py is spoken by libespeak-ng in its language with one of five
voice variants, rates and pitches (the "recording", 0.4 s of quiet before it, room noise at about 30 dB SNR),
and aligned with `facegen.align.align_checked(..., language=code)`: the word-onset error against the
synthesiser's own times, whether the matching transcript is accepted, and whether the same recording with
another sentence of the language (a swapped row) is refused. The figures per language go to
facegen/language_figures.json (what `facegen languages` prints) and every case to
benchmarks/results/languages.json. Caveat: the pronunciations the aligner is given come from the same
synthesiser as the speech, so these figures are a best case for recorded speech.

A language written without spaces (Chinese, Japanese, Thai: facegen.segmentation) is spoken with a space
between its words (and a Japanese word as its reading in kana: espeak-ng reads no kanji), so the synthesiser
times each word; the aligner is given the transcript as written. `--whole` aligns those transcripts without
splitting them into words (as facegen did before), each word then timed by the start of the run it is in.

    python benchmarks/bench_languages.py [--only fr de ...] [--swaps 1-4] [--whole]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from language_sentences import SENTENCES

REPO = Path(__file__).resolve().parents[1]
VOICES = [("m1", 150, 40), ("f3", 140, 70), ("m3", 175, 50), ("f2", 160, 60), ("m4", 130, 45)]
LEAD = 0.4


def said(text: str, code: str) -> str:
    """`text` as espeak-ng is given it to speak: in a script without spaces, its words (Japanese: their
    readings) with a space between them, punctuation kept."""
    from facegen.segmentation import segment, unspaced

    return " ".join(piece for chunk in text.split()
                    for _, piece in (segment(chunk, code) if unspaced(chunk, code) else [(chunk, chunk)]))


def recording(text: str, code: str, k: int) -> tuple[np.ndarray, list[float]]:
    from facegen.espeak import synthesize

    variant, rate, pitch = VOICES[k % len(VOICES)]
    speech = synthesize(said(text, code), voice=code, variant=variant, rate=rate, pitch=pitch,
                        sample_rate=16000)
    rng = np.random.default_rng(k)
    lead = np.zeros(int(LEAD * 16000), np.float32)
    audio = np.concatenate([lead, speech.audio, np.zeros(4000, np.float32)])
    level = np.sqrt(np.mean(speech.audio ** 2))
    audio = audio + (level * 10 ** (-30 / 20) * rng.standard_normal(len(audio))).astype(np.float32)
    return audio, [w.start + LEAD for w in speech.words]


def judged(audio: np.ndarray, text: str, code: str, whole: bool = False):
    from facegen import segmentation
    from facegen.align import align_checked
    from facegen.errors import FacegenError

    kept = dict(segmentation.SEGMENTERS)
    if whole:  # as before facegen.segmentation: words only at whitespace
        segmentation.SEGMENTERS.clear()
    try:
        return align_checked(audio, 16000, text, True, code)
    except FacegenError as exc:
        return str(exc)
    finally:
        segmentation.SEGMENTERS.update(kept)


def onsets(words, code: str) -> list[float]:
    """Each word's onset as a user gets it: a run aligned whole (`--whole`) gives each of its words its own
    start."""
    from facegen.words import spoken_words

    return [w.start for w in words for _ in range(max(1, len(spoken_words(w.text, code))))]


def main() -> None:
    from facegen.languages import HELD_OUT

    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", nargs="*")
    parser.add_argument("--no-write", action="store_true", help="print only")
    parser.add_argument("--swaps", type=int, default=1, choices=range(1, 5),
                        help="each recording with the transcripts of this many other sentences (4: all)")
    parser.add_argument("--whole", action="store_true",
                        help="align transcripts in scripts without spaces unsplit (as before); print only")
    args = parser.parse_args()
    cases, figures = [], {}
    for code, sentences in SENTENCES.items():
        if args.only and code not in args.only:
            continue
        errors, accepted, refused, gaps_right, gaps_wrong, seconds = [], 0, 0, [], [], []
        for k, text in enumerate(sentences):
            audio, truth = recording(text, code, k)
            start = time.perf_counter()
            found = judged(audio, text, code, args.whole)
            seconds.append(time.perf_counter() - start)
            if isinstance(found, str):
                cases.append({"language": code, "sentence": k, "kind": "matching", "error": found})
            else:
                accepted += found.match.problem is None
                gaps_right.append(found.match.word_gap)
                starts = onsets(found.words, code)
                if len(starts) == len(truth):
                    errors += [abs(s - t) for s, t in zip(starts, truth, strict=True)]
                cases.append({"language": code, "sentence": k, "kind": "matching", **found.match.as_dict(),
                              "words": len(found.words),
                              "onset_errors_ms": [round(1000 * abs(s - t)) for s, t in
                                                  zip(starts, truth, strict=False)]})
            for shift in range(1, args.swaps + 1):
                other = sentences[(k + shift) % len(sentences)]
                wrong = judged(audio, other, code, args.whole)
                if isinstance(wrong, str):
                    refused += 1
                    cases.append({"language": code, "sentence": k, "kind": "swapped", "error": wrong})
                else:
                    refused += wrong.match.problem is not None
                    gaps_wrong.append(wrong.match.word_gap)
                    cases.append({"language": code, "sentence": k, "kind": "swapped",
                                  **wrong.match.as_dict()})
        e = np.array(errors) if errors else np.array([np.nan])
        figures[code] = {"onset_median_ms": round(float(np.nanmedian(e)) * 1000, 1),
                         "within_100ms": round(float(np.mean(e < 0.1)), 3),
                         "accepted": round(accepted / len(sentences), 3),
                         "refused": round(refused / (len(sentences) * args.swaps), 3),
                         "sentences": len(sentences), "seconds_per_line": round(float(np.median(seconds)), 2),
                         **({"held_out": True} if code in HELD_OUT else {})}
        print(f"{code:<4} onset median {figures[code]['onset_median_ms']:5.1f} ms, "
              f"{figures[code]['within_100ms']:.0%} within 100 ms, accepted {accepted}/{len(sentences)}, "
              f"swapped refused {refused}/{len(sentences) * args.swaps}; word gap right "
              f"{np.round(gaps_right, 1).tolist()} wrong {np.round(gaps_wrong, 1).tolist()}"
              f"{'  (held out)' if code in HELD_OUT else ''}", flush=True)
    if not (args.no_write or args.whole):  # each language's other figures (cross_language.py's lips) are kept
        path = REPO / "facegen" / "language_figures.json"
        kept = json.loads(path.read_text()) if path.exists() else {}
        for code, found in figures.items():
            kept[code] = {**kept.get(code, {}), **found}
        path.write_text(json.dumps(kept, indent=1) + "\n")
        path = REPO / "benchmarks" / "results" / "languages.json"  # the cases of languages not run are kept
        old = json.loads(path.read_text()) if path.exists() else []
        path.write_text(json.dumps([c for c in old if c["language"] not in figures] + cases, indent=1) + "\n")


if __name__ == "__main__":
    main()
