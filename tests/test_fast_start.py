"""Fast start, through real `python -m facegen` processes: complete outputs and unchanged exit codes although
the process skips the interpreter's teardown, imports only what a command needs, quiet when nothing is wrong
(no CPU note, no progress-bar frames in logs), the profile still printed. No timed asserts:
benchmarks/bench_start.py measures the time."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

ROOT = Path(__file__).resolve().parents[1]
WAV = ROOT / "examples" / "excellent_room.wav"
TXT = ROOT / "examples" / "excellent_room.txt"
HEAVY = ("torch", "transformers", "scipy", "librosa", "numba")


def facegen(*args, env: dict | None = None, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "facegen", *map(str, args)], capture_output=True, text=True,
                          env={**os.environ, "HF_HUB_OFFLINE": "1", **(env or {})}, timeout=600, check=False,
                          **kwargs)


def imported(args: list, cwd: Path | None = None) -> tuple[subprocess.CompletedProcess, set[str]]:
    """Run `python -X importtime -m facegen ARGS`: the result and the top-level packages it imported."""
    proc = subprocess.run([sys.executable, "-X", "importtime", "-m", "facegen", *map(str, args)],
                          capture_output=True,
                          text=True, env={**os.environ, "HF_HUB_OFFLINE": "1"}, cwd=cwd, timeout=600,
                          check=False)
    names = {m.group(1).split(".")[0] for m in re.finditer(r"^import time:.*\|\s*(\S+)$", proc.stderr,
                                                           re.MULTILINE)}
    assert "click" in names, proc.stderr[-2000:]  # the listing is there: an empty one proves nothing
    return proc, names


@pytest.fixture(scope="module")
def animated(tmp_path_factory):
    """`facegen animate` with the built-in model on the example clip, not quiet, profiled, stderr a pipe. A
    first run before it: the first animate on a machine (or after a change to the code the ARKit shapes are
    made by) builds those shapes once, with scipy, and caches them (facegen.arkit.shapes); the fast start
    measured here is every later run's, whatever ran before this test."""
    warm = facegen("animate", WAV, "--text-file", TXT, "-o", tmp_path_factory.mktemp("warm") / "out.usdc",
                   "-q")
    assert warm.returncode == 0, warm.stderr
    d = tmp_path_factory.mktemp("fast")
    proc = facegen("animate", WAV, "--text-file", TXT, "-o", d / "out.usdc", env={"FACEGEN_PROFILE": "1"})
    return d, proc


def test_animate_output_is_complete_after_the_fast_exit(animated):
    from pxr import Usd, UsdGeom

    d, proc = animated
    assert proc.returncode == 0, proc.stderr
    stage = Usd.Stage.Open(str(d / "out.usdc"))
    mesh = next(UsdGeom.Mesh(p) for p in stage.Traverse() if p.IsA(UsdGeom.Mesh))
    times = mesh.GetPointsAttr().GetTimeSamples()
    audio_frames = sf.info(WAV).duration * 25
    assert len(times) == round(audio_frames) or len(times) == int(np.ceil(audio_frames))
    last = np.asarray(mesh.GetPointsAttr().Get(times[-1]))
    assert last.shape == (23370, 3) and np.isfinite(last).all()
    samples, rate = sf.read(d / "out.wav")
    reference, reference_rate = sf.read(WAV)
    assert rate == reference_rate and len(samples) == len(reference) and np.abs(samples).max() > 0.01
    assert sorted(p.name for p in d.iterdir()) == ["out.usdc", "out.wav"]  # no temporary left behind


def test_animate_says_only_what_it_wrote_and_the_profile(animated):
    _, proc = animated
    assert "\r" not in proc.stderr and "CUDA" not in proc.stderr and "CPU" not in proc.stderr, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert lines[0].startswith("facegen: wrote ") and "out.usdc" in lines[0] and len(lines) == 2, proc.stderr
    profile = json.loads(lines[1])  # FACEGEN_PROFILE=1: still printed, by the atexit handler before os._exit
    stages = profile["facegen_profile"]
    assert {"model_load", "alignment", "text_model_load", "text_features", "inference",
            "writing"} <= stages.keys()
    assert "transformers" not in profile["heavy_modules"] and "scipy" not in profile["heavy_modules"]
    assert proc.stdout == ""


def test_stdout_is_flushed_before_the_fast_exit(tmp_path):
    info = facegen("info", "--json")
    assert info.returncode == 0, info.stderr
    assert json.loads(info.stdout)["text_backend"]["id"] == "minilm"
    words = facegen("align", WAV, "--text-file", TXT)
    assert words.returncode == 0, words.stderr
    found = json.loads(words.stdout)
    assert [w["word"] for w in found["words"]][:3] == ["What", "an", "excellent"]


def test_exit_codes_are_unchanged(tmp_path):
    missing = facegen("animate", tmp_path / "missing.wav", "--no-text", "-o", tmp_path / "out.usda")
    assert missing.returncode == 2 and missing.stderr.startswith("facegen: error: ") and \
        len(missing.stderr.strip().splitlines()) == 1, missing.stderr
    usage = facegen("animate", WAV, "--no-text", "-o", tmp_path / "out.usda", "--device", "tpu")
    assert usage.returncode == 2 and "--device" in usage.stderr
    np.save(tmp_path / "anim.npy", np.zeros((3, 30), np.float32))
    failed = facegen("validate", tmp_path / "anim.npy")  # a check fails (no template for a .npy): exit 1
    assert failed.returncode == 1 and "FAIL" in failed.stdout, failed.stdout + failed.stderr
    assert facegen("--version").returncode == 0 and facegen("--help").returncode == 0
    assert list(tmp_path.iterdir()) == [tmp_path / "anim.npy"]


def test_ctrl_c_still_exits_130_and_leaves_nothing(tmp_path):
    out = tmp_path / "out.usda"
    proc = subprocess.Popen([sys.executable, "-m", "facegen", "animate", str(WAV), "--no-text", "-o",
                             str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env={**os.environ,
                                                                                 "HF_HUB_OFFLINE": "1"})
    deadline = time.monotonic() + 300
    while not any(p.name.startswith(".out.") for p in tmp_path.iterdir()) and proc.poll() is None:
        assert time.monotonic() < deadline
        time.sleep(0.005)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    if proc.returncode == 0:
        pytest.skip("the run finished before the signal arrived")
    assert proc.returncode == 130, err.decode()
    assert err.decode().strip().splitlines()[-1] == "facegen: interrupted"
    assert list(tmp_path.iterdir()) == []


def test_asking_for_cuda_without_one_is_still_an_error(tmp_path):
    import torch

    if torch.cuda.is_available():
        pytest.skip("this machine has a CUDA GPU")
    proc = facegen("animate", WAV, "--no-text", "-o", tmp_path / "out.usda", "--device", "cuda")
    assert proc.returncode == 2 and "torch sees no CUDA GPU" in proc.stderr, proc.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("args", [["--help"], ["animate", "--help"], ["info"], ["info", "--json"]])
def test_commands_that_need_no_network_import_no_torch(args):
    proc, names = imported(args)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert not names & set(HEAVY), sorted(names & set(HEAVY))


def test_validate_imports_no_torch(tmp_path):
    np.save(tmp_path / "anim.npy", np.zeros((3, 30), np.float32))
    proc, names = imported(["validate", tmp_path / "anim.npy"])
    assert proc.returncode == 1  # the .npy has no template: one failed check, as the test above
    assert not names & set(HEAVY), sorted(names & set(HEAVY))


def test_animate_on_the_cpu_imports_neither_torch_nor_transformers(animated):
    """The network and the packaged MiniLM run in numpy (facegen.numpy_network, facegen.minilm)."""
    d, _ = animated
    proc, names = imported(["animate", WAV, "--text-file", TXT, "-q", "-o", d / "again.usdc"])
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert {"tokenizers", "safetensors", "pxr"} <= names
    assert not names & {"torch", "transformers"}, sorted(names & {"torch", "transformers"})


# ---------------------------------------------------------------- progress bars: one home, a terminal only


def bar_script(leave: bool, enabled: bool = True) -> str:
    return ("from facegen.runtime import progress_bar\n"
            f"bar = progress_bar(total=4, desc='render', unit='frame', leave={leave}, enabled={enabled})\n"
            "for _ in range(4):\n    bar.update(1)\nbar.close()\n"
            f"print(sum(1 for _ in progress_bar(range(3), desc='import', unit='seq', leave={leave})))\n")


def test_progress_in_a_log_is_one_summary_line_at_most():
    run = [sys.executable, "-c"]
    kept = subprocess.run(run + [bar_script(leave=True)], capture_output=True, text=True, check=True)
    assert kept.stdout == "3\n"
    assert re.fullmatch(r"facegen: render: 4 frame in \d+\.\d s\nfacegen: import: 3 seq in \d+\.\d s\n",
                        kept.stderr), kept.stderr
    transient = subprocess.run(run + [bar_script(leave=False)], capture_output=True, text=True, check=True)
    assert transient.stderr == "" and transient.stdout == "3\n"
    quiet = subprocess.run(run + [bar_script(leave=True, enabled=False)], capture_output=True, text=True,
                           check=True)
    # only the enabled 'import' bar speaks
    assert quiet.stderr.count("\n") == 1 and "render" not in quiet.stderr


def test_progress_on_a_terminal_is_a_bar():
    import fcntl
    import pty
    import struct
    import termios

    main, child = pty.openpty()
    fcntl.ioctl(child, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))  # a terminal 100 columns wide
    proc = subprocess.Popen([sys.executable, "-c", bar_script(leave=True)], stdout=subprocess.PIPE,
                            stderr=child)
    os.close(child)
    out, _ = proc.communicate(timeout=120)
    chunks = []
    while True:
        try:
            chunk = os.read(main, 4096)
        except OSError:  # the terminal closed with the process
            break
        if not chunk:
            break
        chunks.append(chunk)
    os.close(main)
    drawn = b"".join(chunks).decode()
    assert out == b"3\n"
    assert "\r" in drawn and "4/4" in drawn and "3/3" in drawn and "facegen: render" not in drawn


def test_no_module_imports_tqdm_but_the_runtime():
    users = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "facegen").rglob("*.py")
                   if re.search(r"^\s*(from tqdm|import tqdm)", p.read_text(), re.MULTILINE))
    assert users == ["facegen/runtime.py"]
