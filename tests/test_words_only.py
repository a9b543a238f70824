"""Alignment files with words but no phones: the phones read where a file carries them (Gentle JSON, an MFA
TextGrid), aligned inside the file's word times where it does not (facegen.phone_timing), so that every model,
the phone-stream models included, animates from every alignment format."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
import soundfile as sf

from facegen.alignment_files import ALIGNMENT_FORMATS, read_alignment, read_phones, write_alignment
from facegen.errors import FacegenError
from facegen.phone_timing import phones_in_word_times
from facegen.phonetics import INDEX, espeak_to_cmu
from facegen.runtime import Reporter
from facegen.word_timing import FILE, FILE_PHONES_ALIGNED, alignment_phones, clip_words_and_phones
from facegen.words import Word

# What Gentle (lowerquality/gentle) writes for "Such expensive furnishings, Bob!": Kaldi's CMU phones in lower
# case with the phone's place in the word (_B begin, _I inside, _E end, _S a word of one phone), durations
# from the word's start; a word its dictionary lacks is "<unk>" with one "oov_S" phone; a word it did not hear
# has no times.
GENTLE = {
    "transcript": "Such expensive furnishings, Bob!",
    "words": [
        {"alignedWord": "such", "case": "success", "end": 0.62, "endOffset": 4, "startOffset": 0,
         "phones": [{"duration": 0.1, "phone": "s_B"}, {"duration": 0.09, "phone": "ah_I"},
                    {"duration": 0.13, "phone": "ch_E"}], "start": 0.3, "word": "Such"},
        {"alignedWord": "expensive", "case": "success", "end": 1.31, "endOffset": 14, "startOffset": 5,
         "phones": [{"duration": 0.06, "phone": "ih_B"}, {"duration": 0.08, "phone": "k_I"},
                    {"duration": 0.09, "phone": "s_I"}, {"duration": 0.07, "phone": "p_I"},
                    {"duration": 0.1, "phone": "eh_I"}, {"duration": 0.06, "phone": "n_I"},
                    {"duration": 0.08, "phone": "s_I"}, {"duration": 0.05, "phone": "ih_I"},
                    {"duration": 0.07, "phone": "v_E"}], "start": 0.65, "word": "expensive"},
        {"alignedWord": "<unk>", "case": "success", "end": 2.0, "endOffset": 26, "startOffset": 15,
         "phones": [{"duration": 0.62, "phone": "oov_S"}], "start": 1.38, "word": "furnishings"},
        {"case": "not-found-in-audio", "endOffset": 31, "startOffset": 28, "word": "Bob"},
    ],
}


def _interval_tier(name: str, intervals: list[tuple[float, float, str]], end: float) -> str:
    lines = ['        class = "IntervalTier"', f'        name = "{name}"', "        xmin = 0",
             f"        xmax = {end}", f"        intervals: size = {len(intervals)}"]
    for k, (a, b, label) in enumerate(intervals, 1):
        lines += [f"        intervals [{k}]:", f"            xmin = {a}", f"            xmax = {b}",
                  f'            text = "{label}"']
    return "\n".join(lines)


def mfa_textgrid(speakers: dict[str, tuple[list, list]], end: float = 2.4) -> str:
    """A TextGrid as the Montreal Forced Aligner writes it (long text format): a words and a phones tier per
    speaker ("words"/"phones" for one, "<speaker> - words"/"<speaker> - phones" for several), empty intervals
    for pauses."""
    tiers = []
    for speaker, (words, phones) in speakers.items():
        prefix = f"{speaker} - " if len(speakers) > 1 else ""
        tiers += [(prefix + "words", words), (prefix + "phones", phones)]
    head = ['File type = "ooTextFile"', 'Object class = "TextGrid"', "", "xmin = 0", f"xmax = {end}",
            "tiers? <exists>", f"size = {len(tiers)}", "item []:"]
    body = [f"    item [{n}]:\n" + _interval_tier(name, items, end)
            for n, (name, items) in enumerate(tiers, 1)]
    return "\n".join(head + body) + "\n"


# "Such expensive furnishings" aligned by MFA's english_us_arpa model: ARPAbet with stress digits, "" for
# pauses, "spn" (spoken noise) for a word its dictionary lacks
MFA_WORDS = [(0, 0.3, ""), (0.3, 0.62, "such"), (0.62, 0.65, ""), (0.65, 1.31, "expensive"),
             (1.31, 1.38, ""), (1.38, 2.0, "furnishings"), (2.0, 2.4, "")]
MFA_PHONES = [(0, 0.3, ""), (0.3, 0.4, "S"), (0.4, 0.49, "AH1"), (0.49, 0.62, "CH"), (0.62, 0.65, ""),
              (0.65, 0.71, "IH0"), (0.71, 0.79, "K"), (0.79, 0.88, "S"), (0.88, 0.95, "P"),
              (0.95, 1.05, "EH1"), (1.05, 1.11, "N"), (1.11, 1.19, "S"), (1.19, 1.24, "IH0"),
              (1.24, 1.31, "V"), (1.31, 1.38, ""), (1.38, 2.0, "spn"), (2.0, 2.4, "")]
EXPECTED = [("S", 0.3, 0.4), ("AH", 0.4, 0.49), ("CH", 0.49, 0.62), ("IH", 0.65, 0.71), ("K", 0.71, 0.79),
            ("S", 0.79, 0.88), ("P", 0.88, 0.95), ("EH", 0.95, 1.05), ("N", 1.05, 1.11), ("S", 1.11, 1.19),
            ("IH", 1.19, 1.24), ("V", 1.24, 1.31)]


def assert_phones(got, expected):
    assert [p for p, _, _ in got] == [p for p, _, _ in expected]
    np.testing.assert_allclose([t for _, a, b in got for t in (a, b)],
                               [t for _, a, b in expected for t in (a, b)], atol=1e-9)


# --------------------------------------------------------------------------- reading the phones files carry

def test_the_table_says_which_formats_carry_phones():
    assert {f.name: f.phones for f in ALIGNMENT_FORMATS} == {
        "JSON": True, "Gentle JSON": True, "WhisperX JSON": False, "TextGrid": True, "CSV": False}


def test_gentle_phones_are_read_per_word_and_unknown_words_have_none(tmp_path):
    path = tmp_path / "gentle.json"
    path.write_text(json.dumps(GENTLE, indent=4, sort_keys=True))
    assert [(w.text, w.start, w.end) for w in read_alignment(path, duration=2.4)] == [
        ("Such", 0.3, 0.62), ("expensive", 0.65, 1.31), ("furnishings", 1.38, 2.0)]
    assert_phones(read_phones(path, duration=2.4), EXPECTED)  # nothing for "<unk>" furnishings


@pytest.mark.parametrize("speakers", [1, 2])
def test_mfa_textgrid_phones_tier_is_read_for_the_words_speaker(tmp_path, speakers):
    other = ([(0, 1.0, ""), (1.0, 1.5, "bob"), (1.5, 2.4, "")],
             [(0, 1.0, ""), (1.0, 1.1, "B"), (1.1, 1.4, "AA1"), (1.4, 1.5, "B"), (1.5, 2.4, "")])
    tiers = {"anna": (MFA_WORDS, MFA_PHONES), "bert": other} if speakers == 2 else {"anna": (MFA_WORDS,
                                                                                             MFA_PHONES)}
    path = tmp_path / "mfa.TextGrid"
    path.write_text(mfa_textgrid(tiers))
    assert [w.text for w in read_alignment(path, duration=2.4)] == ["such", "expensive", "furnishings"]
    assert_phones(read_phones(path, duration=2.4), EXPECTED)


def test_phones_that_are_not_arpabet_are_left_out_with_a_note(tmp_path):
    """MFA's english_mfa model writes IPA: those phones are not read (a note), the words are."""
    ipa = [(0.3, 0.4, "s"), (0.4, 0.49, "ɐ"), (0.49, 0.62, "tʃ"), (0.65, 1.31, "ɪ")]
    path = tmp_path / "ipa.TextGrid"
    path.write_text(mfa_textgrid({"anna": (MFA_WORDS, ipa)}))
    notes = []
    assert read_phones(path, duration=2.4, reporter=Reporter(note=notes.append)) is None
    assert len(notes) == 1 and "not CMU/ARPAbet" in notes[0] and "'ɐ'" in notes[0]


def test_words_only_files_have_no_phones(tmp_path):
    words = [Word("such", 0.3, 0.62), Word("expensive", 0.65, 1.31)]
    for name in ("w.json", "w.TextGrid", "w.csv"):
        assert read_phones(write_alignment(words, tmp_path / name)) is None
    whisperx = {"segments": [{"words": [{"word": "such", "start": 0.3, "end": 0.62, "score": 0.9}]}]}
    (tmp_path / "x.json").write_text(json.dumps(whisperx))
    assert read_phones(tmp_path / "x.json") is None
    written = write_alignment(words, tmp_path / "p.json", phones=EXPECTED[:3])
    assert_phones(read_phones(written), EXPECTED[:3])


@pytest.mark.parametrize(("phones", "problem"), [
    ([{"phone": "AH", "start": 0.5, "end": 0.2}], "ends before it starts"),
    ([{"phone": "AH", "start": -0.1, "end": 0.2}], "negative time"),
    ([{"phone": "AH", "start": 0.5, "end": 9.0}], "after the audio's end"),
    ([{"phone": "AH", "start": "nan", "end": 0.2}], "malformed"),
    ([{"phone": "AH", "start": 0.1}], "malformed"),
    ({"phone": "AH"}, "malformed"),
])
def test_broken_phones_are_one_line_errors_naming_the_file(tmp_path, phones, problem):
    path = tmp_path / "broken.json"
    path.write_text(json.dumps({"words": [{"word": "a", "start": 0.1, "end": 0.6}], "phones": phones}))
    with pytest.raises(FacegenError, match=problem) as info:
        read_phones(path, duration=2.0)
    assert "broken.json" in str(info.value) and "\n" not in str(info.value)


# ------------------------------------------------------------------------------ phones inside the word times

SENTENCE = "Grandma was delighted with the yellow flowers we brought her."
PAD = 0.4


@pytest.fixture(scope="module")
def speech():
    """espeak-ng speech with its true word and phone timings, in silence as a recording would be."""
    from facegen.espeak import synthesize

    said = synthesize(SENTENCE, voice="en-us+m3", pitch=45, rate=160)
    pad = np.zeros(int(PAD * said.sample_rate), np.float32)
    audio = np.concatenate([pad, said.audio, pad])
    words = [Word(w.text, round(w.start + PAD, 3), round(w.end + PAD, 3)) for w in said.words]
    truth = [(p, ph.start + PAD) for ph in said.phones for p in espeak_to_cmu([ph.text])[:1]]
    return audio, said.sample_rate, words, truth


def onset_errors(phones, truth) -> list[float]:
    """Onset errors of the phones both sequences agree on, in order."""
    import difflib

    matcher = difflib.SequenceMatcher(a=[p for p, _ in truth], b=[p for p, _, _ in phones], autojunk=False)
    return [abs(phones[m.b + k][1] - truth[m.a + k][1]) for m in matcher.get_matching_blocks()
            for k in range(m.size)]


def test_words_only_phones_match_the_synthesiser_and_stay_inside_their_words(speech):
    audio, sr, words, truth = speech
    found = phones_in_word_times(audio, sr, words)
    assert (found.aligned, found.spread) == (len(words), 0)
    assert all(p in INDEX for p, _, _ in found.phones)
    for w in words:  # each word's phones inside its time in the file, and most of it
        inside = [(a, b) for _, a, b in found.phones if w.start - 1e-6 <= a and b <= w.end + 1e-6]
        assert inside and sum(b - a for a, b in inside) > 0.7 * (w.end - w.start), w
    assert sum(b - a for _, a, b in found.phones) <= sum(w.end - w.start for w in words) + 1e-6
    errors = onset_errors(found.phones, truth)
    assert len(errors) >= 0.8 * len(truth) and np.median(errors) < 0.03, np.median(errors)
    assert sum(p in ("B", "M") for p, _, _ in found.phones) >= 2  # "brought", "Grandma"


def test_the_file_phones_are_kept_and_only_the_words_without_them_aligned(speech):
    audio, sr, words, _ = speech
    file_phones = [("AH", w.start, w.end) for w in words[1:]]  # stand-ins a real file would carry
    found = phones_in_word_times(audio, sr, words, file_phones)
    assert (found.aligned, found.spread) == (1, 0)
    assert found.phones[len(found.phones) - len(file_phones):] == file_phones
    grandma = [p for p, a, b in found.phones if b <= words[0].end + 1e-6]
    assert grandma[:2] == ["G", "R"] and "M" in grandma


def test_a_word_too_short_for_its_phones_gets_its_pronunciation_spread_over_its_time(speech):
    """A word whose time cannot hold its phones (a wrong time in the file) does not align: espeak-ng's
    pronunciation is spread over it, vowels twice as long as consonants."""
    from facegen.espeak import pronounce
    from facegen.phonetics import CMU_VOWELS

    audio, sr, words, _ = speech
    wrong = [Word("grandmothers", 0.1, 0.15)]  # ten phones in 50 ms, in the leading silence
    found = phones_in_word_times(audio, sr, wrong + words)
    assert (found.aligned, found.spread) == (len(words), 1)
    spread = [(p, a, b) for p, a, b in found.phones if b <= 0.15 + 1e-6]
    assert [p for p, _, _ in spread] == pronounce("grandmothers") and len(spread) >= 8
    assert spread[0][1] == pytest.approx(0.1) and spread[-1][2] == pytest.approx(0.15)
    vowel = next(b - a for p, a, b in spread if p in CMU_VOWELS)
    consonant = next(b - a for p, a, b in spread if p not in CMU_VOWELS)
    assert vowel == pytest.approx(2 * consonant, abs=2e-3)  # times are kept to the millisecond


def _write_formats(folder, words) -> dict[str, object]:
    """The same words as each words-only format a user brings."""
    paths = {name: write_alignment(words, folder / f"words.{ext}")
             for name, ext in (("JSON", "json"), ("TextGrid", "TextGrid"), ("CSV", "csv"))}
    whisperx = {"segments": [{"start": words[0].start, "end": words[-1].end, "text": SENTENCE,
                              "words": [{"word": w.text, "start": w.start, "end": w.end, "score": 0.8}
                                        for w in words]}]}
    paths["WhisperX JSON"] = folder / "whisperx.json"
    paths["WhisperX JSON"].write_text(json.dumps(whisperx))
    gentle = {"transcript": SENTENCE, "words": [{"alignedWord": w.text.lower(), "case": "success",
                                                 "start": w.start, "end": w.end, "word": w.text}
                                                for w in words]}  # Gentle's word list without phones
    paths["Gentle JSON"] = folder / "gentle.json"
    paths["Gentle JSON"].write_text(json.dumps(gentle))
    with open(folder / "tabs.csv", "w", newline="") as f:  # a CSV as a spreadsheet exports it
        csv.writer(f, delimiter="\t").writerows([["start", "end", "word"]]
                                                + [[w.start, w.end, w.text] for w in words])
    paths["CSV (tabs)"] = folder / "tabs.csv"
    return paths


def test_every_words_only_format_gets_the_same_aligned_phones(speech, tmp_path):
    audio, sr, words, _ = speech
    results = {name: alignment_phones(audio, sr, path)
               for name, path in _write_formats(tmp_path, words).items()}
    first = results["JSON"]
    for name, (got_words, phones, source) in results.items():
        assert source == FILE_PHONES_ALIGNED, name
        assert [w.text for w in got_words] == [w.text for w in words], name
        assert phones == first[1], name


def test_a_gentle_file_with_phones_needs_no_alignment_but_its_unknown_word_does(speech, tmp_path):
    audio, sr, words, truth = speech
    gentle = {"transcript": SENTENCE, "words": []}
    for w in words:
        said = [(p, a) for p, a in truth if w.start <= a < w.end]
        ends = [a for _, a in said[1:]] + [w.end]
        phones = ([{"phone": "oov_S", "duration": round(w.end - w.start, 3)}] if w.text == "yellow" else
                  [{"phone": f"{p.lower()}_I", "duration": round(b - a, 3)} for (p, a), b in zip(said, ends,
                                                                                                  strict=True)])
        gentle["words"].append({"alignedWord": "<unk>" if w.text == "yellow" else w.text.lower(),
                                "case": "success", "start": said[0][1] if said else w.start, "end": w.end,
                                "word": w.text, "phones": phones})
    path = tmp_path / "gentle.json"
    path.write_text(json.dumps(gentle))
    got_words, phones, source = alignment_phones(audio, sr, path)
    assert source == FILE_PHONES_ALIGNED
    yellow = next(w for w in got_words if w.text == "yellow")
    inside = [p for p, a, b in phones if yellow.start - 1e-6 <= a and b <= yellow.end + 1e-6]
    assert inside[:2] == ["Y", "EH"] and "L" in inside  # aligned inside the unknown word's time
    gentle["words"] = [w for w in gentle["words"] if w["word"] != "yellow"]
    path.write_text(json.dumps(gentle))
    assert alignment_phones(audio, sr, path)[2] == FILE  # every word has its phones: nothing aligned


def test_a_phone_model_animates_from_a_words_only_file(speech, tmp_path):
    """The refusal is gone: a model with a phone stream gets per-frame phones from a words-only file, those
    that pocketsphinx finds for the transcript inside them."""
    audio, sr, words, _ = speech
    path = write_alignment(words, tmp_path / "words.csv")
    T = round(len(audio) / sr * 25)
    notes = []
    timing = clip_words_and_phones(audio, sr, T, 25.0, text=None, alignment=path, no_text=False,
                                   reporter=Reporter(note=notes.append))
    got, source, frames = timing.words, timing.source, timing.phones
    assert source == FILE_PHONES_ALIGNED and notes == [] and frames.shape == (T, len(INDEX))
    speaking = np.zeros(T, bool)
    for w in got:
        speaking[int(w.start * 25):int(np.ceil(w.end * 25))] = True
    voiced = frames[:, 1:].sum(1) > 0
    assert voiced[speaking].mean() > 0.85 and not voiced[~speaking].any()


def test_the_default_model_animates_from_a_words_only_file(speech, tmp_path):
    import facegen

    audio, sr, words, _ = speech
    wav = tmp_path / "line.wav"
    sf.write(wav, audio, sr, subtype="PCM_16")
    animation = facegen.animate(wav, alignment=write_alignment(words, tmp_path / "words.TextGrid"),
                                device="cpu")
    assert animation.metadata["word_timing"] == FILE_PHONES_ALIGNED
    vertices = np.asarray(animation.vertices)
    assert vertices.shape[0] == round(len(audio) / sr * 25) and np.isfinite(vertices).all()
