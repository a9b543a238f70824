"""--language (issue 25): the languages espeak-ng reads, the script check, IPA phones mapped by articulatory
features, forced alignment of French and Russian speech with their own pronunciations (word onsets against the
synthesiser's times), the mismatch check in another language, and the commands' one-line refusals."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from facegen.errors import FacegenError
from facegen.languages import HELD_OUT, check_language, check_script, languages
from facegen.phonetics import ipa_to_cmu

FRENCH = ["Bonjour à tous, je suis très heureux de vous voir aujourd'hui.",
          "Le train pour Marseille part à huit heures du matin."]
RUSSIAN = "Доброе утро, я очень рад видеть вас всех сегодня."


def test_every_espeak_language_with_its_family_and_script():
    table = languages()
    assert len(table) >= 100 and {"en", "fr", "de", "es", "ru", "cmn", "pt-br"} <= set(table)
    assert table["fr"].family_name == "Romance" and table["ru"].scripts == ("CYRILLIC",)
    assert check_language("pt_BR").code == "pt-BR" and check_language("en-US").code == "en"
    assert check_language(None).code == "en" and set(HELD_OUT) <= set(table)
    with pytest.raises(FacegenError, match="unknown language 'xx': `facegen languages` lists"):
        check_language("xx")


@pytest.mark.parametrize("tag, voice", [
    ("fr-CA", "fr"), ("de_AT", "de"), ("pt-PT", "pt"), ("pt-BR", "pt-BR"), ("fr-BE", "fr-BE"),
    ("en-GB", "en-GB-x-rp"), ("en-AU", "en"), ("es-MX", "es-419"), ("es-ES", "es"), ("zh-CN", "cmn"),
])
def test_a_locale_tag_reads_as_its_voice_or_its_language(tag, voice):
    """Pipelines name languages by locale; a region espeak-ng has no voice for reads as its language."""
    assert check_language(tag).code == voice


def test_an_unknown_language_with_a_region_is_still_unknown():
    with pytest.raises(FacegenError, match="unknown language 'xx-YY'"):
        check_language("xx-YY")


def test_a_transcript_in_another_script_is_refused():
    check_script("Bonjour à tous, IBM et 42", check_language("fr"))
    check_script(RUSSIAN + " (Apple)", check_language("ru"))
    with pytest.raises(FacegenError, match=r"written in Cyrillic script, which fr is not .*--language .*ru"):
        check_script(RUSSIAN, check_language("fr"))
    with pytest.raises(FacegenError, match="Greek script"):
        check_script("Καλημέρα σε όλους", check_language("de"))


def test_ipa_phones_map_by_what_shows_on_the_lips():
    assert ipa_to_cmu(["ˈyː"]) == ["UW"]  # French /y/ rounds
    assert ipa_to_cmu(["β"]) == ["V"]  # a Spanish /b/ between vowels does not close
    assert ipa_to_cmu(["b", "m", "p"]) == ["B", "M", "P"]
    assert ipa_to_cmu(["ʁ"])[0] not in ("R", "W")  # uvular: not the rounded English R
    assert ipa_to_cmu(["ø"]) == ["OW"] and ipa_to_cmu(["ts"]) == ["T", "S"] and ipa_to_cmu(["ɛ̃"]) == ["EH"]


def _recording(text: str, voice: str, variant: str = "f3") -> tuple[np.ndarray, list[float]]:
    from facegen.espeak import synthesize

    speech = synthesize(text, voice=voice, variant=variant, rate=140, pitch=70, sample_rate=16000)
    audio = np.concatenate([np.zeros(6400, np.float32), speech.audio, np.zeros(4000, np.float32)])
    audio += 2e-3 * np.random.default_rng(0).standard_normal(len(audio)).astype(np.float32)
    return audio, [w.start + 0.4 for w in speech.words]


@pytest.mark.parametrize(("text", "code"), [(FRENCH[0], "fr"), (RUSSIAN, "ru")])
def test_words_align_with_their_own_pronunciation(text, code):
    from facegen.align import align_checked

    audio, truth = _recording(text, code)
    found = align_checked(audio, 16000, text, True, code)
    assert [w.text for w in found.words] == [w.strip(",.?") for w in text.split()]
    errors = np.abs(np.array([w.start for w in found.words]) - truth)
    assert np.median(errors) < 0.04 and errors.max() < 0.15, errors
    assert found.match.problem is None and found.phones and all(p[0] != "SIL" for p in found.phones)


def test_another_lines_transcript_is_refused_in_french():
    from facegen.align import align_checked

    audio, _ = _recording(FRENCH[0], "fr")
    try:
        found = align_checked(audio, 16000, FRENCH[1], False, "fr")
        assert found.match.problem is not None
    except FacegenError as exc:
        assert "does not match the speech" in str(exc)


@pytest.fixture(scope="module")
def french_wav(tmp_path_factory):
    import soundfile as sf

    path = tmp_path_factory.mktemp("fr") / "bonjour.wav"
    sf.write(path, _recording(FRENCH[0], "fr", "m3")[0], 16000)
    return path


def test_animate_and_align_in_french(french_wav, tmp_path):
    out = tmp_path / "bonjour.json"
    subprocess.run([sys.executable, "-m", "facegen", "animate", str(french_wav), "-l", "fr", "--text",
                    FRENCH[0], "-o", str(out), "-q"], check=True)
    block = json.loads(out.read_text())["facegen"]
    assert block["language"] == "fr"
    done = subprocess.run([sys.executable, "-m", "facegen", "align", str(french_wav), "--language", "fr",
                           "--text", FRENCH[0]], capture_output=True, text=True, check=True)
    assert json.loads(done.stdout)["words"][0]["word"] == "Bonjour"


@pytest.mark.parametrize(("args", "said"), [
    (["-l", "xx", "--text", FRENCH[0]], "unknown language 'xx'"),
    (["-l", "fr", "--text", RUSSIAN], "Cyrillic script"),
])
def test_bad_language_input_is_one_line_and_writes_nothing(french_wav, tmp_path, args, said):
    out = tmp_path / "x.json"
    done = subprocess.run([sys.executable, "-m", "facegen", "animate", str(french_wav), *args, "-o",
                           str(out)], capture_output=True, text=True, check=False)
    assert done.returncode == 2 and said in done.stderr and done.stderr.count("\n") == 1
    assert not out.exists()


def test_languages_lists_what_was_measured():
    done = subprocess.run([sys.executable, "-m", "facegen", "languages", "--json"], capture_output=True,
                          text=True, check=True)
    rows = {r["code"]: r for r in json.loads(done.stdout)}
    measured = [c for c, r in rows.items() if r["measured"]]
    assert len(measured) >= 20 and {"fr", "de", "ru", "nl"} <= set(measured)
    assert rows["nl"].get("held_out") and rows["fr"]["measured"]["onset_median_ms"] < 40


def test_a_words_only_file_gets_its_phones_in_the_language():
    from facegen.phone_timing import phones_in_word_times
    from facegen.words import Word

    audio, _ = _recording(FRENCH[1], "fr")
    from facegen.espeak import synthesize

    spoken = synthesize(FRENCH[1], voice="fr", variant="f3", rate=140, pitch=70).words
    words = [Word(w.text, w.start + 0.4, w.end + 0.4) for w in spoken]
    found = phones_in_word_times(audio, 16000, words, None, "fr")
    assert found.aligned == len(words) and found.spread == 0
    names = [p[0] for p in found.phones]
    assert "T" in names and "UW" in names  # "train" ... "du": /y/ rounds as UW


def test_batch_reads_a_language_column(french_wav, tmp_path):
    """Each row in its own language (the run's, English, where the column is empty); an unknown code refuses
    the manifest before any work, naming its line."""
    import csv

    def run(rows: list[list[str]]) -> subprocess.CompletedProcess:
        manifest = tmp_path / "lines.csv"
        with manifest.open("w", newline="") as f:
            csv.writer(f).writerows([["audio", "text", "output", "language"], *rows])
        return subprocess.run([sys.executable, "-m", "facegen", "batch", str(manifest), "-o",
                               str(tmp_path / "out"), "-q", "--jobs", "1"], capture_output=True, text=True,
                              check=False)

    rows = [[french_wav, FRENCH[0], "fr.json", "fr"], [french_wav, FRENCH[0], "en.json", ""]]
    bad = run([*rows, [french_wav, FRENCH[0], "xx.json", "xx-nowhere"]])
    assert bad.returncode == 2 and "line 4" in bad.stderr and "xx-nowhere" in bad.stderr
    assert len(bad.stderr.strip().splitlines()) == 1 and not list((tmp_path / "out").glob("*.json"))
    done = run(rows)
    assert done.returncode == 0, done.stderr
    assert json.loads((tmp_path / "out" / "fr.json").read_text())["facegen"]["language"] == "fr"
    assert "language" not in json.loads((tmp_path / "out" / "en.json").read_text())["facegen"]  # English
