"""Benchmark: lip sync and expression on voices the model never heard (issue 10's cross-voice table).

On a voices corpus (`facegen data synth OUT --preset voices`), for each model bundle given:

- test-a: the test sentences said by TRAINING voices (espeak-ng variants, Festival diphones), unseen
  sentences;
- held-out synthesiser: the same sentences said by Flite's voices (slt, rms, awb), never in training;
- unseen words: the test-unseen sentences (one HELD_OUT_LEXICON word each, never in any training sentence)
  said by the held-out synthesiser; the upper-face response is the upper face's motion with the emotional
  word over its motion with a neutral twin word at the same time on the same audio (>= 1.5 wanted).

Columns: LVE (x1e-4), upper-face error (mesh units), aperture r (lag 0), median aperture ratio, bilabial
closure, crossed lips, rest aperture (mm, non-speech frames), unseen-word upper-face response, and the median
aperture on 5 s of pure noise animated with --no-text (the mouth should stay at rest: < 1.5 mm). Prints a
Markdown table and writes it with the raw numbers to --json.

    python benchmarks/cross_voice.py CORPUS BUNDLE [BUNDLE ...] [--name A --name B] [--limit 80]
                                     [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

SPLITS = {"test-a": "1993-2208", "xvoice": "11993-12208", "unseen-xvoice": "12209-12448"}
STYLES = ("F2", "F3", "F4", "M3", "M4", "M5")


def _splits(test: str):
    from facegen.datasets.splits import Splits

    return Splits(train_subjects=STYLES, test_subjects=(), train_sentences="49-1776",
                  val_sentences="1777-1992",
                  test_sentences=test)


def evaluate_set(bundle, corpus: str, test: str, limit: int | None) -> dict:
    from facegen.evaluate import evaluate
    from facegen.runtime import SILENT

    result = evaluate(bundle, corpus, "test-a", splits=_splits(test), reporter=SILENT)
    return {"metrics": result["metrics"], "lipsync": result["lipsync"], "sequences": result["sequences"]}


def unseen_word_response(bundle_path, corpus: str, test: str, limit: int | None) -> dict:
    """Upper-face motion with the held-out emotional word / with its neutral twin, same audio and timing."""
    from facegen.alignment_files import read_alignment
    from facegen.evaluate import prepare
    from facegen.lipsync import FaceGeometry, upper_face_response
    from facegen.runtime import SILENT
    from facegen.synth.sentences import neutral_twin
    from facegen.synth.voice_corpus import XVOICE_OFFSET
    from facegen.text import load_text_backend, text_features
    from facegen.words import Word, strip_edges

    run = prepare(bundle_path, corpus, "test-a", splits=_splits(test), reporter=SILENT)
    bundle = run.bundle
    if not bundle.config.uses_text:
        return {"response": None, "sequences": 0}
    backend = load_text_backend(bundle.text_backend)
    geo = FaceGeometry.of(bundle.template)
    ratios = []
    for item in run.items[:limit]:
        number = int(item.name.split("_e")[1]) - XVOICE_OFFSET
        words = read_alignment(item.seq.alignment)
        twin = neutral_twin(number).split()
        if len(twin) != len(words):
            continue
        neutral = [Word(strip_edges(t), w.start, w.end) for t, w in zip(twin, words, strict=True)]
        condition = run.conditions(item)[0]
        emotional = item.template[None] + run.predict(item, condition)[0]
        item.text = text_features(neutral, backend, item.num_frames, bundle.features)
        calm = item.template[None] + run.predict(item, condition)[0]
        ratio = upper_face_response(calm, emotional, geo, rest_pose=item.template)
        if np.isfinite(ratio):
            ratios.append(ratio)
    return {"response": float(np.median(ratios)) if ratios else None, "mean": float(np.mean(ratios)) if ratios
            else None, "sequences": len(ratios)}


def rest_on_noise(bundle_path, seconds: float = 5.0) -> float:
    """Median lip aperture (mm) of the model on pure noise (pink-ish, -30 dBFS) animated with --no-text."""
    import tempfile

    from facegen import animate
    from facegen.audio import write_wav
    from facegen.bundle import load_bundle
    from facegen.lipsync import FaceGeometry, aperture

    rng = np.random.default_rng(0)
    noise = np.cumsum(rng.standard_normal(int(seconds * 16000))) * 0.02
    noise = noise - np.convolve(noise, np.ones(400) / 400, mode="same")  # a soft rumble-free noise
    noise *= 10 ** (-30 / 20) / np.sqrt(np.mean(noise ** 2))
    bundle = load_bundle(bundle_path)
    with tempfile.TemporaryDirectory() as tmp:
        wav = write_wav(noise.astype(np.float32), 16000, Path(tmp) / "noise.wav")
        anim = animate(wav, no_text=True, bundle=bundle, speaker=0)
    return float(np.median(aperture(anim.vertices, FaceGeometry.of(bundle.template)) * 10))


def row(name: str, sets: dict, unseen: dict, noise_mm: float) -> str:
    def fmt(v, f):
        return "-" if v is None else f.format(v)

    cells = [name]
    for key in ("test-a", "xvoice"):
        m, ls = sets[key]["metrics"], sets[key]["lipsync"] or {}
        cells += [fmt(m["lve"] * 1e4, "{:.2f}"), fmt(m["upper_error"], "{:.2e}"), fmt(ls.get("aperture_r"),
                                                                                      "{:.2f}"),
                  fmt(ls.get("aperture_median_ratio"), "{:.2f}"), fmt(ls.get("bilabial_closure_rate"),
                                                                      "{:.0%}"),
                  fmt(ls.get("crossed_lips_rate"), "{:.1%}"), fmt(ls.get("rest_aperture_mm"), "{:.1f}")]
    cells.append(fmt(unseen["response"], "{:.2f}"))
    cells.append(fmt(noise_mm, "{:.1f}"))
    return "| " + " | ".join(cells) + " |"


HEADER = ("| model | A: LVE ×1e-4 | A: upper err | A: aperture r | A: ratio | A: p/b/m closed | "
          "A: crossed | A: rest mm | X: LVE ×1e-4 | X: upper err | X: aperture r | X: ratio | "
          "X: p/b/m closed | X: crossed | X: rest mm | unseen-word response | noise: aperture mm |\n|"
          + "---|" * 17)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("corpus")
    parser.add_argument("bundles", nargs="+", help="model bundles ('default' for the built-in model)")
    parser.add_argument("--name", action="append", help="row name of each bundle, in order (repeat it)")
    parser.add_argument("--limit", type=int, default=None, help="at most this many unseen-word sequences")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    names = args.name or args.bundles
    if len(names) != len(args.bundles):
        parser.error(f"{len(names)} --name for {len(args.bundles)} bundles: give one per bundle")
    lines, raw = [HEADER], {}
    for name, bundle in zip(names, args.bundles, strict=True):
        path = None if bundle == "default" else bundle
        start = time.perf_counter()
        sets = {key: evaluate_set(path, args.corpus, SPLITS[key], args.limit) for key in ("test-a", "xvoice")}
        unseen = unseen_word_response(path, args.corpus, SPLITS["unseen-xvoice"], args.limit)
        noise_mm = rest_on_noise(path)
        raw[name] = {"bundle": bundle, **sets, "unseen": unseen, "noise_aperture_mm": noise_mm,
                     "seconds": time.perf_counter() - start}
        lines.append(row(name, sets, unseen, noise_mm))
        print(lines[-1], flush=True)
    table = "\n".join(lines)
    print("\n" + table)
    if args.json:
        args.json.write_text(json.dumps({"table": table, "rows": raw}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
