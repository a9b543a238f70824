"""Forced alignment with pocketsphinx: a transcript's words and phones in time
(recognition without a transcript is facegen.recognition's; the decoders, facegen.sphinx's).

What the recogniser hears comes from `facegen.words.normalize_transcript` (lower case, numbers spelled
out, stage directions left out), and every result maps back to the user's words. Words missing from
pocketsphinx's dictionary get a pronunciation from libespeak-ng (`facegen.espeak.pronounce`); a word written
in capitals may also be said letter by letter ("IAX", "SIP"): the search picks the one said.
The first word's start and the last word's end come from the audio (`facegen.align_pieces.speech_edges`).

Long audio is aligned piece by piece, cut at pauses (`facegen.align_pieces`; a piece that fails is retried
alone with wide beams). Every pass subtracts the whole clip's cepstral mean and starts with a fresh noise
estimate, so results never depend on earlier calls; each piece re-aligns the word before it, so the pieces
give the words and phones of one search over the clip; a piece that leaves loud speech outside its words lets
the next one skip words already said, which go back to it (re-synchronisation, in align_pieces).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facegen.align_pieces import (
    HOP,
    LOOKAHEAD,
    LOOKBEHIND,
    MAX_SEARCH,
    RATE,
    RESYNC_LOUD,
    RESYNC_WORDS,
    loud_frames,
    pieces,
    prefix_grammar,
    scored,
    skipped,
    speech_edges,
    unheld,
    word_window,
)
from facegen.errors import FacegenError
from facegen.phonetics import SIL, is_filler
from facegen.sphinx import (
    FRAME,
    LOCK,
    base_word,
    clip_cmn,
    decode,
    dictionary_word,
    get_decoder,
    pcm16k,
    pcm_bytes,
)
from facegen.transcript_match import UNALIGNED, Match, judge, mismatch, speech_snr_db
from facegen.words import Word, check_word_rate, no_words, spelled, spoken_words

Phone = tuple[str, float, float]  # (CMU phone without stress, start s, end s)


@dataclass
class Alignment:
    """A forced alignment: the transcript's words in time, their phones (with_phones) and how well the
    transcript matches the speech (facegen.transcript_match)."""

    words: list[Word]
    phones: list[Phone] | None
    match: Match


def state_pass(decoder, pcm: bytes, cmn: str):
    """pocketsphinx's second, state-level alignment pass over the word alignment it has just found."""
    decoder.set_alignment()
    decode(decoder, pcm, cmn)
    alignment = decoder.get_alignment()
    if alignment is None:
        raise mismatch("pocketsphinx found no phone alignment for its words")
    return alignment


def _state_gaps(alignment, n_frames: int) -> np.ndarray:
    """Per frame: how far the alignment's HMM state scores below the best state of that frame."""
    gaps = np.zeros(n_frames)
    for phone in alignment.phones():
        if phone.duration > 0:
            gaps[phone.start:phone.start + phone.duration] = -phone.score / phone.duration
    return gaps


def _free_gaps(pcm: bytes, n_frames: int, cmn: str) -> np.ndarray | None:
    """Per frame: how far the best unconstrained phone sequence scores below the best HMM state of that frame
    (its phone's acoustic score over its frames): the fit a matching transcript nearly reaches."""
    decoder = get_decoder("phone-loop")
    decoder.activate_search("_phones")
    if not decode(decoder, pcm, cmn):
        return None
    gaps = np.zeros(n_frames)
    for phone in decoder.seg():  # ascore is a probability; logmath.log gives pocketsphinx's log units back
        gaps[phone.start_frame:phone.end_frame + 1] = -decoder.logmath.log(phone.ascore) / (
            phone.end_frame - phone.start_frame + 1)
    return gaps


def align(audio: np.ndarray, sample_rate: int, transcript: str, language: str = "en") -> list[Word]:
    """Word start/end times (s) of `transcript` in `audio` (mono, any rate), by forced alignment.

    Returns one Word per written word of the transcript (words made only of punctuation are left
    out), in order, with the user's spelling. Raises FacegenError for an empty transcript, silent or
    too short audio, or a transcript that does not match the speech.
    """
    return checked(align_checked(audio, sample_rate, transcript, False, language)).words


def align_phones(audio: np.ndarray, sample_rate: int, transcript: str,
                 language: str = "en") -> tuple[list[Word], list[Phone]]:
    """The words of `align` and the phones inside them: (CMU phone without stress, start, end) in seconds,
    pauses left out — pocketsphinx's phone alignment of the same search (a second pass over the audio)."""
    found = checked(align_checked(audio, sample_rate, transcript, True, language))
    return found.words, found.phones


def checked(found: Alignment) -> Alignment:
    """`found`, or the refusal of its transcript when it does not match the speech."""
    if found.match.problem is not None:
        raise mismatch(found.match.problem)
    return found


def align_checked(audio: np.ndarray, sample_rate: int, transcript: str, with_phones: bool,
                  language=None) -> Alignment:
    """The words (and phones, `with_phones`) of `transcript` in `audio` and how well it matches the speech,
    without refusing a mismatch (its `match.problem` says what is wrong: `checked` refuses it). Raises
    FacegenError where no alignment exists (no words, silent or too short audio, words that cannot be placed).
    `language` (a code of facegen.languages; None: English): its words said with espeak-ng's pronunciation in
    that language, in these phones (sphinx.dictionary_word); its mismatch bound FOREIGN_WORD_GAP.
    """
    from facegen.languages import check_language

    language = check_language(language)
    foreign = language.code != "en"
    entries = spoken_words(transcript, language.code)
    if not entries:
        raise no_words(transcript)
    # (its word's index, token, its letters when it may be said letter by letter, or the voice it is said in)
    spoken = [(i, token, language.voice if foreign else spelled(word, token))
              for i, (word, tokens) in enumerate(entries) for token in tokens]
    check_word_rate(len(spoken), len(audio) / sample_rate, "the transcript")  # "1234": four words said
    audio = pcm16k(audio, sample_rate)
    pcm = pcm_bytes(audio)
    duration = len(audio) / RATE
    n_frames = len(audio) // HOP
    loud = loud_frames(audio, n_frames)
    spans = pieces(loud)
    chosen = scored(spans)
    words: list[tuple[str, int, int]] = []
    phones: list[list[Phone]] = []  # per word, with_phones
    gaps, free = np.full(n_frames, np.nan), np.full(n_frames, np.nan)
    with LOCK:
        cmn = clip_cmn(pcm)
        start, p = 0, 0
        before = before_start = 0  # the piece before's first word and frame (its re-synchronisation)
        no_skip = -1  # a piece whose skipped words could not be aligned with the piece before: tried without
        while p < len(spans) and len(words) < len(spoken):
            last = p == len(spans) - 1
            cut = spans[p][1]
            stop = n_frames if last else min(n_frames, cut + LOOKAHEAD)
            resync = p != no_skip and unheld(loud, words[before:], start) >= RESYNC_LOUD
            # the piece before's last word aligned again (LOOKBEHIND in align_pieces), unless re-synchronising
            back = 1 if words and not resync else 0
            origin = start if resync else max(0, words[-1][1] - LOOKBEHIND) if words else 0  # search's start
            part = pcm[origin * HOP * 2:stop * HOP * 2]
            found = align_piece(part, [(t, s) for _, t, s in spoken[len(words) - back:]], stop - origin,
                                n_frames - origin, cmn, not last, RESYNC_WORDS if resync else 0)
            if found is None or len(found[1]) <= back:
                if last or spans[p + 1][1] - start > MAX_SEARCH:
                    raise mismatch(UNALIGNED)
                chosen = {i - (i > p) for i in chosen}
                # a piece whose words cannot be told apart: aligned with the next one (not with all the rest:
                # a search's time and its state pass's memory grow with its length times its words)
                spans[p:p + 2] = [(start, spans[p + 1][1])]
                continue
            decoder, segments, skip = found
            kept = segments[back:] if last else [s for s in segments[back:] if s[1] < cut - origin]
            if kept and words and kept[0][1] + origin <= words[-1][2]:  # never before the word before ends
                kept[0] = (kept[0][0], words[-1][2] + 1 - origin, max(kept[0][2], words[-1][2] + 1 - origin))
            end = n_frames if last else max(cut, origin + (kept[-1][2] + 1 if kept else 0))
            piece_phones = []
            if kept and (with_phones or p in chosen):
                alignment = _piece_states(decoder, part, segments[:back + len(kept)], end - origin, cmn, last)
                if with_phones:
                    piece_phones = word_phones(alignment, back, len(kept), origin, duration)
                if p in chosen:
                    _score(alignment, pcm, decoder.n_frames(), origin, start, end, cmn, gaps, free)
            if skip:  # words said in the piece before: aligned again with it, up to this piece's first word
                after = words[before - 1][2] + 1 if before else 0  # the word before that piece ends
                redone = _piece_again(pcm, spoken[before:len(words) + skip], after,
                                      kept[0][1] + origin if kept else end, cmn, with_phones,
                                      (before_start, gaps, free) if p - 1 in chosen else None)
                if redone is None:
                    no_skip = p
                    continue
                words[before:], again = redone
                if with_phones:
                    phones[before:] = again
            words += [(w, a + origin, b + origin) for w, a, b in kept]
            phones += piece_phones
            before, before_start, start, p = len(words) - len(kept), start, end, p + 1
    if len(words) < len(spoken):
        raise mismatch(UNALIGNED)
    # the outer edges from the audio (align_pieces.speech_edges); a word whose edge moves is scored over its
    # new bounds as the search placed them (the frames it gave to silence fit worse), and its phones come from
    # aligning it again inside them
    first, last = words[0][1], words[-1][2]
    start, end = speech_edges(loud, first, last)
    words[0] = (words[0][0], start, words[0][2])
    words[-1] = (words[-1][0], words[-1][1], end)
    match = judge(loud, words, gaps, free, speech_snr_db(audio), foreign=foreign)
    moved = {k for k, edge in ((0, start != first), (len(words) - 1, end != last))
             if edge and with_phones and len(phones) == len(words)}
    for k in moved:
        with LOCK:
            alignment = _word_alone(pcm, spoken[k][1:], words[k][1], words[k][2] + 1, cmn)
            again = [] if alignment is None else word_phones(alignment, 0, 1, words[k][1], duration)
            phones[k] = again[0] if again else phones[k]
    times: dict[int, list[float]] = {}
    for (index, _, _), (_, first, last) in zip(spoken, words, strict=True):
        start, end = first * FRAME, min((last + 1) * FRAME, duration)
        times.setdefault(index, [start, end])[1] = end
    return Alignment([Word(entries[i][0], round(t[0], 3), round(t[1], 3)) for i, t in sorted(times.items())],
                     [phone for word in phones for phone in word] if with_phones else None, match)


def _word_alone(pcm: bytes, token: tuple[str, list[str] | None], first: int, end: int, cmn: str):
    """The state alignment of the clip's first or last word (`token` and its letters) over its frames `first`
    to `end` (excluded), whose outer edge came from the audio (align_pieces.speech_edges): aligned again over
    just those frames, without silence, so that its sounds share them as said (the /s/ of "six" its 150 ms,
    not one frame); None if pocketsphinx finds none."""
    decoder = get_decoder("align-nofiller")
    decoder.set_align_text(dictionary_word(decoder, *token))
    part = pcm[first * HOP * 2:end * HOP * 2]
    if not decode(decoder, part, cmn):
        return None
    try:
        return state_pass(decoder, part, cmn)
    except (FacegenError, RuntimeError):
        return None


def align_piece(pcm: bytes, tokens: list[tuple[str, list[str] | None]], length: int, rest: int, cmn: str,
                prefix: bool, skippable: int = 0) -> tuple[object, list[tuple[str, int, int]], int] | None:
    """Align one piece: all of `tokens` (each with its letters, if it may be spelled), or (`prefix`) as many
    of the first of them as its speech holds, possibly (`skippable`) after skipping up to that many of them.

    Tries the decoders of _CONFIGS in turn (wide beams only when the first fails; a grammar never without
    fillers, it would have nothing else for a pause); returns the decoder that aligned it (its search still
    holds the alignment), the words (dictionary word, first frame, last frame in the piece) and how many
    tokens it skipped, or None. A prefix that takes every word it was offered is offered them all.
    """
    offers = [word_window(len(tokens), length, rest), len(tokens)] if prefix else [len(tokens)]
    grammar = prefix or skippable > 0
    for kind in ("align", "align-wide") if grammar else ("align", "align-wide", "align-nofiller"):
        decoder = get_decoder(kind)
        for offered in offers:
            keys = [dictionary_word(decoder, token, letters) for token, letters in tokens[:offered]]
            if grammar:
                decoder.add_fsg("_prefix", prefix_grammar(decoder, "_prefix", keys, prefix, skippable))
                decoder.activate_search("_prefix")
            else:
                decoder.set_align_text(" ".join(keys))
            words = [s for s in decode(decoder, pcm, cmn) if not is_filler(s[0])]
            skip = skipped([base_word(w) for w, _, _ in words], keys, skippable, whole=not prefix)
            if skip is not None:
                if skip + len(words) < offered or offered == len(tokens):
                    return decoder, words, skip
            elif not prefix or not words:
                break
    return None


def _piece_again(pcm: bytes, tokens: list, first: int, end: int, cmn: str, with_phones: bool, score):
    """The words (dictionary word, first frame, last frame) of the piece before a re-synchronised one
    (align_pieces), `tokens` (index, token, letters) forced over its frames from `first` to `end` (excluded),
    and their phones (with_phones); None when they cannot be aligned there. `score`: None, or (the piece's
    first frame, gaps, free) to fill again for a scored piece (`_score`)."""
    part = pcm[first * HOP * 2:end * HOP * 2]
    found = align_piece(part, [(t, s) for _, t, s in tokens], end - first, end - first, cmn, prefix=False)
    if found is None or len(found[1]) != len(tokens):
        return None
    decoder, segments, _ = found
    phones = []
    if with_phones or score:
        try:
            alignment = state_pass(decoder, part, cmn)
        except (FacegenError, RuntimeError):
            return None
        if with_phones:
            phones = word_phones(alignment, 0, len(tokens), first, len(pcm) / 2 / RATE)
        if score:
            _score(alignment, pcm, decoder.n_frames(), first, score[0], end, cmn, score[1], score[2])
    return [(w, a + first, b + first) for w, a, b in segments], phones


def _score(alignment, pcm: bytes, searched: int, origin: int, start: int, end: int, cmn: str,
           gaps: np.ndarray, free: np.ndarray) -> None:
    """Fill `gaps` and `free` (facegen.transcript_match) from `start` to `end` with a scored piece's state
    gaps (`alignment` of a search over `searched` frames from `origin`) and the free phone loop's."""
    n = min(searched + origin, end) - start
    gaps[start:start + n] = _state_gaps(alignment, searched)[start - origin:][:n]
    piece_free = _free_gaps(pcm[start * HOP * 2:end * HOP * 2], n, cmn)
    free[start:start + n] = gaps[start:start + n] if piece_free is None else piece_free[:n]


def _piece_states(decoder, pcm: bytes, kept: list[tuple[str, int, int]], length: int, cmn: str, last: bool):
    """The state alignment of a piece (`pcm`, its lookbehind and lookahead included) whose words `decoder` has
    just aligned; `kept`: its words up to the cut (the lookbehind's word first).

    The state pass follows all the words the search placed, those of the lookahead too, over the audio they
    cover: the words at the cut get the phones of one search over the clip. The search may have stopped inside
    the lookahead's last word, which the state pass then cannot place (pocketsphinx: "Failed to stop utterance
    processing"); then the kept words are aligned again alone, over the piece's first `length` frames."""
    if not last:
        covered = max(s.end_frame for s in decoder.seg()) + 1
        try:
            return state_pass(decoder, pcm[:covered * HOP * 2], cmn)
        except RuntimeError:
            pcm = pcm[:length * HOP * 2]
            decoder.set_align_text(" ".join(w for w, _, _ in kept))
            decode(decoder, pcm, cmn)
    try:
        return state_pass(decoder, pcm, cmn)
    except RuntimeError:  # its words do not fit the frames (seen: a 9-syllable Thai word over another line)
        raise mismatch("pocketsphinx found no phone alignment for its words") from None


def word_phones(alignment, skip: int, count: int, first: int, duration: float) -> list[list[Phone]]:
    """The phones of `count` words of a piece's state alignment after its first `skip` words (`first`: the
    frame the piece's search started at). Read while iterating: an entry of pocketsphinx's alignment is only
    valid while its iterator is."""
    phones: list[list[Phone]] = []
    for word in alignment:
        if count == 0:
            break
        if is_filler(word.name):
            continue
        if skip:
            skip -= 1
            continue
        count -= 1
        phones.append([(phone.name, round((first + phone.start) * FRAME, 3),
                        round(min((first + phone.start + phone.duration) * FRAME, duration), 3))
                       for phone in word if phone.name != SIL])
    return phones

