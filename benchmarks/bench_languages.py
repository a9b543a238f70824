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

    python benchmarks/bench_languages.py [--only fr de ...]
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


def recording(text: str, code: str, k: int) -> tuple[np.ndarray, list[float]]:
    from facegen.espeak import synthesize

    variant, rate, pitch = VOICES[k % len(VOICES)]
    speech = synthesize(text, voice=code, variant=variant, rate=rate, pitch=pitch, sample_rate=16000)
    rng = np.random.default_rng(k)
    lead = np.zeros(int(LEAD * 16000), np.float32)
    audio = np.concatenate([lead, speech.audio, np.zeros(4000, np.float32)])
    level = np.sqrt(np.mean(speech.audio ** 2))
    audio = audio + (level * 10 ** (-30 / 20) * rng.standard_normal(len(audio))).astype(np.float32)
    return audio, [w.start + LEAD for w in speech.words]


def judged(audio: np.ndarray, text: str, code: str):
    from facegen.align import align_checked
    from facegen.errors import FacegenError

    try:
        return align_checked(audio, 16000, text, True, code)
    except FacegenError as exc:
        return str(exc)


def main() -> None:
    from facegen.languages import HELD_OUT

    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", nargs="*")
    parser.add_argument("--no-write", action="store_true", help="print only")
    args = parser.parse_args()
    cases, figures = [], {}
    for code, sentences in SENTENCES.items():
        if args.only and code not in args.only:
            continue
        errors, accepted, refused, gaps_right, gaps_wrong, seconds = [], 0, 0, [], [], []
        for k, text in enumerate(sentences):
            audio, truth = recording(text, code, k)
            start = time.perf_counter()
            found = judged(audio, text, code)
            seconds.append(time.perf_counter() - start)
            if isinstance(found, str):
                cases.append({"language": code, "sentence": k, "kind": "matching", "error": found})
            else:
                accepted += found.match.problem is None
                gaps_right.append(found.match.word_gap)
                if len(found.words) == len(truth):
                    errors += [abs(w.start - t) for w, t in zip(found.words, truth, strict=True)]
                cases.append({"language": code, "sentence": k, "kind": "matching", **found.match.as_dict(),
                              "onset_errors_ms": [round(1000 * abs(w.start - t)) for w, t in
                                                  zip(found.words, truth, strict=False)]})
            other = sentences[(k + 1) % len(sentences)]
            wrong = judged(audio, other, code)
            if isinstance(wrong, str):
                refused += 1
                cases.append({"language": code, "sentence": k, "kind": "swapped", "error": wrong})
            else:
                refused += wrong.match.problem is not None
                gaps_wrong.append(wrong.match.word_gap)
                cases.append({"language": code, "sentence": k, "kind": "swapped", **wrong.match.as_dict()})
        e = np.array(errors) if errors else np.array([np.nan])
        figures[code] = {"onset_median_ms": round(float(np.nanmedian(e)) * 1000, 1),
                         "within_100ms": round(float(np.mean(e < 0.1)), 3),
                         "accepted": round(accepted / len(sentences), 3),
                         "refused": round(refused / len(sentences), 3),
                         "sentences": len(sentences), "seconds_per_line": round(float(np.median(seconds)), 2),
                         **({"held_out": True} if code in HELD_OUT else {})}
        print(f"{code:<4} onset median {figures[code]['onset_median_ms']:5.1f} ms, "
              f"{figures[code]['within_100ms']:.0%} within 100 ms, accepted {accepted}/{len(sentences)}, "
              f"swapped refused {refused}/{len(sentences)}; word gap right "
              f"{np.round(gaps_right, 1).tolist()} wrong {np.round(gaps_wrong, 1).tolist()}"
              f"{'  (held out)' if code in HELD_OUT else ''}", flush=True)
    if not args.no_write:  # each language's other figures (cross_language.py's lips) are kept
        path = REPO / "facegen" / "language_figures.json"
        kept = json.loads(path.read_text()) if path.exists() else {}
        for code, found in figures.items():
            kept[code] = {**kept.get(code, {}), **found}
        path.write_text(json.dumps(kept, indent=1) + "\n")
        (REPO / "benchmarks" / "results" / "languages.json").write_text(json.dumps(cases, indent=1) + "\n")


if __name__ == "__main__":
    main()
