"""Expression control (issue 24): --emotion LABEL[:INTENSITY] moves brows, lids, cheeks and mouth corners over
the whole clip, in the ARKit fit as in the mesh; intensity 0 is neutral exactly; bad values are one line."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

import facegen
from facegen.arkit.solve import fit_arkit
from facegen.errors import FacegenError
from facegen.expression import EMOTIONS, Emotion, parse_emotion

WAV, TEXT = "examples/excellent_room.wav", "examples/excellent_room.txt"


def test_parse():
    assert parse_emotion("happy") == Emotion("happy", 1.0)
    assert parse_emotion(" Angry:0.4 ") == Emotion("angry", 0.4)
    assert parse_emotion(None) is None
    with pytest.raises(FacegenError, match="unknown emotion 'joyful': use one of neutral, happy, sad"):
        parse_emotion("joyful")
    for bad in ("happy:1.5", "happy:-0.1", "happy:nan", "happy:lots", "sad:inf"):
        with pytest.raises(FacegenError, match="intensity of emotion"):
            parse_emotion(bad)
    assert set(EMOTIONS) == {"neutral", "happy", "sad", "angry", "surprised", "afraid", "disgusted"}


@pytest.fixture(scope="module")
def text():
    from pathlib import Path

    return Path(TEXT).read_text()


@pytest.fixture(scope="module")
def neutral(text):
    anim = facegen.animate(WAV, text=text)
    return anim, fit_arkit(anim).weights.mean(0)


@pytest.mark.parametrize(("emotion", "up", "still"), [
    ("happy", ("mouthSmileLeft", "mouthSmileRight", "cheekSquintLeft", "cheekSquintRight"),
     ("browDownLeft",)),
    ("sad", ("browInnerUp", "mouthFrownLeft", "mouthFrownRight"), ("mouthSmileLeft",)),
    ("angry", ("browDownLeft", "browDownRight"), ("browInnerUp", "mouthSmileLeft")),
    ("surprised", ("browInnerUp", "browOuterUpLeft", "eyeWideLeft"), ("browDownLeft",)),
])
def test_emotions_move_the_face(neutral, text, emotion, up, still):
    from facegen.arkit.names import ARKIT_NAMES

    base, mean = neutral
    anim = facegen.animate(WAV, text=text, emotion=emotion)
    assert anim.metadata["emotion"] == {"label": emotion, "intensity": 1.0}
    change = fit_arkit(anim).weights.mean(0) - mean
    for name in up:
        assert change[ARKIT_NAMES.index(name)] >= 0.4, (emotion, name)
    for name in still:
        assert abs(change[ARKIT_NAMES.index(name)]) < 0.05, (emotion, name)
    assert np.abs(anim.vertices - base.vertices).max() > 0


def test_intensity_zero_and_neutral_are_the_face_without_emotion(neutral, text):
    base, _ = neutral
    for emotion in ("happy:0", "neutral"):
        anim = facegen.animate(WAV, text=text, emotion=emotion)
        assert np.array_equal(anim.vertices, base.vertices), emotion
    # linear in the intensity (without the lip seal, whose weights answer the gap the emotion leaves)
    plain = facegen.animate(WAV, text=text, lip_seal=False).vertices
    half = facegen.animate(WAV, text=text, emotion="happy:0.5", lip_seal=False).vertices - plain
    full = facegen.animate(WAV, text=text, emotion="happy", lip_seal=False).vertices - plain
    assert np.allclose(2 * half, full, atol=1e-5)


def test_cli_and_batch(tmp_path, text):
    out = tmp_path / "a.json"
    command = [sys.executable, "-m", "facegen", "animate", WAV, "--text-file", TEXT, "-o", str(out), "-q"]
    bad = subprocess.run([*command, "--emotion", "furious"], check=False, capture_output=True, text=True)
    assert bad.returncode == 2 and not out.exists()
    assert bad.stderr.strip().splitlines() == [bad.stderr.strip()] and "use one of neutral" in bad.stderr
    from pathlib import Path

    wav = str(Path(WAV).resolve())
    manifest = tmp_path / "lines.json"
    manifest.write_text(json.dumps([{"audio": wav, "text": text, "output": "a.json", "emotion": "sad:0.5"},
                                    {"audio": wav, "text": text, "output": "b.json"}]))
    batch = [sys.executable, "-m", "facegen", "batch", str(manifest), "-q", "--jobs", "1"]
    done = subprocess.run([*batch, "-o", str(tmp_path / "out"), "--emotion", "happy"], check=False,
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    a = json.loads((tmp_path / "out" / "a.json").read_text())
    b = json.loads((tmp_path / "out" / "b.json").read_text())
    names = a["facsNames"]
    frown, smile = names.index("mouthFrownLeft"), names.index("mouthSmileLeft")
    assert np.mean(np.asarray(a["weightMat"])[:, frown]) > 0.2  # the row's own emotion
    assert np.mean(np.asarray(b["weightMat"])[:, smile]) > 0.4  # the run's
    manifest.write_text(json.dumps([{"audio": wav, "text": "hello", "output": "a.json", "emotion": "sad:2"}]))
    bad = subprocess.run([*batch, "-o", str(tmp_path / "o2")], check=False, capture_output=True, text=True)
    assert bad.returncode == 2 and "intensity" in bad.stderr and not (tmp_path / "o2").exists(), bad.stderr


def test_markup_spans_and_their_errors():
    from facegen.expression import emotion_spans, is_markup

    text = "Well [happy:0.7] what a lovely [tone] day [/happy] it was, [sad]truly[/sad]."
    spans = emotion_spans(text)
    assert [(s.emotion, text[s.first:s.last].strip()) for s in spans] == [
        (Emotion("happy", 0.7), "what a lovely [tone] day"), (Emotion("sad", 1.0), "truly")]
    assert is_markup("[happy:0.7]") and is_markup("[/sad]") and not is_markup("[tone]")
    assert emotion_spans("a [beep] b (laughs)") == []
    for bad, message in [("[happy] hello", "character 1 is never closed"),
                         ("hello [/happy]", "at character 7 closes a span that was never opened"),
                         ("[glad:0.5] hi [/glad]", "'[glad:0.5]' at character 1 names no emotion"),
                         ("[happy:2] hi [/happy]", "intensity"),
                         ("[sad] a [sad] b [/sad]", "opens [sad] again")]:
        with pytest.raises(FacegenError, match=message.replace("[", r"\[").replace("]", r"\]")):
            emotion_spans(bad)


def test_a_marked_span_moves_its_words_only(neutral, text):
    from facegen.arkit.names import ARKIT_NAMES

    base, _ = neutral
    words = text.split()
    marked = " ".join(words[:3] + ["[happy]"] + words[3:6] + ["[/happy]"] + words[6:])
    anim = facegen.animate(WAV, text=marked)
    spans = anim.metadata["emotion_spans"]
    assert len(spans) == 1 and spans[0]["label"] == "happy"
    aligned = anim.metadata["words"]
    assert spans[0]["start"] == aligned[3]["start"] and spans[0]["end"] == aligned[5]["end"]
    assert [w["word"] for w in aligned] == [w["word"] for w in base.metadata["words"]]  # unaligned
    assert "stage_directions" not in anim.metadata
    smile = fit_arkit(anim).weights[:, ARKIT_NAMES.index("mouthSmileLeft")]
    t = np.arange(len(smile)) / anim.fps
    inside = (t > spans[0]["start"] + 0.2) & (t < spans[0]["end"] - 0.2)
    outside = (t < spans[0]["start"] - 0.3) | (t > spans[0]["end"] + 0.3)
    assert smile[inside].mean() > 0.5 and smile[outside].mean() < 0.1
