"""Scripts as they are written (stage directions, acronyms said as letters, numbers of any size) and short
clips (one word, under a second) through the real aligner."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from facegen.align import align, align_phones
from facegen.audio import load_audio, resample
from facegen.errors import FacegenError
from facegen.espeak import synthesize
from facegen.words import normalize_transcript, spelled, split_directions

ALSA = Path("/usr/share/sounds/alsa")  # real recorded speech (Debian's alsa-utils): "Front Center", ...
# a real recorded 8 kHz voice-prompt library (Debian's asterisk-core-sounds-en-wav); only its odd-numbered
# lines (sorted by name) are used here: the even ones are kept for a held-out check
ASTERISK = Path("/usr/share/asterisk/sounds/en")
needs_alsa = pytest.mark.skipif(not (ALSA / "Noise.wav").exists(), reason="apt-get install alsa-utils")
needs_asterisk = pytest.mark.skipif(not (ASTERISK / "digits/6.wav").exists(),
                                    reason="apt-get install asterisk-core-sounds-en-wav")

# ---------------------------------------------------------------------------- stage directions


@pytest.mark.parametrize(("text", "spoken", "directions"), [
    ("Please leave your message after the tone. (simple tone sound plays)",
     "Please leave your message after the tone.", ["(simple tone sound plays)"]),
    ('IAX (note: does not say "2")', "IAX", ['(note: does not say "2")']),
    ("(laughs) Well, [tone] here <beep> we *sighs* go {music}",
     "Well, here we go", ["(laughs)", "[tone]", "<beep>", "*sighs*", "{music}"]),
    ("yes(laughs)no", "yes no", ["(laughs)"]),
    ("[door slams\n  loudly (off screen)] Hi", "Hi", ["[door slams loudly (off screen)]"]),
    ("It costs (50%) less, 3 * 4 is 12, a < b, 2 > 1", "It costs (50%) less, 3 * 4 is 12, a < b, 2 > 1", []),
    ("an (unclosed bracket", "an (unclosed bracket", []),
])
def test_stage_directions_are_set_apart(text, spoken, directions):
    got_spoken, got_directions = split_directions(text)
    assert " ".join(got_spoken.split()) == spoken
    assert got_directions == directions


def test_unclosed_brackets_cost_linear_time():
    """One pass over the brackets: a million unclosed ones (a quadratic scan would take hours) open nothing,
    and a balanced direction inside an unclosed bracket is still one."""
    assert split_directions("(" * 1_000_000 + " hi") == ("(" * 1_000_000 + " hi", [])
    assert split_directions("<" * 1_000_000 + "x") == ("<" * 1_000_000 + "x", [])
    assert split_directions("so (he says [quietly] yes") == ("so (he says   yes", ["[quietly]"])


def test_stage_directions_never_reach_the_aligner():
    assert normalize_transcript("Press one (beep) now [tone] *sighs*") == [
        ("Press", ["press"]), ("one", ["one"]), ("now", ["now"])]
    assert normalize_transcript("a (50%) rise") == [("a", ["a"]), ("50%", ["fifty", "percent"]),
                                                    ("rise", ["rise"])]


@pytest.mark.parametrize("text", ["(laughs)", "  [tone]  <beep> ", "*sighs*", "(simple tone sound plays)."])
def test_a_transcript_of_stage_directions_only_has_its_own_message(text):
    speech = synthesize("hello there")
    with pytest.raises(FacegenError, match=r"only a stage direction.*no spoken word") as info:
        align(speech.audio, speech.sample_rate, text)
    assert info.value.param == "text" and "\n" not in str(info.value)
    assert split_directions(text)[1][0] in str(info.value)


# ---------------------------------------------------------------------------- numbers

BIG = "7" * 5000


@pytest.mark.parametrize(("word", "spoken"), [
    (BIG, ["seven"] * 5000), (BIG + "th", ["seven"] * 4999 + ["seventh"]),
    (BIG[:-1] + "0s", ["seven"] * 4999 + ["zeros"]), (BIG + "%", ["seven"] * 5000 + ["percent"]),
    ("$" + BIG, ["seven"] * 5000 + ["dollars"]),
    ("$" + BIG + "k", ["seven"] * 5000 + ["thousand", "dollars"]),
    ("0" * 5000, ["zero"] * 5000), ("1" + "0" * 15, ["one"] + ["zero"] * 15),
    ("1" + "0" * 14, ["one", "hundred", "trillion"]),
    ("①", ["one"]), ("⑩", ["ten"]), ("²", ["two"]), ("1½", ["one", "one", "half"]),
    ("¾", ["three", "quarters"]), ("Ⅻ", ["twelve"]), ("m²", ["m", "two"]), ("⓪", ["zero"]),
])
def test_numbers_of_any_size_and_sign_are_said(word, spoken):
    assert normalize_transcript(word) == [(word, spoken)]


def test_a_huge_number_is_a_user_error_not_an_internal_one():
    speech = synthesize("seven seven seven")
    for word in (BIG, BIG + "th", BIG + "%", "$" + BIG):
        with pytest.raises(FacegenError, match="words for"):
            align(speech.audio, speech.sample_rate, word)


# ---------------------------------------------------------------------------- acronyms


def test_capitals_may_be_spelled():
    assert spelled("IAX", "iax") == ["i.", "a.", "x."]
    assert spelled("R&D", "r") == ["r."]
    assert spelled("SIP-based", "sip") == ["s.", "i.", "p."] and spelled("SIP-based", "based") is None
    assert spelled("sip", "sip") is None and spelled("COVID-19", "nineteen") is None
    assert spelled("INTERNATIONAL", "international") is None  # long words in capitals are shouted words


@pytest.mark.parametrize(("said", "written"), [("I A X", "IAX"), ("S I P", "SIP"), ("sip", "SIP"),
                                                ("I A X please", "IAX please")])
def test_an_acronym_aligns_as_letters_or_as_a_word(said, written):
    speech = synthesize(said, voice="en-us", rate=150)
    pad = np.zeros(int(0.3 * speech.sample_rate), np.float32)
    words, phones = align_phones(np.concatenate([pad, speech.audio, pad]), speech.sample_rate, written)
    assert [w.text for w in words] == written.split()
    first = words[0]
    truth = speech.words[len(said.split()) - len(written.split())]  # the acronym's last spoken part
    assert abs(first.start - 0.3 - speech.words[0].start) < 0.06
    assert abs(first.end - 0.3 - truth.end) < 0.08
    letters = [p for p, a, _ in phones if a < first.end]
    if said.startswith("I A X"):
        assert letters[:2] == ["AY", "EY"], letters  # I, A: said as letters


# ---------------------------------------------------------------------------- short clips


def telephone(audio: np.ndarray, rate: int) -> np.ndarray:
    """`audio` as a telephone line carries it: through 8 kHz and back (nothing above 4 kHz)."""
    return resample(resample(audio, rate, 8000), 8000, rate)


@pytest.mark.parametrize("word", ["six", "sixth", "press", "e", "tick", "yes"])
@pytest.mark.parametrize("voice", ["en-us", "en+f3"])
def test_a_lone_word_in_telephone_audio_aligns_where_it_is_said(word, voice):
    """In telephone audio the acoustic model hears a lone word's /s/ or aspiration as silence: its bounds come
    from the audio (before: "six" and "press" were refused, their words starting up to 0.3 s late)."""
    speech = synthesize(word, voice=voice)
    pad = np.zeros(int(0.15 * speech.sample_rate), np.float32)
    audio = telephone(np.concatenate([pad, speech.audio, pad]), speech.sample_rate)
    words, phones = align_phones(audio, speech.sample_rate, word)
    assert [w.text for w in words] == [word]
    assert abs(words[0].start - 0.15 - speech.words[0].start) < 0.06
    assert words[0].end - 0.15 > speech.words[0].end - 0.05
    assert phones[0][1] == words[0].start and phones[-1][2] <= words[0].end + 1e-6


@needs_asterisk
@pytest.mark.parametrize(("name", "text", "index", "phone", "start", "end"), [
    ("digits/6", "six", 0, "S", 0.13, 0.30), ("letters/ascii39", "tick", 0, "T", 0.085, 0.15),
    ("letters/e", "e", 0, "IY", 0.105, None), ("vm-press", "press", -1, "S", 0.38, 0.58),
    ("spy-iax2", 'IAX (note: does not say "2")', 0, "AY", 0.10, None),
    ("digits/h-6", "sixth", -1, "TH", None, 0.75),
])
def test_real_one_word_prompts_align(name, text, index, phone, start, end):
    """Recorded telephone prompts that were refused ("66 % of the speech lies outside its words"), against
    their spectrograms: "six"'s /s/ lasts from 0.13 to 0.30 s, "press"'s from 0.38 to 0.58 s, the burst of
    "tick" is at 0.085 s."""
    audio, rate = load_audio(ASTERISK / f"{name}.wav")
    words, phones = align_phones(audio, rate, text)
    assert len(words) == 1 and phones[index][0] == phone, phones
    assert start is None or abs(phones[index][1] - start) <= 0.03, phones
    assert end is None or abs(phones[index][2] - end) <= 0.03, phones


@needs_asterisk
def test_real_prompts_with_the_wrong_script_are_refused():
    audio, rate = load_audio(ASTERISK / "digits/6.wav")
    with pytest.raises(FacegenError, match="does not match the speech"):
        align(audio, rate, "Please leave your message after the tone.")
    audio, rate = load_audio(ASTERISK / "vm-intro.wav")  # "Please leave your message after the tone. ..."
    with pytest.raises(FacegenError, match="does not match the speech"):
        align(audio, rate, "They have been carried away by monkeys.")


@needs_alsa
@pytest.mark.parametrize("name", ["Front_Center", "Front_Left", "Rear_Right", "Side_Left"])
def test_real_short_recordings_align(name):
    audio, rate = load_audio(ALSA / f"{name}.wav")
    words = align(audio, rate, name.replace("_", " "))
    assert [w.text for w in words] == name.split("_")
    assert words[0].start < 0.1 and words[1].end > len(audio) / rate - 0.25


@needs_alsa
@pytest.mark.parametrize("text", ["Front Center", "six", "hello there", "noise"])
def test_noise_stays_refused(text):
    audio, rate = load_audio(ALSA / "Noise.wav")
    with pytest.raises(FacegenError, match="does not match the speech"):
        align(audio, rate, text)
