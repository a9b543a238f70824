"""Benchmark (issue 25): the upper face's answer to emotional words in other languages.

For each language, one sentence frame ("My brother was really ___ last night", in that language) is said by
libespeak-ng in that language with each of eight emotional words (joy, sadness, anger, fear, surprise),
aligned with `--language`, and animated by the default model (or --model); then animated again on the same
audio and word times with a neutral word (e.g. "tall") in the emotional word's place. The text effect is
issue 10's unseen-word response (lipsync.upper_face_response: the upper face's motion with the emotional
word over its motion with the neutral one; >= 1.5 wanted), with the emotional word read through its English
gloss (facegen.lexicons: today) and as written (the English encoder alone: before). None of these foreign
words is in any training sentence (the voices corpus's foreign sentences leave out every lexicon word);
their glosses are training-lexicon words. English is the reference row. A line the mismatch check refuses is
animated anyway (--on-mismatch warn) and counted in "refused".

    python benchmarks/foreign_emotion.py [--model M] [--out benchmarks/results/foreign_emotion.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

# language: (sentence frame, neutral word, emotional words)
FRAMES = {
    "en": ("My brother was really {} last night.", "tall",
           ["happy", "sad", "furious", "terrified", "surprised", "depressed", "delighted", "worried"]),
    "fr": ("Mon frère était vraiment {} hier soir.", "grand",
           ["heureux", "triste", "furieux", "terrifié", "surpris", "déprimé", "ravi", "inquiet"]),
    "de": ("Mein Bruder war gestern Abend wirklich {}.", "groß",
           ["glücklich", "traurig", "wütend", "verängstigt", "überrascht", "enttäuscht", "begeistert",
            "besorgt"]),
    "es": ("Mi hermano estaba realmente {} anoche.", "sentado",
           ["feliz", "triste", "furioso", "aterrorizado", "sorprendido", "deprimido", "encantado",
            "preocupado"]),
    "it": ("Mio fratello era davvero {} ieri sera.", "alto",
           ["felice", "triste", "furioso", "spaventato", "sorpreso", "depresso", "entusiasta",
            "preoccupato"]),
    "pt": ("Meu irmão estava muito {} ontem à noite.", "sentado",
           ["feliz", "triste", "furioso", "assustado", "surpreso", "deprimido", "encantado", "preocupado"]),
    "ru": ("Мой брат был очень {} вчера вечером.", "высокий",
           ["счастлив", "грустный", "злой", "испуганный", "удивлён", "несчастный", "рад", "разгневанный"]),
}


def measure(language: str, folder: Path, animator) -> dict:
    from facegen.audio import write_wav
    from facegen.espeak import synthesize
    from facegen.languages import check_language
    from facegen.lexicons import glossed
    from facegen.lipsync import FaceGeometry, upper_face_response
    from facegen.text import text_features
    from facegen.words import Word

    frame, neutral, emotional = FRAMES[language]
    voice = check_language(language).voice
    backend = animator.text_backend()
    bundle = animator.bundle
    geo = FaceGeometry.of(bundle.template)
    rows = []
    for k, word in enumerate(emotional):
        text = frame.format(word)
        said = synthesize(text, voice=voice, variant=("m1", "f3")[k % 2], sample_rate=16000)
        pad = np.zeros(4800, np.float32)
        wav = write_wav(np.concatenate([pad, said.audio, pad]), 16000, folder / f"{language}{k}.wav")
        clip = animator.prepare(wav, text=text, language=language, speaker=0, on_mismatch="warn")
        twin = frame.format(neutral).split()
        if len(twin) != len(clip.words):
            continue
        calm_words = [Word(t.strip(".,"), w.start, w.end) for t, w in zip(twin, clip.words, strict=True)]
        rest = clip.mesh.vertices

        def upper(words, lang, clip=clip, rest=rest):
            feats = text_features(words, backend, clip.num_frames, bundle.features, lang)
            return rest + animator.offsets(replace(clip, text_features=feats))

        calm = upper(calm_words, language)
        glossed_face = rest + animator.offsets(clip)  # prepare read it with the language's glosses
        as_written = upper(clip.words, None)  # the English encoder alone
        rows.append({"word": word, "gloss": glossed([word], language)[0],
                     "refused": clip.match is not None and clip.match.problem is not None,
                     "glossed": upper_face_response(calm, glossed_face, geo, rest_pose=rest),
                     "as_written": upper_face_response(calm, as_written, geo, rest_pose=rest)})
    return {"words": rows,
            "glossed": float(np.median([r["glossed"] for r in rows])),
            "as_written": float(np.median([r["as_written"] for r in rows])),
            "glossed_min": float(np.min([r["glossed"] for r in rows])),
            "refused": sum(r["refused"] for r in rows)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "foreign_emotion.json")
    parser.add_argument("--languages", nargs="*", default=list(FRAMES))
    parser.add_argument("--model", help="a model bundle (default: the built-in one)")
    args = parser.parse_args()
    from facegen.animator import Animator

    animator = Animator(args.model)
    results = {}
    print("| language | text effect, glossed (median) | min | as written (the English encoder alone) | "
          "refused by the mismatch check |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for language in args.languages:
            found = measure(language, Path(tmp), animator)
            results[language] = found
            print(f"| {language} | {found['glossed']:.2f} | {found['glossed_min']:.2f} | "
                  f"{found['as_written']:.2f} | {found['refused']}/{len(found['words'])} |", flush=True)
    args.out.write_text(json.dumps(results, indent=1, ensure_ascii=False) + "\n")
    print(f"wrote {args.out}", file=sys.stderr)


if __name__ == "__main__":
    main()
