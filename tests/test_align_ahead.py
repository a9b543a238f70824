"""Alignment started ahead (facegen/align_ahead.py): a new `facegen animate` process aligns the transcript in
a forked process while it imports torch. The words, phones and vertices must be those of the in-process path,
a wrong transcript still one line and exit 2 with nothing written, and no aligner process may outlive the
command. The speed-up is measured by benchmarks/bench_start.py, not here."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from facegen import align_ahead
from facegen.audio import load_audio
from facegen.errors import FacegenError

ROOT = Path(__file__).resolve().parents[1]
WAV = ROOT / "examples" / "excellent_room.wav"
TEXT = (ROOT / "examples" / "excellent_room.txt").read_text().strip()


def run_facegen(*args, **env) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "facegen", *map(str, args)], capture_output=True, text=True,
                          env={**os.environ, "HF_HUB_OFFLINE": "1", **env}, timeout=600, check=False)


def profile_of(proc: subprocess.CompletedProcess) -> dict:
    line = next(x for x in reversed(proc.stderr.splitlines()) if x.startswith('{"facegen_profile"'))
    return json.loads(line)["facegen_profile"]


@pytest.fixture
def new_process(monkeypatch):
    """This test process as a new `facegen` process looks to align_ahead: torch not imported, one thread."""
    if "fork" not in __import__("multiprocessing").get_all_start_methods() or align_ahead.cores() < 2:
        pytest.skip("no fork or a single core here: the caller aligns in-process")
    import torch  # noqa: F401 - imported, so that it can be hidden

    monkeypatch.delitem(sys.modules, "torch")
    monkeypatch.setattr(align_ahead.threading, "active_count", lambda: 1)


def children_of(pid: int) -> list[int]:
    path = Path(f"/proc/{pid}/task/{pid}/children")
    return [int(x) for x in path.read_text().split()] if path.exists() else []


@pytest.mark.skipif(sys.platform != "linux", reason="the aligner is forked on Linux")
def test_a_new_process_aligns_ahead_and_gets_what_the_library_gets(tmp_path):
    import facegen

    proc = run_facegen("animate", WAV, "--text", TEXT, "-o", tmp_path / "out.npy", FACEGEN_PROFILE="1")
    assert proc.returncode == 0, proc.stderr
    stages = profile_of(proc)
    assert stages["alignment_in_parallel"] > 0.05  # the forked aligner ran: its own time, reported back
    assert stages["alignment"] < stages["alignment_in_parallel"]  # what the caller waited for it
    here = facegen.animate(WAV, text=TEXT)  # this process has torch: aligned in-process
    assert np.array_equal(np.load(tmp_path / "out.npy"), here.vertices.reshape(here.num_frames, -1))


@pytest.mark.skipif(sys.platform != "linux", reason="the aligner is forked on Linux")
def test_a_wrong_transcript_is_still_one_line_exit_2_and_nothing_written(tmp_path):
    out = tmp_path / "out.usdc"
    proc = run_facegen("animate", WAV, "--text", "The cat sat on the mat and purred all afternoon long.",
                       "-o", out,
                   FACEGEN_PROFILE="1")
    said = [x for x in proc.stderr.splitlines() if not x.startswith("{")]
    assert proc.returncode == 2, proc.stderr
    assert said == [said[0]] and said[0].startswith("facegen: error: the transcript does not match the "
                                                    "speech")
    assert "Traceback" not in proc.stderr
    assert list(tmp_path.iterdir()) == []
    assert profile_of(proc)["alignment"] >= 0  # the error came back from the forked aligner


def test_the_answer_is_what_align_phones_gives(new_process):
    from facegen.align import align_checked, align_phones

    ahead = align_ahead.start(WAV, TEXT, with_phones=True)
    words, phones, match = ahead.result()
    assert (words, phones) == align_phones(*load_audio(WAV), TEXT)
    assert match == align_checked(*load_audio(WAV), TEXT, with_phones=True).match and match.problem is None
    assert len(words) == len(TEXT.split()) and len(phones) > 2 * len(words)


def test_a_mismatch_comes_back_with_its_match_and_an_error_as_the_same_facegen_error(new_process):
    """The forked aligner refuses nothing that matches badly (the caller decides: --on-mismatch), and gives
    back the FacegenError of a transcript that cannot be aligned at all."""
    from facegen.align import align, align_checked

    wrong = " ".join(TEXT.split()[:len(TEXT.split()) // 2])  # half the words: the rest unexplained
    ahead = align_ahead.start(WAV, wrong, with_phones=False)
    _, _, match = ahead.result()
    here = align_checked(*load_audio(WAV), wrong, with_phones=False).match
    assert match == here and match.problem is not None and match.score < 0.5
    ahead = align_ahead.start(WAV, "?!", with_phones=False)
    with pytest.raises(FacegenError) as forked:
        ahead.result()
    with pytest.raises(FacegenError) as here:
        align(*load_audio(WAV), "?!")
    assert str(forked.value) == str(here.value)


def test_an_aligner_that_dies_gives_no_answer_and_is_reaped(new_process):
    ahead = align_ahead.start(WAV, TEXT, with_phones=True)
    pid = ahead._process.pid
    assert pid in children_of(os.getpid())
    ahead._process.kill()
    assert ahead.result() is None  # the caller aligns itself
    assert pid not in children_of(os.getpid())


def test_close_stops_a_running_aligner(new_process):
    ahead = align_ahead.start(WAV, TEXT, with_phones=True)
    pid = ahead._process.pid
    ahead.close()  # the caller failed before it asked (a bad speaker, Ctrl-C)
    assert pid not in children_of(os.getpid())


def test_no_fork_where_it_gains_nothing_or_is_unsafe(monkeypatch):
    import torch  # noqa: F401

    assert align_ahead.start(WAV, TEXT, with_phones=True) is None  # torch imported: a second call, a worker
    monkeypatch.delitem(sys.modules, "torch")
    monkeypatch.setattr(align_ahead.threading, "active_count", lambda: 2)
    assert align_ahead.start(WAV, TEXT, with_phones=True) is None  # other threads: a fork copies their locks
    monkeypatch.setattr(align_ahead.threading, "active_count", lambda: 1)
    assert align_ahead.start(WAV, "   ", with_phones=True) is None
    monkeypatch.setattr(align_ahead, "cores", lambda: 1)
    assert align_ahead.start(WAV, TEXT, with_phones=True) is None


def test_align_file_answers_as_the_forked_aligner_does():
    """align_file (the batch's main process aligning waiting items): align_phones' words and phones and the
    Match, or its FacegenError raised by result(), with the time it took."""
    from facegen.align import align, align_phones

    done = align_ahead.align_file(WAV, TEXT, with_phones=True)
    assert done.result()[:2] == align_phones(*load_audio(WAV), TEXT) and done.error is None
    assert done.result()[2].score > 0.5
    assert 0 < done.cpu_seconds and 0 < done.seconds
    failed = align_ahead.align_file(WAV, "?!", with_phones=False)
    with pytest.raises(FacegenError) as here:
        align(*load_audio(WAV), "?!")
    assert failed.error == str(here.value) and failed.words is None
    with pytest.raises(FacegenError, match="the transcript is empty"):
        failed.result()


def test_while_the_alignment_runs_the_word_vectors_are_computed_and_meanwhile_called(monkeypatch):
    """The work that needs no word times is done while they are found: the same clip as without it."""
    import facegen.text
    from facegen.animator import Animator
    from facegen.bundle import load_bundle
    from facegen.exchange import import_writer

    animator = Animator(load_bundle())
    bundle = animator.bundle
    later = animator.prepare(WAV, text=TEXT)
    found = align_ahead.align_file(WAV, TEXT, with_phones=bool(bundle.config.n_phones))

    class Running(align_ahead.Aligned):
        def ready(self) -> bool:  # still aligning when asked
            return False

    def no_late_features(*args, **kwargs):
        raise AssertionError("the word vectors were computed again after the alignment")

    called = []
    monkeypatch.setattr(facegen.text, "text_features", no_late_features)
    meanwhile = Running(found.words, found.phones, found.match)
    clip = animator.prepare(WAV, text=TEXT, aligned=meanwhile,
                            meanwhile=lambda: called.append(import_writer("out.usdc")))
    assert called == [None] and "pxr.UsdGeom" in sys.modules and "pxr.UsdMedia" in sys.modules
    assert clip.words == later.words
    assert np.array_equal(clip.text_features, later.text_features) and np.array_equal(clip.phones,
                                                                                      later.phones)
