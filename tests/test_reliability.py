"""Nothing half-written: temporaries of killed runs are cleaned, signals unwind like Ctrl-C, a full disk is
one line."""

from __future__ import annotations

import errno
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from helpers import rig_clip

from facegen import atomic
from facegen.errors import FacegenError

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "excellent_room.wav"


def dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_temporary_names_carry_the_mark_and_are_removed_on_failure(tmp_path):
    target = tmp_path / "out.npy"
    with pytest.raises(RuntimeError), atomic.atomic_path(target) as tmp:
        assert tmp.parent == tmp_path and tmp.name.startswith(atomic.temp_prefix(target))
        np.save(tmp, np.zeros(3))
        raise RuntimeError("writer failed")
    assert list(tmp_path.iterdir()) == []


def test_a_later_run_removes_only_dead_runs_temporaries(tmp_path):
    pid = dead_pid()
    stale_file = tmp_path / f".out.{atomic.TEMP_MARK}-{atomic.HOST}-{pid}-k2j3.usdc"
    stale_pxr = tmp_path / f"..out.{atomic.TEMP_MARK}-{atomic.HOST}-{pid}-k2j3.usdc.tmp9x"
    stale_dir = tmp_path / f".out.{atomic.TEMP_MARK}-{atomic.HOST}-{pid}-zz"
    live = tmp_path / f".out.{atomic.TEMP_MARK}-{atomic.HOST}-{os.getppid()}-abcd.usdc"
    other_host = tmp_path / f".out.{atomic.TEMP_MARK}-ffffff-{pid}-abcd.usdc"
    users = [tmp_path / ".out.abcd1234.usdc", tmp_path / "facegen-tmp-notes.txt", tmp_path / "take.usdc"]
    for p in (stale_file, stale_pxr, live, other_host, *users):
        p.write_bytes(b"x" * 10)
    stale_dir.mkdir()
    (stale_dir / "inner.wav").write_bytes(b"x")
    atomic._cleaned.discard(str(tmp_path.resolve()))
    with atomic.atomic_path(tmp_path / "new.npy") as tmp:
        np.save(tmp, np.zeros(2))
    left = {p.name for p in tmp_path.iterdir()}
    assert left == {live.name, other_host.name, "new.npy", *(p.name for p in users)}


def test_disk_full_while_writing_is_one_line(tmp_path):
    target = tmp_path / "out.npy"
    with pytest.raises(FacegenError) as info, atomic.atomic_path(target) as tmp:
        tmp.write_bytes(b"x" * 3_000_000)
        raise OSError(errno.ENOSPC, "No space left on device")
    message = str(info.value)
    assert message.startswith("no space left on ") and str(target) in message and "need about 3 MB" in message
    assert "\n" not in message and list(tmp_path.iterdir()) == []


def _tmpfs(tmp_path: Path, size: str) -> Path:
    mount = tmp_path / "small"
    mount.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs",
                                            str(mount)],
                                           check=False, capture_output=True).returncode != 0:
        pytest.skip("cannot mount a small tmpfs here (needs root)")
    return mount


@pytest.mark.parametrize("suffix", [".npy", ".usdc", ".usda", ".glb"])
def test_disk_full_on_a_small_tmpfs(tmp_path, suffix):
    from facegen.exchange import write_animation

    mount = _tmpfs(tmp_path, "256k")
    try:
        anim = rig_clip(40)
        out = mount / f"out{suffix}"
        proc_err = None
        try:
            write_animation(anim, out)
        except FacegenError as exc:
            proc_err = str(exc)
        assert proc_err is not None and proc_err.startswith("no space left on ") and "\n" not in proc_err
        assert [p.name for p in mount.iterdir()] == []
    finally:
        subprocess.run(["umount", "-l", str(mount)], check=False)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_signal_during_animate_leaves_nothing(tmp_path, sig):
    out = tmp_path / "out.usda"
    env = dict(os.environ, HF_HUB_OFFLINE="1")
    proc = subprocess.Popen([sys.executable, "-m", "facegen", "animate", str(EXAMPLE), "--no-text", "-o",
                             str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, cwd=ROOT)
    deadline = time.monotonic() + 300
    while not any(p.name.startswith(".out.") for p in tmp_path.iterdir()) and proc.poll() is None:
        assert time.monotonic() < deadline
        time.sleep(0.005)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    if proc.returncode == 0:
        pytest.skip("the run finished before the signal arrived")
    assert proc.returncode == 128 + sig, err.decode()
    assert err.decode().strip().splitlines()[-1] == f"facegen: stopped by {signal.Signals(sig).name}"
    assert list(tmp_path.iterdir()) == []


def test_templates_pkl_memory_bomb_refused_in_bounded_memory(tmp_path):
    import pickle
    import tracemalloc

    from facegen.datasets.templates import read_templates_pkl

    try:
        from numpy._core import multiarray
    except ImportError:  # numpy < 2
        from numpy.core import multiarray

    class Bomb:
        def __reduce__(self):
            return multiarray._reconstruct, (np.ndarray, (3 * 10**8,), b"f")

    path = tmp_path / "templates.pkl"
    path.write_bytes(pickle.dumps({"F1": Bomb()}, protocol=2))
    assert path.stat().st_size < 200
    tracemalloc.start()
    with pytest.raises(FacegenError, match="out of nothing"):
        read_templates_pkl(path)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 50e6


def test_tar_member_bigger_than_any_frame_refused_before_reading(tmp_path):
    import io
    import tarfile

    from facegen.datasets.raw import _vl_frames

    path = tmp_path / "F1_e01.tgz"
    with tarfile.open(path, "w:gz") as tar:
        small = tarfile.TarInfo("frame_000.vl")
        small.size = 8
        tar.addfile(small, io.BytesIO(b"\0" * 8))
        huge = tarfile.TarInfo("frame_001.vl")
        huge.size = 1 << 30
        tar.addfile(huge)  # the header only: the archive claims 1 GB that is not there
    with pytest.raises(FacegenError, match="frame_001.vl is 1074 MB"):
        _vl_frames(path)


@pytest.mark.parametrize("kind", ["json", "csv"])
def test_alignment_with_impossible_word_rate_refused(tmp_path, kind):
    from facegen.alignment_files import read_alignment

    n = 2000
    path = tmp_path / f"words.{kind}"
    if kind == "json":
        import json

        path.write_text(json.dumps([{"word": "la", "start": i * 0.002, "end": i * 0.002 + 0.001}
                                    for i in range(n)]))
    else:
        path.write_text("word,start,end\n" + "".join(f"la,{i * 0.002:.4f},{i * 0.002 + 0.001:.4f}\n"
                                                     for i in range(n)))
    with pytest.raises(FacegenError, match="2000 words for 4.4 s of audio"):
        read_alignment(path, duration=4.4)
    assert len(read_alignment(path, duration=400.0)) == n


def test_transcript_with_impossible_word_rate_refused_before_aligning():
    from facegen.align import align

    audio = np.zeros(16000 * 2, np.float32)
    with pytest.raises(FacegenError, match="the transcript has 500 words for 2.0 s"):
        align(audio, 16000, "word " * 500)


def test_deeply_nested_alignment_json_is_a_user_error(tmp_path):
    from facegen.alignment_files import read_alignment

    path = tmp_path / "words.json"
    path.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(FacegenError, match="nested too deeply"):
        read_alignment(path, duration=4.0)


def test_outputs_follow_the_umask_even_when_the_writer_makes_0600_files(tmp_path):
    target = tmp_path / "m.safetensors"
    old = os.umask(0o022)
    try:
        with atomic.atomic_path(target) as tmp:
            fd = os.open(tmp, os.O_CREAT | os.O_WRONLY, 0o600)
            os.close(fd)
    finally:
        os.umask(old)
    assert target.stat().st_mode & 0o777 == 0o644


def test_overlong_output_name_is_one_line(tmp_path):
    with pytest.raises(FacegenError, match="bytes long; this file system allows"):
        atomic.check_writable(tmp_path / ("a" * 300 + ".usdc"))
    # the longest names still get a temporary
    with atomic.atomic_path(tmp_path / ("b" * 240 + ".npy")) as tmp:
        np.save(tmp, np.zeros(1))
    assert (tmp_path / ("b" * 240 + ".npy")).is_file()
