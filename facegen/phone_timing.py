"""Phones inside given word times: for an alignment file that has words but no phones (WhisperX, CSV, a
words-only TextGrid or JSON), or whose aligner could not pronounce some words (MFA's "spn", Gentle's "oov").

The words a file leaves without phones are cut into runs (consecutive words with no pause between them, at
most a piece of `align_pieces` long); each run is force-aligned by pocketsphinx over the audio of its span
only (the clip's cepstral mean, a little audio either side), and each word's phones are then kept inside the
word's time in the file, which stays the authority on when a word is said. A run that does not align is
tried word by word; a word that still does not (too short for its phones, noise, a word not said) gets its
espeak-ng pronunciation spread over its time, vowels twice as long as consonants.

The decoding is the aligner's own (facegen.sphinx's decoders, facegen.align's `align_piece`, `state_pass` and
`word_phones`), not a copy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facegen.align_pieces import HOP, PIECE_SECONDS
from facegen.errors import FacegenError
from facegen.languages import check_language
from facegen.phonetics import CMU_VOWELS, INDEX
from facegen.words import Word, normalize_transcript, spelled, spoken_words

Phone = tuple[str, float, float]  # (CMU phone without stress, start s, end s)
PAUSE = 0.1  # s between two words that ends a run
PAD = 0.05  # s of audio either side of a run that its search sees too


@dataclass
class WordPhones:
    """The phones of a clip's words: the file's where it had them, else found here; how many words were
    aligned here and how many got their espeak-ng pronunciation spread over their time."""

    phones: list[Phone]
    aligned: int = 0
    spread: int = 0


def phones_in_word_times(samples: np.ndarray, sample_rate: int, words: list[Word],
                         known: list[Phone] | None = None, language: str = "en") -> WordPhones:
    """The phones of `words` (times from an alignment file) in `samples` (mono, any rate): `known` (the file's
    own, if any) for the words they cover, pocketsphinx's phone alignment of each run of the others inside
    their times, or for a word that does not align its espeak-ng pronunciation spread over its time; the
    words' pronunciations in `language` (a code of facegen.languages)."""
    known = list(known or [])
    missing = [i for i, covered in enumerate(_covered(words, known)) if not covered]
    if not missing:
        return WordPhones(known)
    found = _align_runs(samples, sample_rate, words, _runs(words, missing), language)
    spread = [i for i in missing if i not in found and _tokens(words[i], language)]
    for i in spread:
        found[i] = _spread(words[i], language)
    phones = known + [p for i in missing if i in found for p in found[i]]
    return WordPhones(sorted(phones, key=lambda p: p[1]), len(found) - len(spread), len(spread))


def _covered(words: list[Word], phones: list[Phone]) -> list[bool]:
    """Per word: whether the middle of one of `phones` lies in its time."""
    middles = np.sort([(a + b) / 2 for _, a, b in phones])
    starts = np.searchsorted(middles, [w.start for w in words], side="left")
    ends = np.searchsorted(middles, [w.end for w in words], side="right")
    return list(ends > starts)


def _runs(words: list[Word], indices: list[int]) -> list[list[int]]:
    """`indices` (ascending) cut into runs of neighbouring words with no pause between them."""
    runs: list[list[int]] = []
    for i in indices:
        run = runs[-1] if runs else None
        if (run and run[-1] == i - 1 and words[i].start - words[i - 1].end <= PAUSE
                and words[i].end - words[run[0]].start <= PIECE_SECONDS):
            run.append(i)
        else:
            runs.append([i])
    return runs


def _tokens(word: Word, language: str = "en") -> list[tuple[str, list[str] | str | None]]:
    """What the aligner hears of a word: its spoken tokens, each with its letters if it may be spelled (in
    another language: with the espeak-ng voice it is said in, sphinx.dictionary_word)."""
    if language != "en":
        voice = check_language(language).voice
        return [(token, voice) for _, tokens in spoken_words(word.text, language) for token in tokens]
    return [(token, spelled(text, token)) for text, tokens in normalize_transcript(word.text)
            for token in tokens]


def _align_runs(samples: np.ndarray, sample_rate: int, words: list[Word],
                runs: list[list[int]], language: str) -> dict[int, list[Phone]]:
    """The phones of the words of `runs` that align (word index → phones in the word's time), each run over
    its span, then the words of a run that does not align one by one."""
    from facegen import sphinx

    found: dict[int, list[Phone]] = {}
    with sphinx.LOCK:
        try:
            audio = sphinx.pcm16k(samples, sample_rate)
        except FacegenError:  # silent or too short: nothing to align
            return found
        pcm = sphinx.pcm_bytes(audio)
        duration = len(audio) / sphinx.RATE
        cmn = sphinx.clip_cmn(pcm)
        for run in runs:
            run = [i for i in run if _tokens(words[i], language)]
            phones = _align_span(pcm, cmn, [words[i] for i in run], duration, language) if run else []
            if phones is None:  # word by word
                phones = [(_align_span(pcm, cmn, [words[i]], duration, language) or [[]])[0] for i in run]
            found.update((i, word_phones) for i, word_phones in zip(run, phones, strict=True) if word_phones)
    return found


def _align_span(pcm: bytes, cmn: str, words: list[Word], duration: float,
                language: str = "en") -> list[list[Phone]] | None:
    """Each of `words`' phones, force-aligned over the audio of their span (PAD either side) and fitted to the
    word's own time; None when pocketsphinx finds no alignment."""
    from facegen import align, sphinx

    first = max(0, int((words[0].start - PAD) / sphinx.FRAME))
    last = min(len(pcm) // (2 * HOP), int(np.ceil((words[-1].end + PAD) / sphinx.FRAME)))
    if last <= first:
        return None
    part = pcm[first * HOP * 2:last * HOP * 2]
    counts = [len(_tokens(w, language)) for w in words]
    tokens = [t for w in words for t in _tokens(w, language)]
    try:
        found = align.align_piece(part, tokens, last - first, last - first, cmn, prefix=False)
        if found is None:
            return None
        per_token = align.word_phones(align.state_pass(found[0], part, cmn), 0, len(tokens), first, duration)
        out, k = [], 0
        for word, count in zip(words, counts, strict=True):
            out.append(_fit([p for phones in per_token[k:k + count] for p in phones], word))
            k += count
        return out
    except (FacegenError, RuntimeError):  # no state alignment of its words
        return None


def _fit(phones: list[Phone], word: Word) -> list[Phone]:
    """`phones`, as the aligner placed them, inside the word's time: where they run past its start or end (the
    search sees PAD more audio), squeezed in; where they lie outside it altogether, stretched over it."""
    if not phones or phones[-1][2] <= phones[0][1]:
        return []
    a, b = phones[0][1], phones[-1][2]
    lo, hi = max(a, word.start), min(b, word.end)
    if hi <= lo:
        lo, hi = word.start, word.end
    scale = (hi - lo) / (b - a)
    return [(p, round(lo + (s - a) * scale, 3), round(lo + (e - a) * scale, 3)) for p, s, e in phones]


def _spread(word: Word, language: str = "en") -> list[Phone]:
    """The word's espeak-ng pronunciation (CMU phones) over its time, vowels twice as long as consonants."""
    from facegen.espeak import phonemize, pronounce
    from facegen.phonetics import ipa_to_cmu

    def said(token: str, voice) -> list[str]:
        return ipa_to_cmu(phonemize(token, voice, ipa=True)) if isinstance(voice, str) else pronounce(token)

    phones = [p for token, voice in _tokens(word, language) for p in said(token, voice) if p in INDEX]
    if not phones:
        return []
    weights = np.array([2.0 if p in CMU_VOWELS else 1.0 for p in phones])
    edges = word.start + (word.end - word.start) * np.concatenate([[0.0], np.cumsum(weights)]) / weights.sum()
    return [(p, round(float(a), 3), round(float(b), 3)) for p, a, b in zip(phones, edges[:-1], edges[1:],
                                                                            strict=True)]
