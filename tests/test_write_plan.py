"""The write plan (exchange/plan.py), the multi-file Transaction (atomic.py), the alignment format table."""

import os

import pytest

from facegen import atomic
from facegen.alignment_files import alignment_format, read_alignment, write_alignment
from facegen.atomic import Transaction, atomic_path
from facegen.errors import FacegenError
from facegen.exchange import format_of_extension
from facegen.exchange.plan import plan_write
from facegen.words import Word


def test_a_transaction_places_all_its_files_at_the_end_or_none(tmp_path):
    with pytest.raises(RuntimeError), Transaction() as transaction:
        with atomic_path(tmp_path / "a.usda") as tmp:
            tmp.write_text("a")
        (transaction.folder(tmp_path / "a.clips") / "x.usdc").write_text("x")
        raise RuntimeError("the preview failed")
    assert list(tmp_path.iterdir()) == []
    with Transaction() as transaction:
        with atomic_path(tmp_path / "a.usda") as tmp:
            tmp.write_text("a")
        (transaction.folder(tmp_path / "a.clips") / "x.usdc").write_text("x")
        assert not (tmp_path / "a.usda").exists()  # renamed at the commit, not before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.clips", "a.usda"]
    assert (tmp_path / "a.clips" / "x.usdc").read_text() == "x"


def test_a_caught_failure_inside_a_transaction_removes_only_its_own_files(tmp_path):
    with Transaction():
        with atomic_path(tmp_path / "kept.npy") as tmp:
            tmp.write_text("k")
        with pytest.raises(ValueError), atomic_path(tmp_path / "lost.npy") as tmp:
            tmp.write_text("l")
            raise ValueError
    assert [p.name for p in tmp_path.iterdir()] == ["kept.npy"]


def test_ctrl_c_the_moment_a_temporary_appears_leaves_nothing(tmp_path, monkeypatch):
    """A temporary is staged before it is made: an interrupt right after the file or folder appears (as
    Ctrl-C on a loaded machine did, between making a temporary and recording it) still removes it."""
    def made_then_interrupted(make):
        def wrapped(path):
            make(path)
            raise KeyboardInterrupt

        return wrapped

    monkeypatch.setattr(atomic, "_create_file", made_then_interrupted(atomic._create_file))
    with pytest.raises(KeyboardInterrupt), atomic_path(tmp_path / "out.usda"):
        pass
    assert list(tmp_path.iterdir()) == []
    monkeypatch.setattr(atomic.os, "mkdir", made_then_interrupted(os.mkdir))
    with pytest.raises(KeyboardInterrupt), Transaction() as transaction:
        transaction.folder(tmp_path / "out.clips")
    assert list(tmp_path.iterdir()) == []


def test_scratch_folders_carry_the_mark_and_outdated_paths_go_at_the_commit(tmp_path):
    old = tmp_path / "old.clips"
    old.mkdir()
    with Transaction() as transaction:
        scratch = transaction.scratch(tmp_path / "out.usdz")
        assert scratch.name.startswith(atomic.temp_prefix(tmp_path / "out.usdz"))
        assert atomic.TEMP_MARK in scratch.name
        transaction.remove(old)
        assert old.is_dir()
    assert list(tmp_path.iterdir()) == []


def test_the_plan_settles_options_sidecar_and_streaming_before_work(tmp_path):
    plan = plan_write(tmp_path / "o.usdc", options={"rig": "arkit"}, audio_source=tmp_path / "in.wav")
    assert plan.options == {"rig": "arkit", "mode": "blendshapes"} and plan.rig == "arkit"
    assert plan.sidecar == tmp_path / "o.wav" and not plan.streams  # blend shapes: a PCA over the whole clip
    assert plan_write(tmp_path / "o.usdc").streams and plan_write(tmp_path / "o.json").rig == "arkit"
    packaged = plan_write(tmp_path / "o.usdz", preview=tmp_path / "p.mp4")
    assert packaged.sidecar is None and not packaged.streams
    assert packaged.outputs == [tmp_path / "o.usdz", tmp_path / "p.mp4"]
    source = tmp_path / "o.wav"
    source.write_bytes(b"RIFF")
    assert plan_write(tmp_path / "o.npy", audio_source=source).sidecar is None  # the input audio is kept


def test_the_plan_refuses_what_it_can_know(tmp_path):
    with pytest.raises(FacegenError) as info:
        plan_write(tmp_path / "o.npy", options={"rig": "arkit", "tolerance": 0.1})
    assert info.value.params == ("rig", "tolerance") and "do not apply to .npy" in str(info.value)
    with pytest.raises(FacegenError, match="unknown extension '.fbx'"):
        plan_write(tmp_path / "o.fbx")
    with pytest.raises(FacegenError, match="does not exist"):
        plan_write(tmp_path / "missing" / "o.glb")
    (tmp_path / "o.wav").mkdir()
    with pytest.raises(FacegenError, match="is a folder"):
        plan_write(tmp_path / "o.glb")  # its sidecar cannot be written
    with pytest.raises(FacegenError, match="unknown rig"):
        plan_write(tmp_path / "o.usdz", options={"rig": "metahuman"})
    assert format_of_extension("USDC").name == "USD" and not os.listdir(tmp_path / "o.wav")


def test_alignment_formats_written_follow_the_table(tmp_path):
    assert alignment_format("w.csv").name == "CSV" and alignment_format("w.TextGrid", phones=True).phones
    with pytest.raises(FacegenError, match=r"cannot write phones to .*use a \.json or \.TextGrid file name"):
        alignment_format("w.csv", phones=True)
    with pytest.raises(FacegenError, match=r"use a \.json, \.TextGrid or \.csv file name"):
        alignment_format("w.xyz")
    words = [Word("hello", 0.1, 0.4), Word("there", 0.5, 0.9)]
    path = write_alignment(words, tmp_path / "w.csv")
    assert path.read_text().splitlines()[0] == "word,start,end"
    assert read_alignment(path, duration=1.0) == words
