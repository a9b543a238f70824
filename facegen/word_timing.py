"""A clip's words (and phones) in time, from whichever source the user gave: an alignment file, the forced
alignment of a transcript, or speech recognition without one.

The Animator (animator.py) asks here for the words of every clip it prepares, and `facegen align` for the
words it prints. The forced alignment itself is align.py's; what may have been started ahead in a process of
its own is align_ahead.py's (`ahead`: its `AlignAhead` or `Aligned`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from facegen.align_ahead import AlignAhead, Aligned
from facegen.errors import FacegenError
from facegen.runtime import SILENT, Reporter
from facegen.transcript_match import Match

FORCED, FILE, RECOGNISED, NONE = ("forced alignment", "alignment file", "speech recognition",
                                  "none (--no-text)")
FILE_PHONES_ALIGNED = "alignment file + phones aligned"  # a file's words, (some of) their phones aligned here


@dataclass
class Timing:
    """A clip's words in time, where they came from (FORCED, FILE, ...), its phones per frame (models with a
    phone stream); for a forced alignment, how well the transcript matches the speech; for recognised words,
    how sure the recogniser is of each (facegen.recognition)."""

    words: list
    source: str
    phones: np.ndarray | None = None
    match: Match | None = None
    confidences: list[float] | None = None
    phone_times: list | None = None  # the aligned phones as (CMU phone, start s, end s), where there are any

    @property
    def driving(self) -> list:
        """The words that drive the upper face: all of them, but of recognised words only those the
        recogniser is sure of (recognition.SURE) — a misheard word would move the brows with the wrong
        meaning; the others leave the face neutral there."""
        from facegen.recognition import SURE

        if self.confidences is None:
            return self.words
        return [w for w, c in zip(self.words, self.confidences, strict=True) if c >= SURE]


def force_aligned(text: str | None, alignment, no_text: bool) -> bool:
    """Whether a clip's words come from forced alignment of `text` (not an alignment file, not
    recognition)."""
    return text is not None and bool(text.strip()) and alignment is None and not no_text


def _check_transcript(text: str) -> None:
    if not text.strip():
        raise FacegenError("the transcript is empty: pass the words spoken", param="text")


def clip_words(samples: np.ndarray, sr: int, *, text: str | None = None,
               alignment: str | os.PathLike | None = None, reporter: Reporter = SILENT,
               ahead: AlignAhead | Aligned | None = None, on_mismatch: str = "error",
               language: str = "en") -> Timing:
    """Word timings for the clip and where they came from (alignment file, forced alignment, recognition);
    `ahead`: the forced alignment of `text` already started in a process of its own (align_ahead.py);
    `on_mismatch`: see `forced`; `language`: the transcript's (recognition hears English only: in another
    language, no transcript means no words)."""
    from facegen import recognition
    from facegen.alignment_files import read_alignment

    if alignment is not None:
        return Timing(read_alignment(alignment, duration=len(samples) / sr), FILE)
    if text is not None:
        _check_transcript(text)
        reporter.progress("aligning the transcript to the speech (pocketsphinx)")
        try:
            words, _, match = forced(samples, sr, text, ahead, False, on_mismatch, reporter, language)
        except FacegenError as exc:
            unaligned = _unaligned(exc, on_mismatch, reporter)
            if language != "en":
                return Timing([], NONE, match=unaligned)
            heard = recognition.hear(samples, sr)
            return Timing(heard.words, RECOGNISED, match=unaligned, confidences=heard.confidences)
        return Timing(words, FORCED, match=match)
    if language != "en":
        reporter.note(_NO_WORDS.format(language=language))
        return Timing([], NONE)
    reporter.note("no transcript given: recognising the words with pocketsphinx (lower quality than with a "
                  "transcript; give the transcript or an alignment file for better upper-face motion)")
    heard = recognition.hear(samples, sr)
    return Timing(heard.words, RECOGNISED, confidences=heard.confidences)


_NO_WORDS = ("no transcript in {language}: the lips follow the audio alone (the recogniser knows English "
             "only: give the transcript for lips and brows that follow the words)")
FOREIGN_SHARE = 0.25  # of the words missing from the English dictionary: another language (fr 0.47, es 0.31)


def forced(samples: np.ndarray, sr: int, text: str, ahead: AlignAhead | Aligned | None, with_phones: bool,
           on_mismatch: str = "error", reporter: Reporter = SILENT,
           language: str = "en") -> tuple[list, list | None, Match]:
    """Forced alignment of `text`: its words, phones (if `with_phones`) and Match (facegen.transcript_match) —
    the answer of the process started ahead, else aligned here (also when that process gave no answer).
    A transcript that does not match the speech is refused (`on_mismatch` "error") or animated with a
    warning ("warn"); one whose words cannot be placed at all is always refused."""
    from facegen import align
    from facegen.transcript_match import ON_MISMATCH, is_mismatch, mismatch, unaligned

    if on_mismatch not in ON_MISMATCH:
        raise FacegenError(f"unknown mismatch choice {on_mismatch!r}: use one of {', '.join(ON_MISMATCH)}",
                           param="on_mismatch")
    match = None
    try:
        found = ahead.result() if ahead is not None else None
        if found is None:
            done = align.align_checked(samples, sr, text, with_phones, language)
            found = done.words, done.phones, done.match
        words, phones, match = found
        if match.problem is not None and on_mismatch == "error":
            raise mismatch(match.problem)
    except FacegenError as exc:
        refusal = _foreign(exc, text) if language == "en" else exc
        if match is None and is_mismatch(exc):  # no alignment at all
            match = unaligned()
        if match is not None:  # a batch reports the refused line's score
            refusal.details = {"transcript_match": match.as_dict()}
        if refusal is exc:
            raise
        raise refusal from exc
    if match.problem is not None:
        reporter.note(f"the transcript may not match the speech ({match.problem}; match score "
                      f"{match.score:.2f}): animated with it as asked — check the transcript")
    return words, phones, match


def _foreign(exc: FacegenError, text: str) -> FacegenError:
    """A mismatch refusal, with a hint when many of the words are not English (FOREIGN_SHARE)."""
    from facegen import sphinx
    from facegen.transcript_match import is_mismatch

    if is_mismatch(exc) and sphinx.unknown_share(text) > FOREIGN_SHARE:
        return FacegenError(f"{exc}; many of its words are not English: pass the transcript's language with "
                            "--language (`facegen languages` lists them)", param=("text", "language"))
    return exc


def clip_words_and_phones(samples: np.ndarray, sr: int, num_frames: int, fps: float, *, text: str | None,
                          alignment, no_text: bool, reporter: Reporter,
                          ahead: AlignAhead | Aligned | None = None, on_mismatch: str = "error",
                          language: str = "en") -> Timing:
    """Words and per-frame phones for a model with a phone stream: pocketsphinx's phone alignment of the
    transcript; the words of an alignment file with its phones, or, where it has none, the phones aligned
    inside its word times (`alignment_phones`); or without a transcript (also with --no-text, which only drops
    the text features) the phone alignment of the recognised words."""
    from facegen.phonetics import silence

    if alignment is not None:
        words, phones, source = alignment_phones(samples, sr, alignment, reporter, language)
        return Timing(words, source, **_phones(phones, num_frames, fps))
    if text is not None and not no_text:
        _check_transcript(text)
        try:
            words, phones, match = forced(samples, sr, text, ahead, True, on_mismatch, reporter, language)
        except FacegenError as exc:
            unaligned = _unaligned(exc, on_mismatch, reporter)
            if language != "en":
                return Timing([], NONE, silence(num_frames), unaligned)
            timing = _heard_with_phones(samples, sr, num_frames, fps, no_text, reporter)
            timing.match = unaligned
            return timing
        return Timing(words, FORCED, match=match, **_phones(phones, num_frames, fps))
    if language != "en":
        if not no_text:
            reporter.note(_NO_WORDS.format(language=language))
        return Timing([], NONE, silence(num_frames))
    if not no_text:
        reporter.note("no transcript given: recognising the words with pocketsphinx (lower quality than with "
                      "a transcript; give the transcript or an alignment file for better lips and brows)")
    return _heard_with_phones(samples, sr, num_frames, fps, no_text, reporter)


def _unaligned(exc: FacegenError, on_mismatch: str, reporter: Reporter) -> Match:
    """A transcript whose words cannot be placed in the speech at all: refused (re-raised) unless
    `on_mismatch` is "warn", where the clip is animated from the recognised words instead, with a note, and
    this Match (score 0) flags it."""
    from facegen.transcript_match import UNALIGNED, is_mismatch, unaligned

    if on_mismatch != "warn" or not is_mismatch(exc):
        raise exc
    reporter.note(f"the transcript does not match the speech ({UNALIGNED}): animated from the words "
                  "recognised in the audio as asked — check the transcript")
    return unaligned()


def _heard_with_phones(samples: np.ndarray, sr: int, num_frames: int, fps: float, no_text: bool,
                       reporter: Reporter) -> Timing:
    """Without a transcript: the recogniser's words, force-aligned again for their phones."""
    from facegen import align, recognition
    from facegen.phonetics import silence

    heard = recognition.hear(samples, sr)
    try:
        words, phones = ((heard.words, heard.phones) if heard.phones is not None  # long audio: heard with it
                         else align.align_phones(samples, sr, " ".join(w.text for w in heard.words)))
        found = _phones(phones, num_frames, fps)
    except FacegenError:
        words, found = heard.words, {"phones": silence(num_frames)}
        reporter.note("no phones could be found in the audio without a transcript: the lips follow the audio "
                      "alone (give the transcript for better lip sync)")
    if not no_text:
        same = len(words) == len(heard.words)  # else a word the aligner split: the recogniser's times
        return Timing(words if same else heard.words, RECOGNISED, confidences=heard.confidences, **found)
    return Timing([], NONE, **found)


def _phones(phones, num_frames: int, fps: float) -> dict:
    """Timing's `phones` (one-hot per frame, the network's phone stream) and `phone_times` (CMU phones with
    their times) from aligned phones."""
    from facegen.phonetics import phone_frames, to_cmu

    times = to_cmu(phones)
    return {"phones": phone_frames(times, num_frames, fps), "phone_times": times}


def alignment_phones(samples: np.ndarray, sr: int, alignment: str | os.PathLike,
                     reporter: Reporter = SILENT, language: str = "en") -> tuple[list, list, str]:
    """The words of an alignment file, their phones and where those came from: the file's own (Gentle, an MFA
    TextGrid, `facegen align --phones`), else pocketsphinx's phone alignment inside the file's word times
    (facegen.phone_timing), with espeak-ng's pronunciations spread over the words that do not align (a note
    counts them)."""
    from facegen.alignment_files import read_alignment, read_phones
    from facegen.phone_timing import phones_in_word_times

    duration = len(samples) / sr
    words = read_alignment(alignment, duration=duration)
    known = read_phones(alignment, duration=duration, reporter=reporter)
    if not known:
        reporter.progress(f"aligning the phones inside the word times of {alignment} (pocketsphinx)")
    found = phones_in_word_times(samples, sr, words, known, language)
    if found.spread:
        reporter.note(f"{found.spread} of {len(words)} words of {alignment} could not be aligned inside "
                      "their times: their phones are spread over them from their pronunciation (check those "
                      "times)")
    return words, found.phones, FILE_PHONES_ALIGNED if found.aligned or found.spread else FILE
