"""Word timing: transcript normalisation, forced alignment against espeak's true timings, recognition,
and the readers/writers of alignment files."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from facegen.align import align, align_phones
from facegen.align_pieces import loud_frames, pieces, scored
from facegen.alignment_files import read_alignment, write_alignment
from facegen.audio import resample
from facegen.errors import FacegenError
from facegen.espeak import Speech, pronounce, synthesize
from facegen.phonetics import espeak_to_cmu
from facegen.recognition import recognize
from facegen.words import Word, normalize_transcript

SENTENCES = [
    ("The quick brown fox jumps over the lazy dog.", "en-us", 50, 170),
    ("She sells sea shells by the sea shore, and then she goes home.", "en-us+f3", 70, 150),
    ("Please call Stella. Ask her to bring these things with her from the store.", "en+m2", 40, 190),
    ("Keep your eyes on the road and your hands upon the wheel.", "en+f5", 55, 185),
    ("Why would anyone build a castle out of sand at the edge of the ocean?", "en-us+m5", 45, 155),
]
PAD = 0.4  # s of silence around each clip, as in a real recording


def padded(speech: Speech, pad: float = PAD) -> np.ndarray:
    silence = np.zeros(int(pad * speech.sample_rate), np.float32)
    return np.concatenate([silence, speech.audio, silence])


def with_noise(audio: np.ndarray, speech: Speech, snr_db: float, seed: int = 0) -> np.ndarray:
    power = np.mean(speech.audio.astype(np.float64) ** 2)
    noise = np.random.default_rng(seed).normal(0, np.sqrt(power / 10 ** (snr_db / 10)), len(audio))
    return (audio + noise).astype(np.float32)


def onset_errors(words: list[Word], speech: Speech, offset: float = PAD) -> list[float]:
    assert [w.text for w in words] == [w.text for w in speech.words]
    return [abs(w.start - offset - t.start) for w, t in zip(words, speech.words, strict=True)]


@pytest.fixture(scope="module")
def corpus() -> list[tuple[str, Speech]]:
    return [(text, synthesize(text, voice=v, pitch=p, rate=r)) for text, v, p, r in SENTENCES]


# ---------------------------------------------------------------------------- transcript normalisation

def test_normalize_keeps_original_words_and_spells_numbers():
    got = normalize_transcript('"Hello," she said -- I have 42 apples, the 3rd costs $5 ... (50%)!')
    assert got == [("Hello", ["hello"]), ("she", ["she"]), ("said", ["said"]), ("I", ["i"]),
                   ("have", ["have"]), ("42", ["forty", "two"]), ("apples", ["apples"]), ("the", ["the"]),
                   ("3rd", ["third"]), ("costs", ["costs"]), ("$5", ["five", "dollars"]),
                   ("50%", ["fifty", "percent"])]


@pytest.mark.parametrize(("word", "spoken"), [
    ("1,000,000", ["one", "million"]), ("$1.01", ["one", "dollar", "and", "one", "cent"]),
    ("3.14", ["three", "point", "one", "four"]), ("1990", ["nineteen", "ninety"]),
    ("1905", ["nineteen", "oh", "five"]), ("2024", ["twenty", "twenty", "four"]),
    ("2005", ["two", "thousand", "five"]), ("1990s", ["nineteen", "nineties"]), ("21st", ["twenty", "first"]),
    ("007", ["zero", "zero", "seven"]), ("115", ["one", "hundred", "fifteen"]),
    ("£3m", ["three", "million", "pounds"]),
    ("it’s", ["it's"]), ("state-of-the-art", ["state", "of", "the", "art"]), ("R&D", ["r", "and", "d"]),
    ("COVID-19", ["covid", "nineteen"]), ("Café", ["café"]),
])
def test_normalize_word(word, spoken):
    assert normalize_transcript(word) == [(word, spoken)]


def test_an_identifier_after_its_key_is_said_digit_by_digit():
    got = dict(normalize_transcript("extension 1234, password: 4242 PIN 0815 in 1990 with 8500 people "
                                    "dial 600"))
    assert got["1234"] == ["one", "two", "three", "four"] and got["4242"] == ["four", "two", "four", "two"]
    assert got["0815"] == ["zero", "eight", "one", "five"] and got["1990"] == ["nineteen", "ninety"]
    assert got["8500"] == ["eight", "thousand", "five", "hundred"] and got["600"] == ["six", "hundred"]


def test_normalize_drops_punctuation_only_words():
    assert normalize_transcript("... -- ! “ ”") == []


def test_oov_pronunciations_use_the_model_phones():
    phones = pronounce("Zorblax")
    assert phones[0] == "Z" and phones[-2:] == ["K", "S"]
    assert espeak_to_cmu(["b", "'V", "?", "n-"]) == ["B", "AH", "T", "N"]  # "button"
    assert espeak_to_cmu(["f", "l", "'I", "b", "b", "I2", "t"]) == ["F", "L", "IH", "B", "IH", "T"]


# ---------------------------------------------------------------------------- forced alignment

def test_alignment_matches_the_synthesiser_timing(corpus):
    errors = []
    for text, speech in corpus:
        words = align(padded(speech), speech.sample_rate, text)
        errors += onset_errors(words, speech)
        for a, b in itertools.pairwise(words):
            assert a.start < a.end <= b.start
    median = float(np.median(errors))
    print(f"clean speech: median word onset error {median * 1000:.1f} ms over {len(errors)} words, "
          f"90th percentile {np.percentile(errors, 90) * 1000:.1f} ms")
    assert median <= 0.030


def test_phone_alignment_matches_the_synthesiser_phones(corpus):
    """`align_phones`: the same words as `align`, and CMU phones inside them that start where espeak's do."""
    errors, closures = [], 0
    for text, speech in corpus:
        audio = padded(speech)
        words, phones = align_phones(audio, speech.sample_rate, text)
        assert [(w.text, w.start, w.end) for w in words] == [(w.text, w.start, w.end)
                                                              for w in align(audio, speech.sample_rate, text)]
        starts = [a for _, a, _ in phones]
        assert starts == sorted(starts) and all(b > a for _, a, b in phones)
        assert all(words[0].start - 1e-6 <= a and b <= words[-1].end + 1e-6 for _, a, b in phones)
        truth = [(p, ph.start + PAD) for ph in speech.phones for p in espeak_to_cmu([ph.text])[:1]]
        said = [p for p, _, _ in phones]
        # phones both agree on, in order: onset error against the synthesiser's own phone boundaries
        matcher = __import__("difflib").SequenceMatcher(a=[p for p, _ in truth], b=said, autojunk=False)
        for block in matcher.get_matching_blocks():
            for k in range(block.size):
                errors.append(abs(phones[block.b + k][1] - truth[block.a + k][1]))
        closures += sum(p in ("P", "B", "M") for p in said)
    assert len(errors) > 100 and closures >= 8
    assert np.median(errors) < 0.03, np.median(errors)


def test_noisy_speech_still_aligns(corpus):
    errors = []
    for k, (text, speech) in enumerate(corpus):
        words = align(with_noise(padded(speech), speech, 10.0, seed=k), speech.sample_rate, text)
        errors += onset_errors(words, speech)
    median = float(np.median(errors))
    print(f"10 dB SNR white noise: median word onset error {median * 1000:.1f} ms over {len(errors)} words")
    assert median <= 0.040


def test_out_of_vocabulary_words_align():
    text = "Zorblax quantifies flibbertigibbet every morning."
    speech = synthesize(text, voice="en-us+f2", pitch=60)
    words = align(padded(speech), speech.sample_rate, text)
    assert np.median(onset_errors(words, speech)) < 0.03


def test_numbers_map_back_to_the_written_word():
    text = "I have 42 apples, but my friend only has 3."
    speech = synthesize(text, voice="en-us+m3")
    words = align(padded(speech), speech.sample_rate, text)
    assert [w.text for w in words] == ["I", "have", "42", "apples", "but", "my", "friend", "only", "has", "3"]
    forty_two, truth = words[2], speech.words[2]
    assert abs(forty_two.start - PAD - truth.start) < 0.04  # start of "forty"
    assert abs(forty_two.end - PAD - truth.end) < 0.06  # end of "two"


def test_any_sample_rate_and_stereo_input(corpus):
    text, speech = corpus[0]
    reference = align(padded(speech), speech.sample_rate, text)
    hi = synthesize(text, voice="en-us", pitch=50, rate=170, sample_rate=44100)
    stereo = np.stack([padded(hi), padded(hi)], axis=1)
    words = align(stereo, 44100, text)
    assert [w.text for w in words] == [w.text for w in reference]
    assert max(abs(a.start - b.start) for a, b in zip(words, reference)) < 0.03


def test_empty_transcript_is_an_error(corpus):
    _, speech = corpus[0]
    for transcript in ("", "   ", "... !"):
        with pytest.raises(FacegenError, match="transcript is empty"):
            align(speech.audio, speech.sample_rate, transcript)


def test_silent_or_short_audio_is_an_error():
    with pytest.raises(FacegenError, match="silent"):
        align(np.zeros(16000, np.float32), 16000, "hello world")
    with pytest.raises(FacegenError, match="too short"):
        align(np.full(800, 0.1, np.float32), 16000, "hello world")
    with pytest.raises(FacegenError, match="NaN"):
        align(np.full(16000, np.nan, np.float32), 16000, "hello world")


@pytest.mark.parametrize("case", ["other sentence", "half of the words", "extra words"])
def test_mismatched_transcript_is_an_error(corpus, case):
    text, speech = corpus[3]
    other = corpus[4][0]
    transcript = {"other sentence": other, "half of the words": " ".join(text.split()[:6]),
                  "extra words": text + " " + other}[case]
    expected = r"does not match the speech \(.+\): check the transcript$"  # English words: no language hint
    with pytest.raises(FacegenError, match=expected) as err:
        align(padded(speech), speech.sample_rate, transcript)
    assert err.value.param == "text"
    if case == "half of the words":
        assert "at the end" in str(err.value)  # says which part of the speech the words leave out


def test_a_small_transcript_error_is_tolerated(corpus):
    text, speech = corpus[1]  # "She sells sea shells by the sea shore, and then she goes home."
    words = align(padded(speech), speech.sample_rate, text.replace("goes home", "goes house"))
    assert words[-1].text == "house" and words[-1].end - PAD > speech.words[-1].start


def test_recognize_returns_timed_words(corpus):
    text, speech = corpus[0]
    words = recognize(padded(speech), speech.sample_rate)
    assert len(words) >= 5
    for a, b in itertools.pairwise(words):
        assert a.start < a.end <= b.start + 1e-6
    assert words[0].start >= PAD - 0.1 and words[-1].end <= PAD + speech.duration + PAD
    truth = {w.lower().strip(".") for w in text.split()}
    assert len(truth & {w.text for w in words}) >= 2  # lower quality than alignment, not nothing


# ---------------------------------------------------------------------------- long audio, piece by piece

def long_clip(corpus, pause: float = 0.6) -> tuple[np.ndarray, str, list[float]]:
    """The corpus said twice in a row with pauses (about 40 s): audio, transcript, true word onsets."""
    rate = corpus[0][1].sample_rate
    parts, texts, onsets, t = [np.zeros(int(PAD * rate), np.float32)], [], [], PAD
    for text, speech in corpus + corpus:
        parts += [speech.audio, np.zeros(int(pause * rate), np.float32)]
        texts.append(text)
        onsets += [t + w.start for w in speech.words]
        t += speech.duration + pause
    return np.concatenate(parts), " ".join(texts), onsets


def test_pieces_are_cut_in_the_middle_of_pauses():
    loud = np.ones(2000, bool)
    loud[[*range(300, 340), *range(700, 720), *range(900, 960), *range(1700, 1800)]] = False
    # 300-340 comes too early (< PIECE_SECONDS), 700-720 is too short, 1700-1800 leaves too little after it
    assert pieces(loud) == [(0, 930), (930, 2000)]
    assert pieces(np.ones(5000, bool)) == [(0, 5000)]  # no pause: one piece, as one long search
    spans = [(i * 600, (i + 1) * 600) for i in range(10)]
    assert scored(spans) == {0, 9}  # 10 s at least, spread out
    assert scored(spans[:1]) == {0}


def test_long_audio_aligns_piece_by_piece(corpus):
    audio, text, onsets = long_clip(corpus)
    rate = corpus[0][1].sample_rate
    at16k = resample(audio, rate, 16000)
    assert len(pieces(loud_frames(at16k, len(at16k) // 160))) >= 4
    words = align(audio, rate, text)
    assert [w.text for w in words] == [w.strip(".,?!") for w in text.split()]
    errors = np.abs(np.array([w.start for w in words]) - onsets)
    assert np.median(errors) <= 0.03 and np.percentile(errors, 95) < 0.1, (np.median(errors), errors.max())
    for a, b in itertools.pairwise(words):
        assert a.start < a.end <= b.start
    same, phones = align_phones(audio, rate, text)
    assert same == words
    assert [p for p, _, _ in phones[:4]] == ["DH", "AH", "K", "W"]  # "the quick"
    assert all(b > a for _, a, b in phones) and phones[-1][2] <= words[-1].end + 1e-6


def test_pieces_give_the_timings_of_one_search_over_the_clip(corpus, monkeypatch):
    """Piece by piece, the words and phones of one search over the whole clip. Every piece subtracts the whole
    clip's cepstral mean (a piece's own mean, which the acoustic model's feat.params asked for over the
    decoder's settings, moved words near the cuts by up to half a second), and aligns again the last word of
    the piece before it (a search's noise estimate starts afresh: a piece's first word started up to 90 ms
    early)."""
    import facegen.align as align_module
    import facegen.align_pieces
    from facegen.sphinx import get_decoder

    for kind in ("align", "align-wide", "align-nofiller", "phone-loop"):
        assert get_decoder(kind).config["cmn"] == "live"
    audio, text, _ = long_clip(corpus)
    rate = corpus[0][1].sample_rate
    split = align_phones(audio, rate, text)
    monkeypatch.setattr(facegen.align_pieces, "PIECE_SECONDS", 1e9)
    monkeypatch.setattr(align_module, "pieces", facegen.align_pieces.pieces)
    whole = align_phones(audio, rate, text)
    assert split[0] == whole[0]
    # the phones too, but for a phone edge a frame apart now and then: a decoder that aligned other clips
    # before (tests/test_words_only.py first) may place one of ~400 edges 10 ms from where a fresh one does
    assert [p for p, _, _ in split[1]] == [p for p, _, _ in whole[1]]
    moved = np.abs(np.array([t for _, *t in split[1]]) - np.array([t for _, *t in whole[1]]))
    assert moved.max() <= 0.0101 and np.mean(moved > 0) <= 0.01, (moved.max(), np.mean(moved > 0))


@pytest.mark.parametrize("case", ["half of the sentences", "the wrong sentences"])
def test_long_audio_with_a_mismatched_transcript_is_an_error(corpus, case):
    audio, _, _ = long_clip(corpus)
    sentences = [t for t, _ in corpus]
    transcript = {"half of the sentences": " ".join(sentences),
                  "the wrong sentences": " ".join(sentences[::-1] * 2)}[case]
    with pytest.raises(FacegenError, match="does not match the speech"):
        align(audio, corpus[0][1].sample_rate, transcript)


# ---------------------------------------------------------------------------- alignment files

GENTLE = {
    "transcript": "Hello, brave new world.",
    "words": [
        {"alignedWord": "hello", "case": "success", "end": 0.83, "endOffset": 5,
         "phones": [{"duration": 0.09, "phone": "hh_B"}, {"duration": 0.06, "phone": "ah_I"},
                    {"duration": 0.08, "phone": "l_I"}, {"duration": 0.2, "phone": "ow_E"}],
         "start": 0.4, "startOffset": 0, "word": "Hello,"},
        {"case": "not-found-in-audio", "endOffset": 12, "startOffset": 7, "word": "brave"},
        {"alignedWord": "new", "case": "success", "end": 1.1, "endOffset": 16,
         "phones": [{"duration": 0.1, "phone": "n_B"}, {"duration": 0.17, "phone": "uw_E"}],
         "start": 0.83, "startOffset": 13, "word": "new"},
        {"alignedWord": "world", "case": "success", "end": 1.52, "endOffset": 22,
         "phones": [{"duration": 0.42, "phone": "w_B"}], "start": 1.1, "startOffset": 17, "word": "world"},
    ],
}
EXPECTED = [Word("Hello", 0.4, 0.83), Word("new", 0.83, 1.1), Word("world", 1.1, 1.52)]
MFA_EXPECTED = [Word("hello", 0.4, 0.83), Word("new", 0.83, 1.1), Word("world", 1.1, 1.52)]  # lower case

TEXTGRID_LONG = '''File type = "ooTextFile"
Object class = "TextGrid"

xmin = 0 
xmax = 1.8 
tiers? <exists> 
size = 2 
item []: 
    item [1]:
        class = "IntervalTier" 
        name = "words" 
        xmin = 0 
        xmax = 1.8 
        intervals: size = 5 
        intervals [1]:
            xmin = 0 
            xmax = 0.4 
            text = "" 
        intervals [2]:
            xmin = 0.4 
            xmax = 0.83 
            text = "hello" 
        intervals [3]:
            xmin = 0.83 
            xmax = 1.1 
            text = "new" 
        intervals [4]:
            xmin = 1.1 
            xmax = 1.52 
            text = "world" 
        intervals [5]:
            xmin = 1.52 
            xmax = 1.8 
            text = "" 
    item [2]:
        class = "IntervalTier" 
        name = "phones" 
        xmin = 0 
        xmax = 1.8 
        intervals: size = 3 
        intervals [1]:
            xmin = 0 
            xmax = 0.4 
            text = "" 
        intervals [2]:
            xmin = 0.4 
            xmax = 0.5 
            text = "HH" 
        intervals [3]:
            xmin = 0.5 
            xmax = 1.8 
            text = "AH0" 
'''

TEXTGRID_SHORT = '''File type = "ooTextFile"
Object class = "TextGrid"

0
1.8
<exists>
2
"TextTier"
"events"
0
1.8
1
0.5
"click"
"IntervalTier"
"utterance"
0
1.8
4
0
0.4
"sil"
0.4
0.83
"hello"
0.83
1.1
"new"
1.1
1.8
"say ""hi"" now"
'''

WHISPERX = {
    "segments": [
        {"start": 0.4, "end": 1.52, "text": " Hello new world, 42 times.",
         "words": [{"word": "Hello", "start": 0.4, "end": 0.83, "score": 0.91},
                   {"word": "new", "start": 0.83, "end": 1.1, "score": 0.88},
                   {"word": "world,", "start": 1.1, "end": 1.52, "score": 0.95},
                   {"word": "42"},
                   {"word": "times.", "start": 2.0, "end": 2.4, "score": 0.7}]},
    ],
    "word_segments": [{"word": "Hello", "start": 0.4, "end": 0.83, "score": 0.91}],
}


def write(tmp_path, name: str, content) -> str:
    path = tmp_path / name
    if isinstance(content, str):
        path.write_text(content, encoding="utf-8")
    else:
        path.write_text(json.dumps(content), encoding="utf-8")
    return str(path)


def test_read_gentle(tmp_path):
    assert read_alignment(write(tmp_path, "gentle.json", GENTLE), duration=2.0) == EXPECTED


def test_read_textgrid_long_format_words_tier(tmp_path):
    assert read_alignment(write(tmp_path, "mfa.TextGrid", TEXTGRID_LONG), duration=1.8) == MFA_EXPECTED


def test_read_textgrid_short_format_first_interval_tier(tmp_path):
    words = read_alignment(write(tmp_path, "short.TextGrid", TEXTGRID_SHORT))
    assert words == MFA_EXPECTED[:2] + [Word('say "hi" now', 1.1, 1.8)]


def test_read_textgrid_in_utf16(tmp_path):
    path = tmp_path / "praat.TextGrid"
    path.write_bytes(TEXTGRID_LONG.replace('"new"', '"café"').encode("utf-16"))
    assert [w.text for w in read_alignment(path)] == ["hello", "café", "world"]


def test_read_whisperx_places_untimed_words(tmp_path):
    words = read_alignment(write(tmp_path, "whisperx.json", WHISPERX), duration=2.5)
    assert [w.text for w in words] == ["Hello", "new", "world", "42", "times"]
    assert (words[3].start, words[3].end) == (1.52, 2.0)  # between its neighbours
    only_word_segments = {"word_segments": WHISPERX["segments"][0]["words"][:3]}
    assert read_alignment(write(tmp_path, "ws.json", only_word_segments)) == [
        Word("Hello", 0.4, 0.83), Word("new", 0.83, 1.1), Word("world", 1.1, 1.52)]


def test_read_plain_json_and_csv(tmp_path):
    plain = [{"word": "Hello", "start": 0.4, "end": 0.83}, {"text": "new", "start": 0.83, "end": 1.1},
             {"word": "world", "start": 1.1, "end": 1.52}]
    assert read_alignment(write(tmp_path, "list.json", plain)) == EXPECTED
    assert read_alignment(write(tmp_path, "dict.json", {"words": plain})) == EXPECTED
    csv_header = "start,end,word\n0.4,0.83,Hello\n0.83,1.1,new\n1.1,1.52,world\n"
    assert read_alignment(write(tmp_path, "h.csv", csv_header)) == EXPECTED
    csv_plain = "Hello,0.4,0.83\nnew,0.83,1.1\nworld,1.1,1.52\n"
    assert read_alignment(write(tmp_path, "p.csv", csv_plain)) == EXPECTED
    audacity_labels = "0.400000\t0.830000\tHello\n0.830000\t1.100000\tnew\n1.100000\t1.520000\tworld\n"
    assert read_alignment(write(tmp_path, "labels.txt", audacity_labels)) == EXPECTED


@pytest.mark.parametrize(("name", "content", "problem"), [
    ("broken.json", '{"words": [{"word": "a", "start": 0.1', "malformed"),
    ("nowords.json", {"words": []}, "no timed words"),
    ("text_time.json", [{"word": "a", "start": "soon", "end": 1.0}], "malformed"),
    ("missing_end.json", [{"word": "a", "start": 0.5}], "malformed"),
    ("negative.json", [{"word": "a", "start": -0.5, "end": 0.2}], "negative time"),
    ("reversed.json", [{"word": "a", "start": 0.5, "end": 0.2}], "ends before it starts"),
    ("order.json", [{"word": "a", "start": 0.5, "end": 0.9}, {"word": "b", "start": 0.2, "end": 0.4}],
     "not in order"),
    ("late.json", [{"word": "a", "start": 0.5, "end": 9.0}], "after the audio's end"),
    ("cut.TextGrid", TEXTGRID_LONG[:400], "malformed"),
    ("binary.TextGrid", "ooBinaryFile TextGrid", "malformed"),
    ("bad.csv", "word,start,end\nhello,0.1,later\n", "malformed"),
    ("columns.csv", "hello,0.1\nworld,0.2\n", "malformed"),
    ("nan.json", [{"word": "a", "start": "nan", "end": 1.0}], "malformed"),
])
def test_malformed_alignment_files_name_the_file_and_problem(tmp_path, name, content, problem):
    path = write(tmp_path, name, content)
    with pytest.raises(FacegenError, match=problem) as info:
        read_alignment(path, duration=2.0)
    assert name in str(info.value) and "\n" not in str(info.value)


def test_times_just_past_the_end_are_tolerated(tmp_path):
    path = write(tmp_path, "w.json", [{"word": "a", "start": 0.5, "end": 2.03}])
    assert read_alignment(path, duration=2.0)[0].end == 2.03
    assert read_alignment(path)[0].end == 2.03  # no duration: no check


def test_missing_file_is_an_error(tmp_path):
    with pytest.raises(FacegenError, match="cannot read alignment"):
        read_alignment(tmp_path / "nope.json")


WORDS = [Word("Hello", 0.41, 0.83), Word('5"9,x', 0.83, 1.1), Word("wörld,", 1.35, 1.52)]


@pytest.mark.parametrize("name", ["words.json", "words.TextGrid", "words.csv"])
def test_written_alignments_read_back(tmp_path, name):
    path = write_alignment(WORDS, tmp_path / name, duration=2.0)
    back = read_alignment(path, duration=2.0)
    assert [w.text for w in back] == ["Hello", '5"9,x', "wörld"]  # edge punctuation is dropped
    for a, b in zip(back, WORDS, strict=True):
        assert a.start == pytest.approx(b.start, abs=1e-6) and a.end == pytest.approx(b.end, abs=1e-6)
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]


def test_textgrid_writer_marks_pauses_with_empty_intervals(tmp_path):
    text = write_alignment(WORDS, tmp_path / "w.TextGrid", duration=2.0).read_text()
    assert 'name = "words"' in text and "intervals: size = 6" in text  # pause, 2 words, pause, word, pause
    assert text.count('text = ""') == 3 and "xmax = 2.000000" in text
    plain = json.loads(write_alignment(WORDS, tmp_path / "w.json").read_text())
    assert plain == {"words": [{"word": "Hello", "start": 0.41, "end": 0.83},
                               {"word": '5"9,x', "start": 0.83, "end": 1.1},
                               {"word": "wörld,", "start": 1.35, "end": 1.52}]}


def test_unknown_output_format_is_an_error(tmp_path):
    with pytest.raises(FacegenError, match=r"\.json, \.TextGrid or \.csv"):
        write_alignment(WORDS, tmp_path / "words.xml")
    assert list(tmp_path.iterdir()) == []


def test_alignment_of_synthetic_speech_round_trips_through_a_file(tmp_path, corpus):
    text, speech = corpus[2]
    words = align(speech.audio, speech.sample_rate, text)
    back = read_alignment(write_alignment(words, tmp_path / "a.TextGrid", speech.duration), speech.duration)
    assert back == words


def test_no_writable_temporary_folder_is_one_clear_error(corpus, monkeypatch):
    """The decoders read a temporary copy of the acoustic model's feat.params: without a writable temporary
    folder that is a FacegenError naming the fix, not an OSError."""
    import facegen.sphinx

    def unwritable(*args, **kwargs):
        raise PermissionError(13, "Permission denied", "/tmp/facegen-align-x")

    monkeypatch.setattr(facegen.sphinx, "DECODERS", {})
    monkeypatch.setattr(facegen.sphinx.tempfile, "TemporaryDirectory", unwritable)
    text, speech = corpus[0]
    with pytest.raises(FacegenError, match="set TMPDIR to a writable folder"):
        align(padded(speech), speech.sample_rate, text)
