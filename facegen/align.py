"""Word timing with pocketsphinx: forced alignment of a transcript, and recognition without one.

What the recogniser hears comes from `facegen.words.normalize_transcript` (lower case, numbers spelled
out), and every result maps back to the user's words. Words missing from pocketsphinx's dictionary get a
pronunciation from libespeak-ng (`facegen.espeak.pronounce`).
"""

from __future__ import annotations

import itertools
import re
import threading
import unicodedata

import numpy as np

from facegen.audio import resample
from facegen.errors import FacegenError
from facegen.espeak import CMU_CONSONANTS, CMU_VOWELS, pronounce
from facegen.words import Word, check_word_rate, normalize_transcript

RATE = 16000  # pocketsphinx's en-us model
FRAME = 0.01  # pocketsphinx frame step (s)

_LOCK = threading.RLock()
_DECODERS: dict[str, object] = {}
_PRONOUNCED: dict[int, set[str]] = {}  # id(decoder) → words whose espeak pronunciation is in its dictionary
# Alignment tries these in turn until every word is placed. bestpath=False: the lattice pass after the
# FSG search drops valid alignments. Wide beams rescue noisy speech (the search is constrained by the
# transcript, so they stay affordable); fillers (noise/breath models) sometimes derail it.
_WIDE = {"beam": 1e-120, "wbeam": 1e-100, "pbeam": 1e-120, "maxhmmpf": -1}
_CONFIGS = {
    "align": {"lm": None, "bestpath": False},
    "align-wide": {"lm": None, "bestpath": False, **_WIDE},
    "align-nofiller": {"lm": None, "bestpath": False, "fsgusefiller": False, **_WIDE},
    "recognize": {},
}
_PHONES = CMU_VOWELS + CMU_CONSONANTS
_PHONE_WORD = {p: f"phone_{p.lower()}" for p in _PHONES}  # one-phone words, to align a free phone loop
# A transcript that does not match the speech (see _check_match): more than this share of the loud
# frames left outside its words, or a median word fitting the sounds worse than the best free phone
# sequence by more than this (per-frame gap to the best HMM state, pocketsphinx's log units).
MAX_UNEXPLAINED = 0.3
MAX_WORD_GAP = 22.0


def _decoder(kind: str):
    if kind not in _DECODERS:
        import pocketsphinx

        try:
            decoder = pocketsphinx.Decoder(samprate=RATE, loglevel="FATAL", **_CONFIGS[kind])
            if kind.startswith("align"):
                for phone, word in _PHONE_WORD.items():
                    decoder.add_word(word, phone, False)
                decoder.add_allphone_file("_phones", None)  # also refreshes the dictionary
        except (RuntimeError, ValueError) as exc:
            raise FacegenError(f"cannot start pocketsphinx ({exc}): reinstall it with "
                               "`pip install --force-reinstall pocketsphinx`") from exc
        _DECODERS[kind] = decoder
    return _DECODERS[kind]


def _dictionary_word(decoder, token: str) -> str:
    """The decoder's dictionary entry for `token`.

    A word missing from the dictionary gets espeak's pronunciation; a known word gets it as an
    alternative when it differs, so a quirk of either (CMUdict's "hmm" = HH M) does not derail it.
    New words go in without rebuilding the searches: set_align_text builds a fresh one.
    """
    key = unicodedata.normalize("NFKD", token).encode("ascii", "ignore").decode()
    key = re.sub(r"[^a-z0-9']", "", key.lower()).strip("'") or "oov_" + "_".join(f"{ord(c):x}" for c in token)
    done = _PRONOUNCED.setdefault(id(decoder), set())
    if key in done:
        return key
    known, n = [], 1
    while (pron := decoder.lookup_word(key if n == 1 else f"{key}({n})")) is not None:
        known.append(pron)
        n += 1
    phones = " ".join(pronounce(token) or ["AH"])
    if phones not in known:
        decoder.add_word(key if n == 1 else f"{key}({n})", phones, False)
    done.add(key)
    return key


def _pcm16k(audio: np.ndarray, sample_rate: int) -> np.ndarray:
    """Mono float audio at any rate → 16 kHz float32, after the checks a user's audio needs."""
    audio = np.asarray(audio, dtype=np.float32)
    if audio.ndim == 2:  # [samples, channels] or [channels, samples]
        audio = audio.mean(axis=1 if audio.shape[1] < audio.shape[0] else 0)
    if audio.ndim != 1 or sample_rate <= 0:
        raise FacegenError("audio must be a mono signal with a positive sample rate: pass one channel")
    if len(audio) < 0.25 * sample_rate:
        raise FacegenError(f"the audio is too short ({len(audio) / sample_rate:.2f} s): "
                           "use a recording with at least a quarter second of speech")
    if not np.all(np.isfinite(audio)):
        raise FacegenError("the audio contains NaN or infinite samples: check the audio file")
    if float(np.max(np.abs(audio))) < 1e-3:
        raise FacegenError("the audio is silent: check the audio file, its channel and its volume")
    if sample_rate != RATE:
        audio = resample(audio, sample_rate, RATE)
    return audio


def _pcm_bytes(audio: np.ndarray) -> bytes:
    """16-bit PCM at a standard level, over a faint noise floor: digital silence derails pocketsphinx."""
    level = float(np.percentile(np.abs(audio), 99.5)) or float(np.max(np.abs(audio)))
    x = audio * (0.5 / level)
    x = x + np.random.default_rng(0).normal(0.0, 1e-3, len(x)).astype(np.float32)
    return (np.clip(x, -1.0, 1.0) * 32767).astype("<i2").tobytes()


def _decode(decoder, pcm: bytes) -> list[tuple[str, int, int]]:
    """Run one utterance; return its segments (word, first frame, last frame inclusive)."""
    decoder.start_utt()
    decoder.process_raw(pcm, no_search=False, full_utt=True)
    decoder.end_utt()
    return [(s.word, s.start_frame, s.end_frame) for s in (decoder.seg() or [])]


def _base(word: str) -> str:
    return re.sub(r"\(\d+\)$", "", word)


def _is_filler(word: str) -> bool:
    return word.startswith(("<", "[", "+"))  # <s> </s> <sil> [NOISE] +SPN+ ...


def _state_gaps(decoder, pcm: bytes, n_frames: int) -> np.ndarray:
    """Per frame: how far the current alignment's HMM state scores below the best state of that frame.

    Runs pocketsphinx's second, state-level alignment pass over the current word alignment.
    """
    decoder.set_alignment()
    _decode(decoder, pcm)
    gaps = np.zeros(n_frames)
    for phone in decoder.get_alignment().phones():
        if phone.duration > 0:
            gaps[phone.start:phone.start + phone.duration] = -phone.score / phone.duration
    return gaps


def _free_gaps(decoder, pcm: bytes, n_frames: int) -> np.ndarray | None:
    """State gaps of the best unconstrained phone sequence: the fit a matching transcript nearly reaches."""
    decoder.activate_search("_phones")
    phones = [_PHONE_WORD[w] for w, _, _ in _decode(decoder, pcm) if w in _PHONE_WORD]
    if not phones:
        return None
    decoder.set_align_text(" ".join(phones))
    if not _decode(decoder, pcm):
        return None
    return _state_gaps(decoder, pcm, n_frames)


def _match_scores(decoder, pcm: bytes, n_frames: int,
                  words: list[tuple[str, int, int]]) -> tuple[np.ndarray, np.ndarray | None]:
    """State gaps of the word alignment and of the free phone loop, for _check_match.

    Both passes cost time and memory that grow faster than the audio's length (3 minutes in one pass:
    90 s and 1.3 GB; 10 minutes: more than 6 GB), so audio longer than CHECK_SECONDS is scored in
    segments of at most that length, cut in the longest pause between aligned words; each segment is
    aligned again with its own words and scored alone. At most CHECK_SEGMENTS segments, spread evenly
    over the clip, are scored (the frames of the others are NaN: their words are left out of the
    median); the share of speech outside the words is still measured on the whole clip. Falls back to
    one pass when a segment does not realign.
    """
    segments = _segments(words, n_frames)
    if len(segments) == 1:
        return _state_gaps(decoder, pcm, n_frames), _free_gaps(decoder, pcm, n_frames)
    gaps, free = np.full(n_frames, np.nan), np.full(n_frames, np.nan)
    chosen = np.unique(np.linspace(0, len(segments) - 1, min(CHECK_SEGMENTS, len(segments))).round().astype(int))
    for first, last, keys in (segments[i] for i in chosen):  # frames first..last-1
        part = pcm[first * _FRAME_BYTES:last * _FRAME_BYTES]
        decoder.set_align_text(" ".join(keys))
        if [_base(w) for w, _, _ in _decode(decoder, part) if not _is_filler(w)] != keys:
            decoder.set_align_text(" ".join(_base(w) for w, _, _ in words))
            _decode(decoder, pcm)
            return _state_gaps(decoder, pcm, n_frames), _free_gaps(decoder, pcm, n_frames)
        n = min(decoder.n_frames(), last - first)
        gaps[first:first + n] = _state_gaps(decoder, part, decoder.n_frames())[:n]
        seg_free = _free_gaps(decoder, part, decoder.n_frames())
        free[first:first + n] = gaps[first:first + n] if seg_free is None else seg_free[:n]
    return gaps, free


CHECK_SECONDS = 30.0  # longest stretch of audio scored in one pass by _match_scores
CHECK_SEGMENTS = 8  # most segments scored (4 minutes of audio at most)
_FRAME_BYTES = int(RATE * FRAME) * 2  # 16-bit PCM bytes per pocketsphinx frame


def _segments(words: list[tuple[str, int, int]], n_frames: int) -> list[tuple[int, int, list[str]]]:
    """(first frame, end frame, dictionary words) of segments of at most CHECK_SECONDS, cut in the middle
    of the longest pause between consecutive words in each segment's second half (one segment when the
    audio is short or no pause can be found)."""
    limit = int(CHECK_SECONDS / FRAME)
    if n_frames <= limit:
        return [(0, n_frames, [_base(w) for w, _, _ in words])]
    cuts, start, i = [0], 0, 0
    while n_frames - start > limit:
        best = None
        for j in range(i, len(words) - 1):
            end, following = words[j][2] + 1, words[j + 1][1]
            if following - start > limit:
                break
            if end - start >= limit // 2 and (best is None or following - end > best[0]):
                best = (following - end, (end + following) // 2, j + 1)
        if best is None:
            break
        start, i = best[1], best[2]
        cuts.append(start)
    cuts.append(n_frames)
    segments = []
    for a, b in itertools.pairwise(cuts):
        keys = [_base(w) for w, first, _ in words if a <= first < b]
        segments.append((a, b, keys))
    if any(not keys for _, _, keys in segments):
        return [(0, n_frames, [_base(w) for w, _, _ in words])]
    return segments


def _loud_frames(audio: np.ndarray, n_frames: int) -> np.ndarray:
    """Frames (10 ms step, 25 ms window) clearly louder than the recording's noise floor."""
    hop, win = RATE // 100, int(0.025 * RATE)
    padded = np.pad(audio, (0, max(0, n_frames * hop + win - len(audio))))
    frames = np.lib.stride_tricks.sliding_window_view(padded, win)[::hop][:n_frames]
    energy = 10 * np.log10(np.mean(frames.astype(np.float64) ** 2, axis=1) + 1e-12)
    low, high = np.percentile(energy, 10), np.percentile(energy, 95)
    return energy > low + 0.5 * (high - low)


def _mismatch(detail: str) -> FacegenError:
    return FacegenError(f"the transcript does not match the speech ({detail}): check the transcript; the aligner "
                        "knows English only, so for speech in another language align it with a tool for that "
                        "language (e.g. the Montreal Forced Aligner) and pass --alignment FILE")


def _check_match(audio: np.ndarray, words: list[tuple[str, int, int]], gaps: np.ndarray,
                 free: np.ndarray | None) -> None:
    """Raise if the alignment shows that the transcript is not what was said.

    Two signs, measured on synthetic speech (12 sentences and a paragraph, 14 voices, clean, 10 and
    5 dB SNR) against matching and mismatched transcripts:
    - speech the transcript does not explain is left to silence/noise segments: a transcript with
      half of the words leaves 34-60 % of the loud frames outside words, a matching one under 7 %;
    - words forced onto sounds they are not fit them badly: the median word's state gap exceeds
      the free phone loop's by 16-64 (27+ when clean, 30+ at 10 dB) for a wrong sentence, by -5 to 17
      for the right one (13 at most down to 10 dB SNR). A typo or a swapped word passes, as it should.
    End to end on those 48 clips: every matching transcript passes; 46/48 wrong sentences and 47/48
    half transcripts are refused (the misses are at 10 and 5 dB SNR).
    """
    n = len(gaps)
    loud = _loud_frames(audio, n)
    in_words = np.zeros(n, bool)
    for _, first, last in words:
        in_words[first:last + 1] = True
    unexplained = float(np.sum(loud & ~in_words)) / max(int(np.sum(loud)), 1)
    if unexplained > MAX_UNEXPLAINED:
        raise _mismatch(f"{unexplained:.0%} of the speech lies outside its words")
    if free is not None:  # words in unscored segments of long audio are NaN and left out
        excess = float(np.nanmedian([gaps[f:l + 1].mean() - free[f:l + 1].mean() for _, f, l in words]))
        if excess > MAX_WORD_GAP:
            raise _mismatch(f"its words fit the sounds poorly, score gap {excess:.0f} > {MAX_WORD_GAP:.0f}")


Phone = tuple[str, float, float]  # (CMU phone, start s, end s)


def align(audio: np.ndarray, sample_rate: int, transcript: str) -> list[Word]:
    """Word start/end times (s) of `transcript` in `audio` (mono, any rate), by forced alignment.

    Returns one Word per written word of the transcript (words made only of punctuation are left
    out), in order, with the user's spelling. Raises FacegenError for an empty transcript, silent or
    too short audio, or a transcript that does not match the speech.
    """
    return _align(audio, sample_rate, transcript, with_phones=False)[0]


def align_phones(audio: np.ndarray, sample_rate: int, transcript: str) -> tuple[list[Word], list[Phone]]:
    """The words of `align` and the phones inside them: (CMU phone without stress, start, end) in seconds,
    pauses left out — pocketsphinx's phone alignment of the same search (a second pass over the audio)."""
    return _align(audio, sample_rate, transcript, with_phones=True)


def _align(audio: np.ndarray, sample_rate: int, transcript: str,
           with_phones: bool) -> tuple[list[Word], list[Phone]]:
    entries = normalize_transcript(transcript)
    if not entries:
        raise FacegenError('the transcript is empty: pass the words spoken in the audio (e.g. --text "...")')
    check_word_rate(len(entries), len(audio) / sample_rate, "the transcript")
    audio = _pcm16k(audio, sample_rate)
    pcm = _pcm_bytes(audio)
    spoken = [(i, token) for i, (_, tokens) in enumerate(entries) for token in tokens]
    duration = len(audio) / RATE
    phones: list[Phone] = []
    with _LOCK:
        for kind in ("align", "align-wide", "align-nofiller"):
            decoder = _decoder(kind)
            keys = [_dictionary_word(decoder, token) for _, token in spoken]
            decoder.set_align_text(" ".join(keys))
            words = [s for s in _decode(decoder, pcm) if not _is_filler(s[0])]
            if [_base(w) for w, _, _ in words] == keys:
                break
        else:
            raise _mismatch("no alignment of its words to the audio exists")
        n_frames = decoder.n_frames()
        if with_phones:
            phones = _phone_pass(decoder, pcm, duration)
        gaps, free = _match_scores(decoder, pcm, n_frames, words)
    _check_match(audio, words, gaps, free)
    times: dict[int, list[float]] = {}
    for (index, _), (_, first, last) in zip(spoken, words, strict=True):
        start, end = first * FRAME, min((last + 1) * FRAME, duration)
        times.setdefault(index, [start, end])[1] = end
    return [Word(entries[i][0], round(t[0], 3), round(t[1], 3)) for i, t in sorted(times.items())], phones


def _phone_pass(decoder, pcm: bytes, duration: float) -> list[Phone]:
    """The phones of the word alignment the decoder has just found (pocketsphinx: set_alignment, decode)."""
    decoder.set_alignment()
    decoder.start_utt()
    decoder.process_raw(pcm, no_search=False, full_utt=True)
    decoder.end_utt()
    alignment = decoder.get_alignment()
    if alignment is None:
        raise _mismatch("pocketsphinx found no phone alignment for its words")
    return [(phone.name, round(phone.start * FRAME, 3), round(min((phone.start + phone.duration) * FRAME, duration), 3))
            for word in alignment if not _is_filler(word.name) for phone in word if phone.name != "SIL"]


def recognize(audio: np.ndarray, sample_rate: int) -> list[Word]:
    """Words recognised in `audio` without a transcript (pocketsphinx's default US English model).

    Less accurate than `align` with a transcript: words may be wrong; their timing is usually close.
    """
    audio = _pcm16k(audio, sample_rate)
    pcm = _pcm_bytes(audio)
    with _LOCK:
        segments = _decode(_decoder("recognize"), pcm)
    duration = len(audio) / RATE
    return [Word(_base(w), round(first * FRAME, 3), round(min((last + 1) * FRAME, duration), 3))
            for w, first, last in segments if not _is_filler(w)]
