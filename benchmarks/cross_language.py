"""Benchmark: lip sync across languages (issue 25, deliverable 6): a model against facegen's rig, per
language.

Each sentence of benchmarks/language_sentences.py (and five English ones) is spoken by libespeak-ng in its
language with one of five voice variants; its ground truth is facegen's rig driven by the synthesiser's own
phone times, each phone labelled by espeak-ng's IPA for its word mapped to the rig's phones
(facegen.phonetics.ipa_to_cmu; where the synthesiser spoke another number of phones than the IPA lists, the
word's phones share its time). The model animates the recording with its transcript and `--language CODE`
(no blinks, still head); facegen.lipsync compares the two: aperture r (lag 0), median aperture ratio, p/b/m
closed at their midpoints, crossed lips, and the aligner's word-onset error against the synthesiser's times.

    python benchmarks/cross_language.py [--model BUNDLE] [--only fr de ...] [--json out.json] [--figures]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_languages import said
from language_sentences import SENTENCES

ENGLISH = ["Good morning everyone, I am very happy to see you all today.",
           "My brother works at a big hospital in Boston.",
           "Tomorrow morning we will take the train to Chicago.",
           "The cat is sleeping on the sofa in the living room.",
           "Could you please close the window?"]
VOICES = [("m1", 150, 40), ("f3", 140, 70), ("m3", 175, 50), ("f2", 160, 60), ("m4", 130, 45)]
LEAD = 0.4


def truth_phones(speech, voice: str) -> list[tuple[str, float, float]]:
    """The synthesiser's phones as (rig phone, start, end), labelled from espeak-ng's IPA of each word (as the
    voices corpus labels them: facegen.synth.voices.ipa_phone_times), LEAD seconds later."""
    from facegen.synth.voices import ipa_phone_times

    return [(c, a + LEAD, b + LEAD) for c, a, b in ipa_phone_times(speech, voice)]


def measure(animator, code: str, text: str, k: int, folder: Path) -> dict:
    from facegen.audio import write_wav
    from facegen.espeak import synthesize
    from facegen.languages import check_language
    from facegen.lipsync import bilabial_midpoints, lipsync_metrics, speech_mask
    from facegen.synth.curves import formant_track, loudness_envelope
    from facegen.synth.reference import rig_reference

    voice = check_language(code).voice
    variant, rate, pitch = VOICES[k % len(VOICES)]
    speech = synthesize(said(text, code), voice=voice, variant=variant, rate=rate, pitch=pitch,
                        sample_rate=16000)
    lead = np.zeros(int(LEAD * 16000), np.float32)
    audio = np.concatenate([lead, speech.audio, np.zeros(4000, np.float32)])
    level = np.sqrt(np.mean(speech.audio ** 2)) * 10 ** (-30 / 20)  # room noise at 30 dB SNR
    audio += (level * np.random.default_rng(k).standard_normal(len(audio))).astype(np.float32)
    wav = folder / f"{code}_{k}.wav"
    write_wav(audio, 16000, wav)
    anim = animator.animate(wav, text=text, language=code, blink_rate=0, head_motion=0, on_mismatch="warn")
    refused = bool(anim.metadata.get("transcript_match", {}).get("problem"))
    phones = truth_phones(speech, voice)
    words = [(w.text, w.start + LEAD, w.end + LEAD) for w in speech.words]
    ref = rig_reference(phones, words, anim.num_frames, anim.fps, alphabet="cmu",
                        loudness=loudness_envelope(audio, 16000), f1=formant_track(audio, 16000))
    row = lipsync_metrics(np.asarray(anim.vertices), ref, animator.mesh(), anim.fps,
                          speech=speech_mask(words, anim.num_frames, anim.fps),
                          bilabials=bilabial_midpoints(phones, anim.fps, alphabet="cmu"))
    aligned = anim.metadata["words"]
    onsets = [1000 * abs(a["start"] - (w.start + LEAD)) for a, w in zip(aligned, speech.words, strict=True)
              ] if len(aligned) == len(speech.words) else []
    return row, onsets, refused


def main() -> None:
    import facegen
    from facegen.languages import HELD_OUT
    from facegen.lipsync import pool_lipsync

    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", help="a model bundle (default: the built-in one)")
    parser.add_argument("--only", nargs="*")
    parser.add_argument("--json", type=Path)
    parser.add_argument("--figures", action="store_true",
                        help="add each language's lip figures to facegen/language_figures.json")
    args = parser.parse_args()
    animator = facegen.Animator(args.model)
    table = {"en": ENGLISH, **SENTENCES}
    results = {}
    print("| language | aperture r | median ratio | p/b/m closed (rig) | crossed lips | onset error ms |")
    print("|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for code, sentences in table.items():
            if args.only and code not in args.only:
                continue
            start = time.perf_counter()
            done = [measure(animator, code, text, k, Path(tmp)) for k, text in enumerate(sentences)]
            pooled = pool_lipsync([row for row, _, _ in done])
            onsets = [e for _, found, _ in done for e in found]
            pooled["refused"] = sum(refused for _, _, refused in done)
            pooled["onset_median_ms"] = float(np.median(onsets)) if onsets else None
            pooled["seconds"] = round(time.perf_counter() - start, 1)
            results[code] = pooled
            p = pooled

            def f(v, spec):
                return "-" if v is None else format(v, spec)

            print(f"| {code}{' (held out)' if code in HELD_OUT else ''} | {f(p['aperture_r'], '.2f')} | "
                  f"{f(p['aperture_median_ratio'], '.2f')} | {f(p['bilabial_closure_rate'], '.0%')} "
                  f"({f(p['ref_bilabial_closure_rate'], '.0%')}) | {f(p['crossed_lips_rate'], '.1%')} | "
                  f"{f(p['onset_median_ms'], '.0f')} |" + (f" {p['refused']} refused, animated anyway"
                                                          if p["refused"] else ""), flush=True)
    if args.json:
        args.json.write_text(json.dumps(results, indent=1) + "\n")
    if args.figures:
        merge_figures(results)


def merge_figures(results: dict) -> None:
    """Each language's lip figures into facegen/language_figures.json (what `facegen languages` prints)."""
    path = Path(__file__).resolve().parents[1] / "facegen" / "language_figures.json"
    figures = json.loads(path.read_text()) if path.exists() else {}
    for code, p in results.items():
        figures.setdefault(code, {})["lips"] = {
            "aperture_r": round(p["aperture_r"], 3), "median_ratio": round(p["aperture_median_ratio"], 3),
            "pbm_closed": round(p["bilabial_closure_rate"], 3), "crossed": round(p["crossed_lips_rate"], 4)}
    path.write_text(json.dumps(figures, indent=1) + "\n")


if __name__ == "__main__":
    main()
