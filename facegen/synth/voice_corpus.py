"""The multi-voice speech corpus (`facegen data synth OUT --preset voices`): a corpus that teaches speech,
not one synthesiser's voice.

Every generated sentence (facegen.synth.sentences.generated_sentences: 2,400 distinct ones) is said once by
a voice drawn from the TRAINING voices (espeak-ng variants and Festival's diphone voices) at a random rate,
and moved by a motion style (one of the six training speakers, F2 F3 F4 M3 M4 M5) drawn independently of
the voice, so the style one-hot cannot stand in for the voice. The test and test-unseen sentences are said
a second time by a HELD-OUT synthesiser (Flite's clustergen voices slt, rms, awb) as sentence number
+ XVOICE_OFFSET: the cross-voice test. Festival's HTS voice is left out of both (it is trained on the same
ARCTIC speaker as flite:slt); flite:kal/kal16 are left out of the test (the speaker of festival:kal_diphone).

Per sequence {subject}_e{N}: the audio with pauses (`with_pauses`: silence before the sentence, at a word
boundary and after it), after acoustic augmentation (facegen.synth.augment: the speaker's loudness drifting,
pitch, formants, tempo, reverb, noise, band limits, codecs, level; wav/, 16-bit PCM at 16 kHz), the motion as
rig curves (curves/{name}.npy, float32 [T, len(CHANNELS)] — posed on the fly by the dataset reader: 12
numbers per frame instead of 70,110), the words and phones with their times (alignments/{name}.json, in the
augmented audio's time), the transcript (text/) and what made it (meta/{name}.json: voice, rate, style,
augmentation). The curves follow the synthesiser's own phone timings moved by the pauses and the speech's
loudness after its drift (prosody: louder syllables open the jaw more; facegen.synth.curves.viseme_curves).
Held out from every training sentence: the HELD_OUT_LEXICON words (test-unseen sentences only).

The root holds BIWI.ply (the neutral procedural face) with its regions, templates.pkl (each style's face),
sentences.txt and voices.json, the manifest (parameters and finished sequences): a rerun with the same
parameters resumes; other parameters are refused.
"""

from __future__ import annotations

import json
import os
import time
from concurrent.futures import as_completed
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from facegen.atomic import atomic_path
from facegen.errors import FacegenError
from facegen.processes import process_pool
from facegen.runtime import SILENT, Reporter, set_threads
from facegen.synth.voices import CORPUS_LANGUAGES, FOREIGN_VARIANTS

VERSION = 11  # 2: other languages; 3: their sentences without emotional words; 4: a stop takes its closure;
# 5: rounded lips pursed (facegen.synth.curves.ROUND_CLOSE); (6: a level contour, reverted); 7: the jaw
# calibrated on running speech too (a real ARKit take: schwa reduced, open vowels wider, f/v lips to teeth);
# 8: pauses before, inside and after a sentence (with_pauses), the speaker's loudness drifts
# (facegen.synth.augment.loudness_drift); 9: each vowel's jaw reads its first formant (FORMANT_EXP), rounding
# and spreading move the mouth's width as GRID's speakers do (facegen.face.rig.ROUND_NARROW, WIDE_SPREAD; the
# spreading a part of the full stretch, STRETCH_SPREAD); 10: the jaw stays part open through a p/b/m
# (facegen.synth.curves.BILABIAL_JAW and the PBM viseme's jaw, set on GRID's speakers and the iPhone take);
# 11: the jaw raised for an f/v and lowered for an l, as GRID's speakers hold it (the FV and L visemes)
MANIFEST = "voices.json"
RATE = 16000  # Hz of the stored audio (the model's)
FPS = 25.0
STYLES = ("F2", "F3", "F4", "M3", "M4", "M5")  # the motion styles: facegen.synth.corpus speakers
XVOICE_OFFSET = 10000  # sentence number of the held-out synthesiser's take of test sentence N: N + this
# The other languages (facegen.synth.voices.CORPUS_LANGUAGES): PER_LANGUAGE sentences each
# (facegen.synth.foreign_sentences), train/val/test 80/10/10, numbered FOREIGN_FIRST[split] + 100 x the
# language's place + k, so each split is one range (train 20000-29999, val 30000-39999, test 40000-49999)
PER_LANGUAGE = 60
FOREIGN_FIRST = {"train": 20000, "val": 30000, "test": 40000}
TRAIN_VOICES = ("espeak:en*", "festival:kal_diphone", "festival:ked_diphone")
TEST_VOICES = ("flite:slt", "flite:rms", "flite:awb")
RATES = (0.85, 1.2)  # speaking rate, relative to each voice's own
MEAN_SECONDS = 4.4  # for the disk estimate
BYTES_PER_SECOND = RATE * 2 + 12 * 4 * FPS + 2000 / MEAN_SECONDS  # wav + curves + json


@dataclass(frozen=True)
class Take:
    """One sequence to make: a sentence said by a voice, moved by a style."""

    name: str
    subject: str
    sentence: int
    text: str
    voice: str
    rate: float
    seed: int
    split: str


def _voices(patterns: tuple[str, ...]) -> list[str]:
    from facegen.synth.voices import VOICES, available_voices

    installed = {v.name for v in available_voices()}
    names = [n for p in patterns for n in VOICES if (n.startswith(p[:-1]) if p.endswith("*") else n == p)]
    missing = [n for n in names if n not in installed]
    if missing:
        from facegen.synth.voices import get_voice

        packages = sorted({get_voice(n).package for n in missing})
        raise FacegenError(f"voices {', '.join(missing)} are not installed: run `make voices` or "
                           f"`apt-get install {' '.join(packages)}` as root")
    return names


def plan(sentences: int = 2400, seed: int = 0, train_voices: tuple[str, ...] = TRAIN_VOICES,
         test_voices: tuple[str, ...] = TEST_VOICES, languages: tuple[str, ...] | None = None,
         per_language: int = PER_LANGUAGE) -> list[Take]:
    """Every take of the corpus, in a fixed order (a function of the arguments only): the English takes, then
    `per_language` takes in each of `languages` (None: CORPUS_LANGUAGES)."""
    from facegen.datasets.splits import sequence_name
    from facegen.synth.sentences import generated_sentences, generated_splits

    texts = generated_sentences(sentences, seed)
    splits = generated_splits(sentences)
    train, test = _voices(train_voices), _voices(test_voices)
    rng = np.random.default_rng([seed, 7])
    takes = []
    for split, numbers in splits.items():
        for n in numbers:
            subject = STYLES[int(rng.integers(len(STYLES)))]
            voice = train[int(rng.integers(len(train)))]
            rate = float(rng.uniform(*RATES))
            takes.append(Take(sequence_name(subject, n), subject, n, texts[n], voice, rate, n, split))
            if split in ("test", "test-unseen"):
                m = n + XVOICE_OFFSET
                xvoice = test[int(rng.integers(len(test)))]
                takes.append(Take(sequence_name(subject, m), subject, m, texts[n], xvoice, rate, m,
                                  f"{split}-xvoice"))
    return takes + foreign_takes(CORPUS_LANGUAGES if languages is None else languages, per_language, seed)


def foreign_takes(languages: tuple[str, ...], per_language: int = PER_LANGUAGE, seed: int = 0) -> list[Take]:
    """The takes of the other languages: each sentence said by one of the language's espeak-ng voices
    (FOREIGN_VARIANTS), moved by a style drawn independently."""
    from facegen.datasets.splits import sequence_name
    from facegen.synth.foreign_sentences import foreign_sentences

    takes = []
    val = test = max(1, per_language // 10) if per_language >= 3 else 0
    counts = {"train": per_language - val - test, "val": val, "test": test}
    for i, code in enumerate(languages):
        if code not in CORPUS_LANGUAGES:
            raise FacegenError(f"the voices corpus has no voices for {code!r}: choose among "
                               f"{', '.join(CORPUS_LANGUAGES)}")
        texts = iter(foreign_sentences(code, per_language, seed))
        rng = np.random.default_rng([seed, 11, i])
        for split, count in counts.items():
            for k in range(count):
                n = FOREIGN_FIRST[split] + 100 * CORPUS_LANGUAGES.index(code) + k
                subject = STYLES[int(rng.integers(len(STYLES)))]
                variant = list(FOREIGN_VARIANTS)[int(rng.integers(len(FOREIGN_VARIANTS)))]
                rate = float(rng.uniform(*RATES))
                takes.append(Take(sequence_name(subject, n), subject, n, next(texts),
                                  f"espeak:{code}+{variant}", rate, n, f"{split}-{code}"))
    return takes


def estimate_bytes(takes: list[Take]) -> int:
    return int(len(takes) * MEAN_SECONDS * BYTES_PER_SECOND)


def _scaled(timings, scale: float) -> list[tuple[str, float, float]]:
    return [(str(t), float(a) * scale, float(b) * scale) for t, a, b in timings]


def _words_of(text: str, utt) -> list[tuple[str, float, float]] | None:
    """The transcript's written words with the engine's word times (engines normalise spellings)."""
    from facegen.words import strip_edges

    written = [w for w in (strip_edges(t) for t in text.split()) if w]
    if utt.words is None or len(utt.words) != len(written):
        return None
    return [(w, a, b) for w, (_, a, b) in zip(written, utt.words, strict=True)]


# Pauses. Synthesisers start speaking at once and rarely stop inside a sentence, so the training motion never
# held the in-breath, the lips parting before speech after a pause (facegen.synth.curves: PRE_SPEECH_S,
# PAUSE_S), that real speakers make; the model trained on them kept the lips shut there, and on GRID's real
# speakers the rig without it follows them at r 0.69 instead of 0.74 (docs/real_faces.md). A take now
# starts with LEAD_S of silence (with probability P_LEAD), may pause MID_S at one word boundary (P_MID) and
# ends with up to TRAIL_S.
P_LEAD, LEAD_S = 0.8, (0.1, 1.0)
P_MID, MID_S = 0.5, (0.3, 0.9)
TRAIL_S = (0.0, 0.5)


def with_pauses(audio: np.ndarray, sr: int, words: list, phones: list, rng: np.random.Generator
                ) -> tuple[np.ndarray, list, list, dict]:
    """`audio` with silence before it, at one word boundary and after it (drawn as P_LEAD / LEAD_S, P_MID /
    MID_S, TRAIL_S), and the words' and phones' (text, start, end) moved with it; what was inserted (s)."""
    lead = float(rng.uniform(*LEAD_S)) if rng.random() < P_LEAD else 0.0
    cuts = [(0.0, round(lead * sr))]
    if len(words) > 1 and rng.random() < P_MID:
        at = float(words[int(rng.integers(1, len(words)))][1])
        cuts.append((at, round(float(rng.uniform(*MID_S)) * sr)))
    trail = round(float(rng.uniform(*TRAIL_S)) * sr)
    pieces, last = [], 0
    for at, n in cuts:
        i = min(round(at * sr), len(audio))
        pieces += [audio[last:i], np.zeros(n, audio.dtype)]
        last = i
    pieces += [audio[last:], np.zeros(trail, audio.dtype)]

    def moved(t: float, end: bool) -> float:  # a time after (an end: after or at) a cut moves by its silence
        return t + sum(n for at, n in cuts if (t > at if end else t >= at)) / sr

    def shift(timings):
        return [(str(x), moved(float(a), False), moved(float(b), True)) for x, a, b in timings]

    inserted = {"lead_s": round(cuts[0][1] / sr, 4), "trail_s": round(trail / sr, 4)}
    if len(cuts) > 1:
        inserted["pause"] = {"at_s": round(cuts[1][0], 4), "s": round(cuts[1][1] / sr, 4)}
    return np.concatenate(pieces), shift(words), shift(phones), inserted


def make_take(take: Take, out: Path, augmentation: bool = True) -> dict:
    """Synthesise, augment and rig one take; write its files; return its manifest entry."""
    from facegen.audio import num_frames, resample, write_wav
    from facegen.synth.augment import augment, loudness_drift
    from facegen.synth.corpus import speaker_index
    from facegen.synth.curves import SpeakerStyle, formant_track, loudness_envelope, motion_curves
    from facegen.synth.voices import synthesize
    from facegen.words import Word

    utt = synthesize(take.text, take.voice, rate=take.rate)
    words = _words_of(take.text, utt)
    if words is None or not utt.phones:
        raise FacegenError(f"{take.voice} gave no word or phone timings for e{take.sentence}")
    clean = resample(utt.audio, utt.sample_rate, RATE)
    phones, speaker_changes = utt.phones, {}
    if augmentation:  # the speaker's pauses and own loudness: the motion follows both
        clean, words, phones, speaker_changes["pauses"] = with_pauses(
            clean, RATE, words, phones, np.random.default_rng([take.seed, 3]))
        clean, drift = loudness_drift(clean, RATE, np.random.default_rng([take.seed, 2]))
        if drift is not None:
            speaker_changes["loudness_drift"] = drift
    loud, f1 = loudness_envelope(clean, RATE), formant_track(clean, RATE)
    audio, scale, applied = augment(clean, RATE, take.seed) if augmentation else (clean, 1.0, {})
    applied = {**speaker_changes, **applied}
    if scale != 1.0:  # tempo: the loudness and formant curves and every time stretch with the audio
        at = np.arange(int(np.ceil(len(loud) * scale))) / scale
        loud = np.interp(at, np.arange(len(loud)), loud)
        f1 = f1[np.clip(np.round(at).astype(int), 0, len(f1) - 1)] if len(f1) else f1
    words, phones = _scaled(words, scale), _scaled(phones, scale)
    frames = num_frames(len(audio) / RATE, FPS)
    style = SpeakerStyle.for_speaker(speaker_index(take.subject))
    curves = motion_curves(phones, [Word(*w) for w in words], frames, FPS, style,
                           np.random.default_rng([take.seed, 1]), alphabet=utt.alphabet, loudness=loud, f1=f1)
    for folder in ("wav", "curves", "alignments", "text", "meta"):
        (out / folder).mkdir(exist_ok=True)
    with atomic_path(out / "wav" / f"{take.name}.wav") as tmp:
        write_wav(audio, RATE, tmp)
    with atomic_path(out / "curves" / f"{take.name}.npy") as tmp:
        np.save(tmp, curves.astype(np.float32))
    alignment = {"words": [{"word": w, "start": round(a, 4), "end": round(b, 4)} for w, a, b in words],
                 "phones": [{"phone": p, "start": round(a, 4), "end": round(b, 4)} for p, a, b in phones],
                 "alphabet": utt.alphabet}
    for path, text in ((out / "alignments" / f"{take.name}.json", json.dumps(alignment)),
                       (out / "text" / f"{take.name}.txt", take.text + "\n"),
                       (out / "meta" / f"{take.name}.json",
                        json.dumps({**asdict(take), "augmentation": applied, "time_scale": scale}))):
        with atomic_path(path) as tmp:
            tmp.write_text(text)
    return {"name": take.name, "split": take.split, "voice": take.voice, "frames": frames}


def _work(takes: list[Take], out: str, augmentation: bool) -> list[dict]:
    """One worker's share (a fresh process: one thread for the libraries it loads from now on, its own
    libespeak-ng)."""
    set_threads(1, ("env",))
    done = []
    for take in takes:
        try:
            done.append(make_take(take, Path(out), augmentation))
        except FacegenError as exc:
            done.append({"name": take.name, "split": take.split, "voice": take.voice, "error": str(exc)})
    return done


def _write_root(out: Path, takes: list[Take]) -> None:
    """BIWI.ply with its regions, templates.pkl (each style's face) and sentences.txt."""
    from facegen.datasets.biwi import DatasetWriter
    from facegen.face.procedural import make_face, speaker_face
    from facegen.synth.corpus import speaker_index

    writer = DatasetWriter(out)
    writer.write_mesh(make_face())
    writer.write_templates({s: speaker_face(speaker_index(s)).vertices for s in STYLES})
    lines = sorted({(t.sentence, t.text) for t in takes})
    with atomic_path(out / "sentences.txt") as tmp:
        tmp.write_text("".join(f"e{n:02d} {text}\n" for n, text in lines))


def build(out: str | os.PathLike, *, sentences: int = 2400, seed: int = 0, workers: int = 2,
          augmentation: bool = True, limit: int | None = None, languages: tuple[str, ...] | None = None,
          per_language: int = PER_LANGUAGE, reporter: Reporter = SILENT) -> dict:
    """Make (or resume) the corpus in `out`; returns the manifest. `limit` makes only the first takes of each
    split (a small corpus for tests and trials). How far it is goes to `reporter.progress`."""
    import shutil

    out = Path(out)
    languages = CORPUS_LANGUAGES if languages is None else tuple(languages)
    takes = plan(sentences, seed, languages=languages, per_language=per_language)
    if limit is not None:  # the first `limit` takes of each split
        kept, counts = [], {}
        for t in takes:
            counts[t.split] = counts.get(t.split, 0) + 1
            if counts[t.split] <= limit:
                kept.append(t)
        takes = kept
    params = {"version": VERSION, "sentences": sentences, "seed": seed, "augmentation": augmentation,
              "limit": limit, "fps": FPS, "sample_rate": RATE, "languages": list(languages),
              "per_language": per_language}
    out.mkdir(parents=True, exist_ok=True)
    manifest_path = out / MANIFEST
    manifest = json.loads(manifest_path.read_text()) if manifest_path.is_file() else {"params": params,
                                                                                      "done": {}}
    if manifest["params"] != params:
        raise FacegenError(f"{out} holds a voices corpus made with other parameters ({manifest['params']}): "
                           "choose another folder")
    todo = [t for t in takes if t.name not in manifest["done"]]
    need = estimate_bytes(todo)
    free = shutil.disk_usage(out).free
    if need > free:
        raise FacegenError(f"the corpus needs about {need / 1e9:.1f} GB and {out} has {free / 1e9:.1f} GB "
                           "free: free space or pass fewer sentences")
    if not (out / "BIWI.ply").is_file():
        _write_root(out, takes)
    say = reporter.progress
    say(f"{len(todo)} of {len(takes)} sequences to make ({need / 1e9:.2f} GB), {workers} workers")
    chunks = [todo[i::max(1, workers * 8)] for i in range(max(1, workers * 8))]
    start, made = time.perf_counter(), 0

    def save() -> None:
        with atomic_path(manifest_path) as tmp:
            tmp.write_text(json.dumps(manifest, indent=0))

    with process_pool(workers, start="spawn") as pool:
        futures = [pool.submit(_work, chunk, str(out), augmentation) for chunk in chunks if chunk]
        for future in as_completed(futures):
            for entry in future.result():
                manifest["done"][entry["name"]] = entry
                made += 1
            save()
            say(f"{made}/{len(todo)} sequences ({time.perf_counter() - start:.0f} s)")
    failed = [e for e in manifest["done"].values() if "error" in e]
    if failed:
        say(f"{len(failed)} takes failed (left out): {failed[0]['name']}: {failed[0]['error']}")
    return manifest
