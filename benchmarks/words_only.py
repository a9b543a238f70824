"""Benchmark: the default model from a words-only alignment file against the same words with their phones.

A words-only file (WhisperX, CSV, a words-only TextGrid) gives the phone-stream model no phones: facegen
aligns them inside the file's word times (facegen.phone_timing). On each clip — examples/excellent_room.wav
and test-unseen sentences said by Flite (the held-out synthesiser), each with one held-out emotional word —
this aligns the transcript with its phones (`facegen align --phones`), writes that alignment twice (with its
phones, and words only) and animates each with the default model, then measures:

- the text effect (issue 10's unseen-word response, benchmarks/cross_voice.py): the upper face's motion with
  the clip's words over its motion with a neutral twin sentence at the same times on the same audio
  (lipsync.upper_face_response; >= 1.5 wanted), from the phones file and from the words-only file;
- the lips: the lip aperture's correlation (r, lag 0) between the words-only run and the phones-file run, and
  the share of speech frames whose phone agrees; the same for the espeak-ng fallback alone (every word's
  pronunciation spread over its time) and for no phones at all (the phone stream silent), for scale;
- the seconds the phones inside the word times took.

The words-only file holds the same word times as the phones file, or (`--jitter S`) each start and end moved
by up to S seconds either way (seeded; order kept), as another aligner's times would differ.

    python benchmarks/words_only.py [--sentences 8] [--jitter 0.03] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
EXCELLENT = ("What an excellent room you have, sir. Such expensive furnishings!",
             "What an ordinary room you have, sir. Such wooden furnishings!")
VOICES = ("flite:slt", "flite:rms", "flite:awb")


def clips(folder: Path, count: int) -> list[tuple[str, Path, str, str]]:
    """(name, wav, transcript, neutral twin): the example and `count` test-unseen sentences said by Flite."""
    from facegen.audio import write_wav
    from facegen.synth.sentences import generated_sentences, generated_splits, neutral_twin
    from facegen.synth.voices import synthesize

    out = [("excellent_room", REPO / "examples" / "excellent_room.wav", *EXCELLENT)]
    sentences = generated_sentences()
    for k, number in enumerate(list(generated_splits()["test-unseen"])[:count]):
        voice = VOICES[k % len(VOICES)]
        utt = synthesize(sentences[number], voice)
        pad = np.zeros(int(0.3 * utt.sample_rate), np.float32)
        wav = write_wav(np.concatenate([pad, utt.audio, pad]), utt.sample_rate, folder / f"e{number}.wav")
        out.append((f"e{number} ({voice})", wav, sentences[number], neutral_twin(number)))
    return out


def pearson(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.corrcoef(a, b)[0, 1])


def jittered(words: list, jitter: float, seed: int) -> list:
    """`words` with each start and end moved by up to `jitter` s (uniform), kept in order and apart."""
    from facegen.words import Word

    rng = np.random.default_rng(seed)
    out, last = [], 0.0
    for w in words:
        start = max(last, w.start + rng.uniform(-jitter, jitter))
        end = max(start + 0.03, w.end + rng.uniform(-jitter, jitter))
        out.append(Word(w.text, round(start, 3), round(end, 3)))
        last = end
    return out


def measure(animator, wav: Path, text: str, twin: str, folder: Path, jitter: float = 0.0,
            seed: int = 0) -> dict:
    from facegen.align import align_phones
    from facegen.alignment_files import write_alignment
    from facegen.audio import load_audio
    from facegen.lipsync import FaceGeometry, aperture, upper_face_response
    from facegen.phone_timing import _spread, phones_in_word_times
    from facegen.phonetics import phone_frames, silence
    from facegen.text import text_features
    from facegen.words import Word, strip_edges

    samples, sr = load_audio(wav)
    words, phones = align_phones(samples, sr, text)
    given = jittered(words, jitter, seed) if jitter else words
    files = {"phones": write_alignment(words, folder / "phones.json", phones=phones),
             "words": write_alignment(given, folder / "words.csv")}
    start = time.perf_counter()
    found = phones_in_word_times(samples, sr, given)
    seconds = time.perf_counter() - start
    bundle = animator.bundle
    geo = FaceGeometry.of(bundle.template)
    neutral = {name: [Word(strip_edges(t), w.start, w.end) for t, w in zip(twin.split(), timed, strict=True)]
               for name, timed in (("phones", words), ("words", given))}
    row: dict = {"words": len(words), "aligned": found.aligned, "spread": found.spread,
                 "seconds": seconds, "audio_seconds": len(samples) / sr}
    runs = {}
    for name, path in files.items():
        clip = animator.prepare(wav, alignment=path)
        emotional = clip.mesh.vertices + animator.offsets(clip)
        calm = replace(clip, text_features=text_features(neutral[name], animator.text_backend(),
                                                         clip.num_frames, bundle.features))
        row[f"text_effect_{name}"] = upper_face_response(clip.mesh.vertices + animator.offsets(calm),
                                                         emotional, geo, rest_pose=clip.mesh.vertices)
        row[f"word_timing_{name}"] = clip.word_timing
        runs[name] = (clip, emotional)
    clip, reference = runs["phones"]
    speech = clip.phones[:, 1:].sum(1) > 0
    ref_aperture = aperture(reference, geo)
    variants = {"words": runs["words"][0].phones,
                "spread": phone_frames([p for w in given for p in _spread(w)], clip.num_frames, 25.0),
                "silent": silence(clip.num_frames)}
    for name, frames in variants.items():
        lips = runs["words"][1] if name == "words" else clip.mesh.vertices + animator.offsets(
            replace(clip, phones=frames))
        row[f"aperture_r_{name}"] = pearson(aperture(lips, geo), ref_aperture)
        row[f"phone_agreement_{name}"] = float((frames.argmax(1) == clip.phones.argmax(1))[speech].mean())
    return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sentences", type=int, default=8, help="test-unseen sentences said by Flite")
    parser.add_argument("--jitter", type=float, default=0.0, help="s the words-only file's times move")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)

    from facegen.animator import Animator

    animator = Animator(device="cpu")
    rows = {}
    header = ("| clip | words | aligned / spread | text effect: phones file | words only | aperture r: words "
              "only | espeak spread | no phones | phones agreeing: words only | spread | s per audio s |\n|"
              + "---|" * 11)
    print(header)
    with tempfile.TemporaryDirectory() as tmp:
        for k, (name, wav, text, twin) in enumerate(clips(Path(tmp), args.sentences)):
            r = rows[name] = measure(animator, wav, text, twin, Path(tmp), args.jitter, seed=k)
            cells = [name, r["words"], f"{r['aligned']} / {r['spread']}", f"{r['text_effect_phones']:.2f}",
                     f"{r['text_effect_words']:.2f}", f"{r['aperture_r_words']:.3f}",
                     f"{r['aperture_r_spread']:.3f}", f"{r['aperture_r_silent']:.3f}",
                     f"{r['phone_agreement_words']:.0%}", f"{r['phone_agreement_spread']:.0%}",
                     f"{r['seconds'] / r['audio_seconds']:.3f}"]
            print("| " + " | ".join(map(str, cells)) + " |", flush=True)
    keys = ("text_effect_phones", "text_effect_words", "aperture_r_words", "aperture_r_spread",
            "aperture_r_silent", "phone_agreement_words", "phone_agreement_spread")
    medians = {k: float(np.median([r[k] for r in rows.values()])) for k in keys}
    print("median: " + ", ".join(f"{k} {v:.3f}" for k, v in medians.items()))
    if args.json:
        args.json.write_text(json.dumps({"jitter": args.jitter, "rows": rows, "median": medians}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
