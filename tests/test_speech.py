"""Speech synthesis with libespeak-ng: audio, true word and phone timings, voices."""

from __future__ import annotations

import itertools
import threading

import numpy as np
import pytest
import soundfile as sf

from facegen.atomic import atomic_path
from facegen.audio import write_wav
from facegen.errors import FacegenError
from facegen.espeak import Speech, phonemize, synthesize
from facegen.words import Word

# 14 distinct speakers as the synthetic corpus will use them: (voice with variant, pitch, rate)
VOICES = [("en-us", 50, 170), ("en-us+f3", 70, 160), ("en+m2", 35, 180), ("en-us+m3", 45, 150),
          ("en+f4", 65, 175), ("en-us+m1", 40, 165), ("en+f2", 75, 155), ("en-us+m7", 30, 185),
          ("en+f1", 60, 190), ("en-us+m4", 50, 145), ("en+f5", 55, 170), ("en-us+m5", 45, 200),
          ("en-gb-scotland+m6", 40, 160), ("en-us+f2", 80, 150)]


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x, dtype=np.float64)))) if len(x) else 0.0


def frame_rms(audio: np.ndarray, sr: int, hop: float = 0.01) -> np.ndarray:
    n = int(hop * sr)
    frames = audio[: len(audio) // n * n].reshape(-1, n)
    return np.sqrt(np.mean(frames.astype(np.float64) ** 2, axis=1))


@pytest.fixture(scope="module")
def hello() -> Speech:
    return synthesize("Hello. ... world, this is a test!", voice="en-us", pitch=50, rate=170)


def test_audio_is_mono_float_at_the_native_rate(hello):
    assert hello.sample_rate == 22050
    assert hello.audio.dtype == np.float32 and hello.audio.ndim == 1
    assert 1.5 < hello.duration < 4.0
    assert 0.05 < np.max(np.abs(hello.audio)) <= 1.0


def test_words_are_the_written_words_in_order_with_monotonic_times(hello):
    assert [w.text for w in hello.words] == ["Hello", "world", "this", "is", "a", "test"]
    assert all(isinstance(w, Word) for w in hello.words)
    for a, b in itertools.pairwise(hello.words):
        assert a.start < a.end <= b.start + 1e-6
    assert hello.words[0].start >= 0 and hello.words[-1].end <= hello.duration + 1e-6


def test_the_pause_before_a_word_is_silent_and_the_word_is_not(hello):
    sr, audio = hello.sample_rate, hello.audio
    hello_word, world = hello.words[0], hello.words[1]
    assert world.start - hello_word.end > 0.2  # "Hello. ..." leaves a real pause
    speech_level = rms(audio[int(hello_word.start * sr):int(hello.words[-1].end * sr)])
    pause = audio[int((hello_word.end + 0.02) * sr):int((world.start - 0.005) * sr)]
    onset = audio[int(world.start * sr):int((world.start + 0.1) * sr)]
    assert rms(pause) < 0.01 * speech_level
    assert rms(onset) > 0.2 * speech_level


def test_the_last_word_ends_where_the_voiced_audio_ends(hello):
    levels = frame_rms(hello.audio, hello.sample_rate)
    voiced_end = (np.nonzero(levels > 0.05 * levels.max())[0][-1] + 1) * 0.01
    print(f"last word ends {hello.words[-1].end:.3f} s, voiced audio ends {voiced_end:.3f} s")
    assert abs(hello.words[-1].end - voiced_end) < 0.05


def test_words_cover_the_voiced_audio(hello):
    levels = frame_rms(hello.audio, hello.sample_rate)
    loud = np.nonzero(levels > 0.1 * levels.max())[0] * 0.01 + 0.005
    inside = [any(w.start - 0.01 <= t <= w.end + 0.01 for w in hello.words) for t in loud]
    assert np.mean(inside) > 0.97


def test_words_espeak_speaks_together_get_their_own_times():
    speech = synthesize("Bring it from the store for the kids.")  # espeak joins "from the", "for the"
    assert [w.text for w in speech.words] == ["Bring", "it", "from", "the", "store", "for", "the", "kids"]
    for a, b in itertools.pairwise(speech.words):
        assert a.end - a.start > 0.02
        assert a.end <= b.start + 1e-6
    the = speech.words[3]
    assert [p.text for p in speech.phones if p.word == 3] == ["D", "@2"]  # the phones of "the"
    assert the.start == pytest.approx(speech.phones[[p.word for p in speech.phones].index(3)].start)


def test_numbers_and_punctuation_map_back_to_the_original_words():
    speech = synthesize("I have 42 apples, (really) déjà-vu!")
    assert [w.text for w in speech.words] == ["I", "have", "42", "apples", "really", "déjà-vu"]
    forty_two = speech.words[2]
    assert len([p for p in speech.phones if p.word == 2]) >= 6  # "forty two", spoken as two words
    assert forty_two.end - forty_two.start > 0.3


def test_phones_belong_to_their_words_and_are_ordered(hello):
    assert len(hello.phones) >= 15
    for p in hello.phones:
        word = hello.words[p.word]
        assert word.start - 0.06 <= p.start <= p.end <= word.end + 1e-6
        assert not p.text.startswith("_")  # pauses are not phones
    starts = [p.start for p in hello.phones]
    assert starts == sorted(starts)
    assert {p.word for p in hello.phones} == set(range(len(hello.words)))
    assert [p.text for p in hello.phones if p.word == 0][-2:] == ["l", "'oU"]  # hel-LO


def test_resampled_audio_keeps_the_timing():
    native = synthesize("Timing stays the same.")
    resampled = synthesize("Timing stays the same.", sample_rate=16000)
    assert resampled.sample_rate == 16000
    assert abs(len(resampled.audio) / 16000 - native.duration) < 0.05
    for a, b in zip(resampled.words, native.words, strict=True):  # espeak varies by a few samples per call
        assert a.text == b.text and abs(a.start - b.start) < 0.015 and abs(a.end - b.end) < 0.015


def test_rate_pitch_and_variant_change_the_voice():
    slow = synthesize("A short sentence to time.", rate=110)
    fast = synthesize("A short sentence to time.", rate=260)
    assert slow.duration > 1.6 * fast.duration
    # at 10, F0 sinks to ~50 Hz and creaks: few voiced frames
    low = synthesize("Aaaah.", voice="en-us+m3", pitch=20)
    high = synthesize("Aaaah.", voice="en-us+f3", pitch=90)
    assert pitch_hz(high) > 1.5 * pitch_hz(low)


def pitch_hz(speech: Speech) -> float:
    """Median F0 of the voiced frames by autocorrelation."""
    sr, f0s = speech.sample_rate, []
    for w in speech.words:
        seg = speech.audio[int(w.start * sr):int(w.end * sr)].astype(np.float64)
        for i in range(0, len(seg) - 1024, 512):
            frame = seg[i:i + 1024] - seg[i:i + 1024].mean()
            ac = np.correlate(frame, frame, "full")[1023:]
            lo, hi = sr // 500, sr // 40  # 40-500 Hz: a deep variant at pitch 10 goes below 60 Hz
            if ac[0] > 0 and ac[lo:hi].max() > 0.5 * ac[0]:
                f0s.append(sr / (lo + np.argmax(ac[lo:hi])))
    assert f0s, "no voiced frame found"
    return float(np.median(f0s))


@pytest.mark.parametrize(("voice", "pitch", "rate"), VOICES)
def test_each_corpus_voice_speaks(voice, pitch, rate):
    speech = synthesize("Six spoons of fresh snow peas.", voice=voice, pitch=pitch, rate=rate)
    assert [w.text for w in speech.words] == ["Six", "spoons", "of", "fresh", "snow", "peas"]
    assert speech.duration > 1.0 and rms(speech.audio) > 0.01


def same_speech(a: Speech, b: Speech) -> bool:
    """Equal up to the waveform state espeak carries between calls (times move by < a pitch period)."""
    return (abs(len(a.audio) - len(b.audio)) < 0.05 * len(a.audio)
            and [w.text for w in a.words] == [w.text for w in b.words]
            and all(abs(x.start - y.start) < 0.015 and abs(x.end - y.end) < 0.015
                    for x, y in zip(a.words, b.words)))


def test_variant_argument_equals_plus_syntax():
    a = synthesize("Same voice.", voice="en-us", variant="f3")
    b = synthesize("Same voice.", voice="en-us+f3")
    c = synthesize("Same voice.", voice="en-us+m3")
    assert same_speech(a, b)
    assert pitch_hz(a) == pytest.approx(pitch_hz(b), rel=0.05)
    assert pitch_hz(a) > 1.3 * pitch_hz(c)


def test_synthesis_is_repeatable_and_thread_safe():
    texts = [f"Thread number {i} is speaking now." for i in range(4)]
    expected = [synthesize(t, voice="en+m2") for t in texts]
    results: dict[int, Speech] = {}

    def run(i: int) -> None:
        results[i] = synthesize(texts[i], voice="en+m2")

    threads = [threading.Thread(target=run, args=(i,)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for i in range(4):
        assert same_speech(results[i], expected[i])


def test_bad_inputs_raise_facegen_errors():
    with pytest.raises(FacegenError, match="unknown espeak voice"):
        synthesize("hello", voice="xx-nowhere")
    with pytest.raises(FacegenError, match="empty"):
        synthesize("   ")
    with pytest.raises(FacegenError, match="pitch"):
        synthesize("hello", pitch=150)
    with pytest.raises(FacegenError, match="rate"):
        synthesize("hello", rate=20)
    assert synthesize("hello").words[0].text == "hello"  # the library still works after the errors


def test_phonemize_gives_espeak_phonemes():
    assert phonemize("hello") == ["h", "@", "l", "'oU"]
    assert "z" in phonemize("Zorblax")


def test_write_wav_round_trips(hello, tmp_path):
    path = tmp_path / "hello.wav"
    with atomic_path(path) as tmp:
        write_wav(hello.audio, hello.sample_rate, tmp)
    data, sr = sf.read(path, dtype="float32")
    assert sr == hello.sample_rate and len(data) == len(hello.audio)
    assert np.max(np.abs(data - hello.audio)) < 1e-4
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hello.wav"]  # no temporary file left


def test_a_stop_holds_its_silent_closure():
    """espeak reports a stop at its release: the silence before it (after a word's start, or at the end of
    the vowel before it inside a word) belongs to the stop, where the lips are closed."""
    speech = synthesize("Please keep the paper by the big pot", voice="en-us")
    rate, hop = speech.sample_rate, speech.sample_rate // 200
    for word_index, word in enumerate(speech.words):
        own = [p for p in speech.phones if p.word == word_index]
        if own and own[0].text.lstrip("'") in {"p", "k", "b", "t", "g", "d"}:
            assert own[0].start == pytest.approx(word.start, abs=1e-6), (word.text, own[0])
    closures = 0
    for prev, stop in itertools.pairwise(speech.phones):
        if prev.word != stop.word or stop.text not in {"p", "t", "k", "b", "d", "g"}:
            continue
        frames = speech.audio[int(prev.start * rate): int(prev.end * rate)]
        frames = frames[: len(frames) // hop * hop].reshape(-1, hop)
        db = 10 * np.log10(np.mean(frames.astype(np.float64) ** 2, axis=1) + 1e-12)
        assert not (db[-2:] < db.max() - 25).all(), (prev, stop)  # no silent tail left in the vowel
        inside = speech.audio[int(stop.start * rate): int(stop.start * rate) + 2 * hop].astype(np.float64)
        closures += 10 * np.log10(np.mean(inside ** 2) + 1e-12) < db.max() - 25
    assert closures >= 1  # "paper": the second p's closure moved out of the vowel into the stop
