"""A clip's words (and phones) in time, from whichever source the user gave: an alignment file, the forced
alignment of a transcript, or speech recognition without one.

The Animator (animator.py) asks here for the words of every clip it prepares, and `facegen align` for the
words it prints. The forced alignment itself is align.py's; what may have been started ahead in a process of
its own is align_ahead.py's (`ahead`: its `AlignAhead` or `Aligned`).
"""

from __future__ import annotations

import os

import numpy as np

from facegen.align_ahead import AlignAhead, Aligned
from facegen.errors import FacegenError
from facegen.runtime import SILENT, Reporter

FORCED, FILE, RECOGNISED, NONE = ("forced alignment", "alignment file", "speech recognition",
                                  "none (--no-text)")
FILE_PHONES_ALIGNED = "alignment file + phones aligned"  # a file's words, (some of) their phones aligned here


def force_aligned(text: str | None, alignment, no_text: bool) -> bool:
    """Whether a clip's words come from forced alignment of `text` (not an alignment file, not
    recognition)."""
    return text is not None and bool(text.strip()) and alignment is None and not no_text


def _check_transcript(text: str) -> None:
    if not text.strip():
        raise FacegenError("the transcript is empty: pass the words spoken", param="text")


def clip_words(samples: np.ndarray, sr: int, *, text: str | None = None,
               alignment: str | os.PathLike | None = None, reporter: Reporter = SILENT,
               ahead: AlignAhead | Aligned | None = None) -> tuple[list, str]:
    """Word timings for the clip and where they came from (alignment file, forced alignment, recognition);
    `ahead`: the forced alignment of `text` already started in a process of its own (align_ahead.py)."""
    from facegen import align
    from facegen.alignment_files import read_alignment

    if alignment is not None:
        return read_alignment(alignment, duration=len(samples) / sr), FILE
    if text is not None:
        _check_transcript(text)
        reporter.progress("aligning the transcript to the speech (pocketsphinx)")
        return forced(samples, sr, text, ahead, with_phones=False)[0], FORCED
    reporter.note("no transcript given: recognising the words with pocketsphinx (lower quality than with a "
                  "transcript; give the transcript or an alignment file for better upper-face motion)")
    return align.recognize(samples, sr), RECOGNISED


FOREIGN_SHARE = 0.25  # of the words missing from the English dictionary: another language (fr 0.47, es 0.31)


def forced(samples: np.ndarray, sr: int, text: str, ahead: AlignAhead | Aligned | None,
           with_phones: bool) -> tuple[list, list | None]:
    """Forced alignment of `text` (words, and phones if `with_phones`): the answer of the process started
    ahead, else aligned here (also when that process gave no answer)."""
    from facegen import align

    try:
        found = ahead.result() if ahead is not None else None
        if found is not None:
            return found
        if with_phones:
            return align.align_phones(samples, sr, text)
        return align.align(samples, sr, text), None
    except FacegenError as exc:  # words the English dictionary lacks: another language? say so
        if str(exc).startswith("the transcript does not match") and align.unknown_share(text) > FOREIGN_SHARE:
            raise FacegenError(f"{exc}; many of its words are not English: the aligner knows English only, "
                               "so align speech in another language with a tool for that language and pass "
                               "its word timings", param=("text", "alignment")) from exc
        raise


def clip_words_and_phones(samples: np.ndarray, sr: int, num_frames: int, fps: float, *, text: str | None,
                          alignment, no_text: bool, reporter: Reporter,
                          ahead: AlignAhead | Aligned | None = None) -> tuple[list, str, np.ndarray]:
    """Words and per-frame phones for a model with a phone stream: pocketsphinx's phone alignment of the
    transcript; the words of an alignment file with its phones, or, where it has none, the phones aligned
    inside its word times (`alignment_phones`); or without a transcript (also with --no-text, which only drops
    the text features) the phone alignment of the recognised words."""
    from facegen.phonetics import phone_frames, silence

    if alignment is not None:
        words, phones, source = alignment_phones(samples, sr, alignment, reporter)
        return words, source, phone_frames(phones, num_frames, fps)
    if text is not None and not no_text:
        _check_transcript(text)
        words, phones = forced(samples, sr, text, ahead, with_phones=True)
        return words, FORCED, phone_frames(phones, num_frames, fps)
    from facegen import align

    # no transcript: the recogniser's words, force-aligned again for their phones
    recognised = align.recognize(samples, sr)
    try:
        words, phones = align.align_phones(samples, sr, " ".join(w.text for w in recognised))
        found = phone_frames(phones, num_frames, fps)
    except FacegenError:
        words, found = recognised, silence(num_frames)
        reporter.note("no phones could be found in the audio without a transcript: the lips follow the audio "
                      "alone (give the transcript for better lip sync)")
    if not no_text:
        reporter.note("no transcript given: recognising the words with pocketsphinx (lower quality than with "
                      "a transcript; give the transcript or an alignment file for better lips and brows)")
        return words, RECOGNISED, found
    return [], NONE, found


def alignment_phones(samples: np.ndarray, sr: int, alignment: str | os.PathLike,
                     reporter: Reporter = SILENT) -> tuple[list, list, str]:
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
    found = phones_in_word_times(samples, sr, words, known)
    if found.spread:
        reporter.note(f"{found.spread} of {len(words)} words of {alignment} could not be aligned inside "
                      "their times: their phones are spread over them from their pronunciation (check those "
                      "times)")
    return words, found.phones, FILE_PHONES_ALIGNED if found.aligned or found.spread else FILE
