"""Forced alignment for any language espeak-ng speaks (issue 25), offline, without an acoustic model of the
language: the transcript is spoken by libespeak-ng in that language (facegen.espeak.synthesize, with its own
word and phone times), and the synthetic speech is warped onto the recording by dynamic time warping of their
MFCCs (as aeneas does; librosa's DTW). A word's start and end in the recording are where the warp takes its
start and end in the synthetic speech.

Numbers, abbreviations and punctuation are read by espeak-ng itself, in the language's own rules (its words map
back to the transcript's words). The phones of each word come from espeak-ng's grapheme-to-phoneme rules in
the IPA (`phonemize(ipa=True)`), mapped to the model's phone set by articulatory features
(facegen.phonetics.ipa_to_cmu); they share the word's span in the proportions the synthesiser gave them.

Long recordings are warped in chunks: the synthetic speech is cut in its pauses into chunks of at most
CHUNK_FRAMES, and each chunk is warped onto a window of the recording that starts where the chunk before
ended (subsequence DTW: the chunk whole, the window's ends free), so memory stays bounded (one chunk x window
cost matrix) and time grows with the length.

The mismatch check (a transcript that is not what was said): the mean cost per step of the warp (distance of
the matched MFCC frames after per-recording normalisation) and the share of loud frames outside the words;
COST_BOUND is measured by benchmarks/bench_languages.py on matching and swapped transcripts of training-side
languages (never on held-out ones).
"""

from __future__ import annotations

import numpy as np

from facegen.errors import FacegenError

RATE = 16000
HOP = 160  # 10 ms frames
CHUNK_FRAMES = 1500  # synthetic speech warped at a time (15 s)
STRETCH = 2.5  # a chunk's window: this many times its length (speech slower than espeak's) plus SLACK
SLACK = 300
PAD_S = 0.3  # silence around the synthetic speech: the recording's leading and trailing quiet meet it
COST_BOUND = 1.0  # mean warp cost per step above which the transcript is refused (see the docstring)
RATE_WPM = 165  # espeak's speaking rate for the reference


def align_synth(samples: np.ndarray, sample_rate: int, text: str, language, with_phones: bool):
    """The words of `text` (in `language`, a facegen.languages.Language) in the recording, their phones (CMU,
    with_phones) and how well the transcript matches: a facegen.align.Alignment."""
    from facegen.align import Alignment
    from facegen.audio import resample
    from facegen.espeak import synthesize
    from facegen.words import split_directions

    spoken = split_directions(text)[0]
    if not spoken.strip():
        from facegen.words import no_words

        raise no_words(text)
    audio = resample(np.asarray(samples, np.float32), sample_rate, RATE) if sample_rate != RATE else samples
    speech = synthesize(spoken, voice=language.voice, rate=RATE_WPM, sample_rate=RATE)
    if not speech.words:
        raise FacegenError(f"espeak-ng speaks none of the transcript's words in {language.code}: check the "
                           "transcript and --language", param="text")
    pad = np.zeros(int(PAD_S * RATE), np.float32)
    noise = np.random.default_rng(0).standard_normal(len(speech.audio) + 2 * len(pad)).astype(np.float32)
    reference = np.concatenate([pad, speech.audio, pad]) + 1e-4 * noise  # a quiet room, not digital zero
    ref_feats, rec_feats = features(reference), features(np.asarray(audio, np.float32))
    warp, cost = warp_frames(ref_feats, rec_feats, _pauses(speech, len(ref_feats)))
    duration = len(audio) / RATE

    def at(t: float) -> float:  # a time of the synthetic speech (without its padding) in the recording
        i = int(np.clip(round((t + PAD_S) * 100), 0, len(warp) - 1))
        return float(min(warp[i] / 100, duration))

    from facegen.words import Word

    words = []
    for w in speech.words:
        start, end = at(w.start), at(w.end)
        start = max(start, words[-1].end if words else 0.0)
        words.append(Word(w.text, start, max(end, start + 0.01)))
    phones = _phones(speech, words, language, at) if with_phones else None
    return Alignment(words, phones, _match(audio, words, cost))


def features(audio: np.ndarray) -> np.ndarray:
    """[frames, 13] MFCCs every 10 ms (band up to 4 kHz: telephone speech too), each coefficient normalised
    over the recording (mean 0, deviation 1)."""
    import librosa

    m = librosa.feature.mfcc(y=audio, sr=RATE, n_mfcc=13, n_fft=400, hop_length=HOP, n_mels=40, fmax=4000).T
    return ((m - m.mean(0)) / (m.std(0) + 1e-6)).astype(np.float64)


def _pauses(speech, frames: int) -> list[int]:
    """Frames of the padded synthetic speech where it pauses between words: where chunks may be cut."""
    cuts = []
    for a, b in zip(speech.words, speech.words[1:], strict=False):
        if b.start - a.end > 0.05:
            cuts.append(int(round(((a.end + b.start) / 2 + PAD_S) * 100)))
    return [c for c in cuts if 0 < c < frames]


def warp_frames(ref: np.ndarray, rec: np.ndarray, cuts: list[int]) -> tuple[np.ndarray, float]:
    """For each frame of `ref`, the frame of `rec` it is warped onto (monotonic), and the mean cost per step
    of the warp. Chunks of `ref` of at most CHUNK_FRAMES (cut at `cuts` where possible) are warped one after
    another onto windows of `rec` (see the module docstring)."""
    import librosa

    bounds = [0]
    for c in cuts + [len(ref)]:
        if c - bounds[-1] > CHUNK_FRAMES:
            last = max([x for x in cuts if bounds[-1] < x < c] or [bounds[-1] + CHUNK_FRAMES])
            while last - bounds[-1] > CHUNK_FRAMES:  # no pause near: cut mid-speech
                bounds.append(bounds[-1] + CHUNK_FRAMES)
            if last > bounds[-1]:
                bounds.append(last)
    if bounds[-1] != len(ref):
        bounds.append(len(ref))
    out = np.zeros(len(ref))
    total, steps, pos = 0.0, 0, 0
    for k, (a, b) in enumerate(zip(bounds, bounds[1:], strict=False)):
        final = k == len(bounds) - 2
        stop = len(rec) if final else min(len(rec), pos + int(STRETCH * (b - a)) + SLACK)
        window = rec[pos:stop]
        if len(window) < 2:
            out[a:b] = pos
            continue
        cost, path = librosa.sequence.dtw(X=ref[a:b].T, Y=window.T, metric="euclidean",
                                          subseq=not (final and k == 0))
        path = path[::-1]
        total += float(cost[path[-1][0], path[-1][1]])
        steps += len(path)
        first = np.full(b - a, -1.0)
        for i, j in path:  # the first recording frame each reference frame meets
            if first[i] < 0:
                first[i] = j
        out[a:b] = pos + first
        pos = pos + int(path[-1][1]) + 1
    return np.maximum.accumulate(out), total / max(steps, 1) / np.sqrt(ref.shape[1])


def _phones(speech, words, language, at) -> list[tuple[str, float, float]]:
    """Each word's phones (CMU) over its span in the recording: espeak-ng's IPA for the word mapped by
    articulatory features; their shares of the span from the synthesiser's phones when it spoke as many."""
    from facegen.espeak import phonemize
    from facegen.phonetics import ipa_to_cmu, is_silence

    out = []
    for k, (w, placed) in enumerate(zip(speech.words, words, strict=True)):
        cmu = ipa_to_cmu(phonemize(w.text, language.voice, ipa=True))
        if not cmu:
            continue
        own = [p for p in speech.phones if p.word == k and not is_silence(p.text)]
        if len(own) == len(cmu):  # the synthesiser's own phone times, warped
            edges = [at(p.start) for p in own] + [placed.end]
            edges = np.clip(np.maximum.accumulate(edges), placed.start, placed.end)
        else:
            edges = np.linspace(placed.start, placed.end, len(cmu) + 1)
        out += [(p, float(edges[i]), float(edges[i + 1])) for i, p in enumerate(cmu)]
    return out


def _match(audio: np.ndarray, words, cost: float):
    """The Match of a warp (facegen.transcript_match): its cost in the units of the word gap (the bound at
    CLEAN_WORD_GAP), the loud frames outside the words."""
    from facegen.align_pieces import loud_frames
    from facegen.transcript_match import CLEAN_WORD_GAP, MAX_UNEXPLAINED, Match

    n = len(audio) // HOP
    loud = loud_frames(audio, n)
    inside = np.zeros(n, bool)
    for w in words:
        inside[int(w.start * 100):int(w.end * 100) + 1] = True
    unexplained = float(np.sum(loud & ~inside)) / max(int(np.sum(loud)), 1)
    gap = cost / COST_BOUND * CLEAN_WORD_GAP
    problem = None
    if unexplained > MAX_UNEXPLAINED:
        problem = f"{unexplained:.0%} of the speech lies outside its words"
    elif cost > COST_BOUND:
        problem = f"the speech does not sound like its words (warp cost {cost:.2f} > {COST_BOUND:.2f})"
    return Match(unexplained, gap, CLEAN_WORD_GAP, problem)
