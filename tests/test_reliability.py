"""Nothing half-written: temporaries of killed runs are cleaned, signals unwind like Ctrl-C, a full disk is one line."""

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
    with pytest.raises(FacegenError) as info, atomic.atomic_path(target, need_bytes=5_000_000) as tmp:
        tmp.write_bytes(b"x" * 100)
        raise OSError(errno.ENOSPC, "No space left on device")
    message = str(info.value)
    assert message.startswith("no space left on ") and str(target) in message and "need about 5 MB" in message
    assert "\n" not in message and list(tmp_path.iterdir()) == []


def test_check_space_refuses_before_work(tmp_path):
    with pytest.raises(FacegenError, match="no space left on .* need about"):
        atomic.check_space(tmp_path / "out.usdc", need_bytes=1 << 62)
    atomic.check_space(tmp_path / "out.usdc", need_bytes=1)


def _tmpfs(tmp_path: Path, size: str) -> Path:
    mount = tmp_path / "small"
    mount.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(mount)],
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
        subprocess.run(["umount", str(mount)], check=False)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_signal_during_animate_leaves_nothing(tmp_path, sig):
    out = tmp_path / "out.usda"
    env = dict(os.environ, HF_HUB_OFFLINE="1")
    proc = subprocess.Popen([sys.executable, "-m", "facegen", "animate", str(EXAMPLE), "--no-text", "-o", str(out)],
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
