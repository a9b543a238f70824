"""Without a transcript, the recognised words carry their lattice posteriors; the ones the recogniser is
unsure of do not drive the upper face (a misheard "earth" would move the brows with the wrong meaning), and
the CLI marks them in what it says it heard."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from facegen.audio import load_audio
from facegen.recognition import SURE, hear, recognize

REPO = Path(__file__).resolve().parents[1]
WAV = REPO / "examples" / "excellent_room.wav"  # "What an excellent room you have, sir. Such expensive ..."


@pytest.fixture(scope="module")
def heard():
    return hear(*load_audio(WAV))


def test_every_word_has_a_posterior_and_right_words_are_surer_than_misheard_ones(heard):
    assert [w.text for w in heard.words] == [w.text for w in recognize(*load_audio(WAV))]
    assert len(heard.confidences) == len(heard.words)
    assert all(0.0 <= c <= 1.0 for c in heard.confidences)
    said = {"what", "an", "excellent", "room", "you", "have", "sir", "such", "expensive", "furnishings"}
    right = [c for w, c in zip(heard.words, heard.confidences, strict=True) if w.text in said]
    wrong = [c for w, c in zip(heard.words, heard.confidences, strict=True) if w.text not in said]
    assert right and wrong and np.mean(right) > np.mean(wrong) + 0.15
    confidence = {w.text: c for w, c in zip(heard.words, heard.confidences, strict=True)}
    assert min(confidence[w] for w in ("what", "excellent", "have")) >= SURE  # right, and sure
    assert max(confidence[w] for w in ("earth", "cute")) < SURE  # "sir" and "such expensive" misheard
    assert heard.sure == [w for w, c in zip(heard.words, heard.confidences, strict=True) if c >= SURE]
    assert 0 < len(heard.sure) < len(heard.words)


def test_only_sure_words_drive_the_text_features(heard):
    from facegen.animator import Animator
    from facegen.text import text_features

    animator = Animator()
    clip = animator.prepare(WAV)
    assert clip.confidences == heard.confidences
    cfg = animator.bundle.features
    backend = animator.text_backend()
    sure = [w for w, c in zip(clip.words, clip.confidences, strict=True) if c >= SURE]
    assert np.allclose(clip.text_features, text_features(sure, backend, clip.num_frames, cfg))
    assert not np.allclose(clip.text_features, text_features(clip.words, backend, clip.num_frames, cfg))
    anim = animator.animation(clip, np.zeros((clip.num_frames, *clip.mesh.vertices.shape), np.float32))
    assert [w["confidence"] for w in anim.metadata["words"]] == heard.confidences


def test_the_cli_marks_the_unsure_words_it_heard(tmp_path, heard):
    command = [sys.executable, "-m", "facegen", "animate", str(WAV), "-o", str(tmp_path / "o.npy")]
    done = subprocess.run(command, capture_output=True, text=True, timeout=600, check=False)
    assert done.returncode == 0, done.stderr
    line = next(x for x in done.stderr.splitlines() if "heard:" in x)
    expected = " ".join(w.text + ("?" if c < SURE else "") for w, c in zip(heard.words, heard.confidences,
                                                                          strict=True))
    assert f"heard: {expected}" in line
    assert f"({len(heard.words) - len(heard.sure)} unsure words" in line
