"""Long audio's pieces re-synchronise (facegen.align_pieces): a piece searched after words that were already
said skips them, and the words it skipped are aligned again with the piece before. Real pocketsphinx on
espeak-ng speech."""

from __future__ import annotations

import numpy as np
import pytest

from facegen import align, align_pieces
from facegen.align_pieces import HOP, RATE, skipped, unheld
from facegen.espeak import synthesize
from facegen.sphinx import LOCK, base_word, clip_cmn, pcm_bytes

FIRST = "the quick brown fox jumps over the lazy dog near the river bank"
SECOND = "please leave your message after the tone and then hang up the phone"
THIRD = "seven green bottles were standing on the kitchen wall this morning"


def _said(text: str, variant: str = "m1") -> np.ndarray:
    return synthesize(text, variant=variant, sample_rate=RATE).audio


@pytest.fixture(scope="module")
def three_lines() -> tuple[np.ndarray, list[float]]:
    """Three sentences of 16 kHz speech, each followed by 0.8 s of quiet (three pieces: PIECE_SECONDS is
    lowered by the tests that need it), and where each starts (s)."""
    quiet = np.full(int(0.8 * RATE), 1e-4, np.float32)
    parts, starts, total = [], [], 0
    for text, variant in ((FIRST, "m1"), (SECOND, "f3"), (THIRD, "m3")):
        said = _said(text, variant)
        starts.append(total / RATE)
        parts += [said, quiet]
        total += len(said) + len(quiet)
    return np.concatenate(parts), starts


def test_skipped_counts_the_words_a_search_left_out_at_its_start():
    keys = ["a", "b", "c", "d", "e"]
    assert skipped(["a", "b"], keys, 0, whole=False) == 0
    assert skipped(["c", "d"], keys, 3, whole=False) == 2
    assert skipped(["c", "d"], keys, 1, whole=False) is None  # skips more than allowed
    assert skipped(["c", "d", "e"], keys, 3, whole=True) == 2
    assert skipped(["c", "d"], keys, 3, whole=True) is None  # must reach the end
    assert skipped(["b", "d"], keys, 3, whole=False) is None  # a word left out inside
    assert skipped([], keys, 3, whole=False) is None


def test_unheld_counts_loud_frames_outside_the_words():
    loud = np.zeros(100, bool)
    loud[10:60] = True
    words = [("a", 10, 19), ("b", 25, 34)]
    assert unheld(loud, words, 60) == 5 + 25  # 20-24 and 35-59
    assert unheld(loud, words, 35) == 5
    assert unheld(loud, [], 60) == 0


def test_a_search_after_words_already_said_skips_them(three_lines):
    """The second line's audio searched for the first line's last four words and then its own: with skips
    allowed, the search starts at the second line's words and says it skipped four."""
    audio, starts = three_lines
    second = audio[int(starts[1] * RATE):int(starts[2] * RATE)]
    tokens = [(w, None) for w in FIRST.split()[-4:] + SECOND.split()]
    with LOCK:
        pcm = pcm_bytes(second)
        cmn = clip_cmn(pcm)
        found = align.align_piece(pcm, tokens, len(second) // HOP, len(second) // HOP, cmn, prefix=True,
                                  skippable=10)
        assert found is not None
        _, words, skip = found
        assert skip == 4
        assert [base_word(w) for w, _, _ in words] == SECOND.split()[:len(words)]
        assert len(words) >= 10
        # without skips the same search cannot start at the audio's words: it must place the four first
        plain = align.align_piece(pcm, tokens, len(second) // HOP, len(second) // HOP, cmn, prefix=True)
    assert plain is None or plain[2] == 0 and [base_word(w) for w, _, _ in plain[1]][:4] == FIRST.split()[-4:]


def test_resynchronising_every_piece_keeps_the_words_where_they_are(three_lines, monkeypatch):
    """Every piece re-synchronised (RESYNC_LOUD 0: the next piece searched from the cut, skips allowed) gives
    the words of the plain search, within 60 ms, and each line's first word where the line starts."""
    audio, starts = three_lines
    text = f"{FIRST} {SECOND} {THIRD}"
    monkeypatch.setattr(align_pieces, "PIECE_SECONDS", 3.0)
    plain, plain_phones = align.align_phones(audio, RATE, text)
    monkeypatch.setattr(align, "RESYNC_LOUD", 0)
    words, phones = align.align_phones(audio, RATE, text)
    assert [w.text for w in words] == text.split()
    assert max(abs(a.start - b.start) for a, b in zip(words, plain, strict=True)) < 0.06
    assert max(abs(a.end - b.end) for a, b in zip(words, plain, strict=True)) < 0.06
    firsts = [words[0].start, words[len(FIRST.split())].start, words[len(f"{FIRST} {SECOND}".split())].start]
    assert np.allclose(firsts, starts, atol=0.12)
    assert len(phones) == len(plain_phones)


def test_a_piece_that_gave_its_last_words_to_fillers_hands_them_back(three_lines, monkeypatch):
    """The failure re-synchronisation mends, made on purpose: the first piece's search is cut at the second
    line's start but only offered the first line's words minus its last four (their speech unheld: filler),
    so the second piece starts with four words already said. The alignment still puts every word of each
    line on that line's audio."""
    audio, starts = three_lines
    text = f"{FIRST} {SECOND} {THIRD}"
    monkeypatch.setattr(align_pieces, "PIECE_SECONDS", 3.0)
    real = align.align_piece
    first_words = len(FIRST.split())

    def short_first(pcm, tokens, length, rest, cmn, prefix, skippable=0):
        if len(tokens) == len(text.split()):  # the first piece: offered only what it then takes
            tokens = tokens[:first_words - 4]
            return real(pcm, tokens, length, rest, cmn, False, skippable)
        return real(pcm, tokens, length, rest, cmn, prefix, skippable)

    monkeypatch.setattr(align, "align_piece", short_first)
    words = align.align(audio, RATE, text)
    assert [w.text for w in words] == text.split()
    lines = [words[:first_words], words[first_words:first_words + len(SECOND.split())],
             words[first_words + len(SECOND.split()):]]
    for k, line in enumerate(lines):
        end = starts[k + 1] if k + 1 < len(starts) else len(audio) / RATE
        assert starts[k] - 0.12 <= line[0].start and line[-1].end <= end, (k, line[0], line[-1])
