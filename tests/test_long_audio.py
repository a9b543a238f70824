"""Long recordings (issue 22): every stage in bounded memory and short calls, with the results of one pass —
and SIGTERM honoured at every stage of a long clip (exit 143 within 2 s, one line, nothing left behind).
Speed and memory figures are benchmarks/bench_long.py's."""

from __future__ import annotations

import bisect
import json
import os
import pickle
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from facegen import audio, inference, torch_states
from facegen.arkit import solve
from facegen.atomic import TEMP_MARK

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def speech(tmp_path_factory) -> tuple[Path, Path, float]:
    """About 150 s of speech (espeak sentences with pauses) at 22.05 kHz, and its transcript."""
    from facegen.espeak import synthesize
    from facegen.synth.sentences import generated_sentences

    folder = tmp_path_factory.mktemp("long")
    parts, words, total = [], [], 0.0
    for i, text in enumerate(generated_sentences(60).values()):
        said = synthesize(text, variant=("m1", "f3")[i % 2], sample_rate=22050)
        parts += [said.audio, np.full(int(0.4 * 22050), 1e-4, np.float32)]
        words.append(text)
        total += len(said.audio) / 22050 + 0.4
        if total > 150:
            break
    wav, txt = folder / "long.wav", folder / "long.txt"
    sf.write(wav, np.concatenate(parts), 22050, subtype="PCM_16")
    txt.write_text(" ".join(words) + "\n")
    return wav, txt, total


# ------------------------------------------------------------------------------------------ the same results


def test_network_in_pieces_equals_one_pass():
    """torch's network (a CUDA device's path, here on the CPU) in LONG_FRAMES pieces equals its one pass, and
    the numpy network (the CPU's) equals both."""
    import torch

    from facegen.bundle import load_bundle

    cpu = torch.device("cpu")
    bundle = load_bundle(None)
    cfg = bundle.model.cfg
    T = 2 * torch_states.LONG_FRAMES + 1234
    rng = np.random.default_rng(0)
    mel = (rng.standard_normal((T, cfg.n_mels)) * 10 - 50).astype(np.float32)
    text = (0.1 * rng.standard_normal((T, cfg.text_dim))).astype(np.float32)
    phones = np.eye(cfg.n_phones, dtype=np.float32)[rng.integers(0, cfg.n_phones, T)]
    pieces = inference.decoder_states(bundle, mel, text, 1, phones=phones, device=cpu)
    short = [(mel[:500], text[:500], 0, phones[:500])]
    both = inference.batch_decoder_states(bundle, [*short, (mel, text, 1, phones)], device=cpu)
    torch_states.LONG_FRAMES, limit = 10**9, torch_states.LONG_FRAMES
    try:
        whole = inference.decoder_states(bundle, mel, text, 1, phones=phones, device=cpu)
        alone = inference.decoder_states(bundle, *short[0][:3], phones=short[0][3], device=cpu)
    finally:
        torch_states.LONG_FRAMES = limit
    assert pieces.shape == (T, 2 * cfg.lstm_dim)
    assert float((pieces - whole).abs().max()) < 1e-5 < float(whole.abs().max())
    assert float((both[1] - whole).abs().max()) < 1e-5 and float((both[0] - alone).abs().max()) < 1e-5
    in_numpy = inference.decoder_states(bundle, mel, text, 1, phones=phones)
    assert isinstance(in_numpy, np.ndarray) and in_numpy.shape == (T, 2 * cfg.lstm_dim)
    assert float(np.abs(in_numpy - whole.numpy()).max()) < 1e-5


def test_mel_features_in_blocks_equal_one_stft():
    import torch

    from facegen.audio import FeatureConfig, mel_features, mel_filters

    cfg = FeatureConfig()
    rng = np.random.default_rng(1)
    samples = (0.1 * rng.standard_normal(16000 * 100 + 77)).astype(np.float32)  # 2,500 frames: two blocks
    filters = mel_filters(cfg)
    window = torch.hann_window(cfg.n_fft)
    spec = torch.stft(torch.from_numpy(samples), cfg.n_fft, cfg.hop_length, window=window, center=True,
                      pad_mode="constant", return_complex=True)
    power = spec.real.square() + spec.imag.square()
    reference = (10 * torch.log10(torch.clamp(torch.from_numpy(filters) @ power, min=cfg.amin))).T.numpy()
    feats = mel_features(samples, 16000, cfg, filters)
    assert feats.shape == (2500, cfg.n_mels) and len(reference) > audio.MEL_FRAMES
    np.testing.assert_allclose(feats, reference[:2500], atol=1e-4)


def test_resample_in_blocks_equals_one_call():
    import soxr

    x = np.random.default_rng(2).standard_normal(3 * audio.RESAMPLE_BLOCK + 5).astype(np.float32)
    for rates in ((48000, 16000), (8000, 16000), (44100, 22050)):
        expected = soxr.resample(x, *rates, quality="HQ")
        assert np.array_equal(audio.resample(x, *rates), expected)


def test_long_high_rate_audio_is_held_at_a_lower_rate(tmp_path, monkeypatch):
    x = (0.3 * np.random.default_rng(3).standard_normal((48000 * 30, 2))).astype(np.float32)
    path = tmp_path / "stereo.wav"
    sf.write(path, x, 48000, subtype="FLOAT")
    samples, rate = audio.load_audio(path)  # 5.8 MB as mono float32: under the bound
    assert rate == 48000 and np.array_equal(samples, x.mean(axis=1))
    monkeypatch.setattr(audio, "HELD_BYTES", 4 << 20)  # 30 s at 48 kHz no longer fits: 32 kHz does
    held, rate = audio.load_audio(path)
    assert rate == 32000 and np.array_equal(held, audio.resample(x.mean(axis=1), 48000, 32000))
    assert audio.held_rate(16000, 10**9) == 16000 and audio.held_rate(8000, 10**9) == 8000


def test_wav_written_in_blocks_is_the_clipped_signal(tmp_path):
    x = (0.8 * np.random.default_rng(4).standard_normal((1 << 22) + 10)).astype(np.float32)
    audio.write_wav(x, 16000, tmp_path / "a.wav")
    sf.write(tmp_path / "b.wav", np.clip(x, -1, 1), 16000, subtype="PCM_16", format="WAV")
    assert (tmp_path / "a.wav").read_bytes() == (tmp_path / "b.wav").read_bytes()


def test_arkit_solve_in_blocks_matches_one_converged_solve():
    rng = np.random.default_rng(5)
    basis = rng.standard_normal((200, 12))
    basis[:, 1] = basis[:, 0] + 1e-3 * rng.standard_normal(200)  # two shapes nearly alike (jawLeft, jawRight)
    truth = np.clip(0.5 + 0.6 * np.sin(np.linspace(0, 40, 2600)[:, None] * rng.uniform(0.2, 1, 12)), 0, 1)
    gram, rhs = basis.T @ basis, (truth @ basis.T + 0.3 * rng.standard_normal((2600, 200))) @ basis
    blocks = solve.solve_weights(gram, rhs, 5.0, ridge=1e-5, block_frames=1000, margin=300)
    whole = solve.solve_weights(gram, rhs, 5.0, ridge=1e-5, block_frames=10**9, tol=1e-9, max_iter=50000)

    def cost(w):
        return float(np.einsum("tk,kl,tl->", w, gram + 1e-5 * np.diag(np.diag(gram)), w) - 2 * np.vdot(w, rhs)
                     + 5.0 * np.sum(np.diff(w, axis=0) ** 2))

    assert blocks.min() >= 0 and blocks.max() <= 1 and ((blocks == 0) | (blocks == 1)).mean() > 0.05
    assert cost(blocks) - cost(whole) < 1e-6 * abs(cost(whole))
    assert np.abs(blocks @ basis.T - whole @ basis.T).max() < 1e-3  # the posed shapes agree


def test_a_streams_projection_is_its_frames_projection():
    rng = np.random.default_rng(6)
    states = rng.standard_normal((700, 16)).astype(np.float32)
    weight = (0.01 * rng.standard_normal((90, 16))).astype(np.float32)
    base = rng.standard_normal(90).astype(np.float32)
    stream = inference.FrameStream(states, weight, base, block_frames=128)
    basis = rng.standard_normal((5, 90)).astype(np.float32)
    origin = rng.standard_normal(90).astype(np.float32)
    expected = (np.asarray(stream).reshape(700, -1).astype(np.float64) - origin) @ basis.T.astype(np.float64)
    np.testing.assert_allclose(stream.project(basis, origin), expected, rtol=1e-5, atol=1e-4)


def test_arkit_json_in_parts_is_json_dumps():
    from types import SimpleNamespace

    from facegen.exchange import arkit_json

    weights = np.random.default_rng(7).uniform(0, 1, (arkit_json.ROWS + 3, 52)).astype(np.float32)
    fit = SimpleNamespace(names=tuple(f"s{i}" for i in range(52)), weights=weights, lip_error_mm=0.1,
                          face_error_mm=0.2)
    text = "".join(arkit_json._document(SimpleNamespace(fps=25.0, metadata={"model": "m"}, head=None), fit,
                                        "t.wav"))
    doc = json.loads(text)
    assert doc["numFrames"] == len(weights) and list(doc)[-2:] == ["weightMat", "facegen"]
    doc["weightMat"] = weights.astype(np.float64).round(arkit_json.DECIMALS).tolist()
    assert text == json.dumps(doc, separators=(",", ":")) + "\n"


_HEAR_WITH_HELPER = """
import pickle, sys
from facegen import audio, recognition
recognition.HELPER_SECONDS = 20.0  # the second half in a forked helper
made, start = [], recognition._helper
recognition._helper = lambda *args: made.append(start(*args)) or made[-1]
heard = recognition.hear(*audio.load_audio(sys.argv[1]))
sys.stdout.buffer.write(pickle.dumps((heard, made[0] is not None)))
"""


@pytest.mark.slow
def test_long_audio_is_heard_in_pieces_with_phones(speech):
    from facegen import recognition

    wav, _, seconds = speech
    samples, rate = audio.load_audio(wav)
    heard = recognition.hear(samples, rate)  # 150 s: all here
    # the helper in a new process: no fork while another test's threads linger here (hear would not fork)
    done = subprocess.run([sys.executable, "-c", _HEAR_WITH_HELPER, str(wav)], capture_output=True, cwd=REPO,
                          env=dict(os.environ, HF_HUB_OFFLINE="1"), check=True)
    helped, forked = pickle.loads(done.stdout)
    assert helped == heard and forked  # pieces do not depend on
    # each other (every pass in steps: a whole-utterance pass would change the next piece's words)
    assert seconds > recognition.LONG_SECONDS and len(heard.words) > 100 and heard.phones
    starts = [w.start for w in heard.words]
    assert starts == sorted(starts) and heard.words[-1].end <= seconds + 0.5 and starts[-1] > seconds - 20
    assert all(0 <= c <= 1 for c in heard.confidences) and len(heard.confidences) == len(heard.words)
    for _, start, end in heard.phones:  # every phone inside a word
        word = heard.words[bisect.bisect_right(starts, start + 0.011) - 1]
        assert word.start - 0.011 <= start < end <= word.end + 0.011


# ------------------------------------------------------------------------------------------ SIGTERM


def _stop_at(command: list[str], folder: Path, ready) -> tuple[int, float, list[str]]:
    """Run `command`; once `ready(stderr lines so far, folder, its pid)` holds, send SIGTERM: (exit code,
    seconds from the signal to the exit, the stderr lines said after it). The process runs in a session of
    its own, so that any process it left behind is found by its session."""
    proc = subprocess.Popen(command, stderr=subprocess.PIPE, text=True, cwd=REPO, start_new_session=True,
                            env=dict(os.environ, HF_HUB_OFFLINE="1"))
    lines: list[str] = []
    os.set_blocking(proc.stderr.fileno(), False)
    deadline = time.monotonic() + 300
    while not ready(lines, folder, proc.pid):
        assert proc.poll() is None, f"it ended before the stage: {lines[-3:]}"
        assert time.monotonic() < deadline, f"the stage never came: {lines[-3:]}"
        lines += [line.rstrip("\n") for line in proc.stderr.readlines()]
        time.sleep(0.05)
    said = len(lines)
    sent = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(timeout=30)
    finally:
        proc.kill()
    took = time.monotonic() - sent
    os.set_blocking(proc.stderr.fileno(), True)
    lines += [line.rstrip("\n") for line in proc.stderr.read().splitlines()]
    left = subprocess.run(["ps", "-o", "pid=", "-s", str(proc.pid)], capture_output=True, text=True,
                          check=False).stdout
    assert not left.strip(), f"processes left behind: {left}"
    return proc.returncode, took, lines[said:]


def _said(text: str, after: float = 0.0):
    """Ready `after` seconds once a stderr line holds `text`."""
    seen: dict[Path, float] = {}

    def ready(lines: list[str], folder: Path, _pid: int) -> bool:
        if folder not in seen and any(text in line for line in lines):
            seen[folder] = time.monotonic()
        return folder in seen and time.monotonic() >= seen[folder] + after

    return ready


def _forked(seconds: float):
    """Ready `seconds` after the command has a child process (the forked aligner; nothing says so)."""
    started: dict[Path, float] = {}

    def ready(_lines: list[str], folder: Path, pid: int) -> bool:
        if folder not in started:
            children = subprocess.run(["ps", "-o", "pid=", "--ppid", str(pid)], capture_output=True,
                                      text=True, check=False).stdout
            if not children.strip():
                return False
            started[folder] = time.monotonic()
        return time.monotonic() >= started[folder] + seconds

    return ready


def _after(seconds: float):
    """Ready `seconds` after the start."""
    started: dict[Path, float] = {}

    def ready(_lines: list[str], folder: Path, _pid: int) -> bool:
        return time.monotonic() >= started.setdefault(folder, time.monotonic()) + seconds

    return ready


def _writing(_lines: list[str], folder: Path, _pid: int) -> bool:
    """Ready once the output's temporary files exist."""
    return any(TEMP_MARK in p.name for p in folder.iterdir())


@pytest.mark.slow
@pytest.mark.parametrize(("name", "command", "ready"), [
    ("aligning (the forked aligner)", ["animate", "-o", "a.json", "--text-file"], _forked(2.0)),
    ("aligning (in the process)", ["align", "-o", "words.json", "--text-file"], _after(3.0)),  # 150 s: ~5 s
    ("recognising", ["animate", "-o", "r.json"], _said("recognising the words", 2.0)),
    ("the ARKit fit", ["animate", "-o", "f.json", "--text-file"], _said("inference for", 2.5)),
    ("writing the .npy", ["animate", "-o", "w.npy", "--text-file"], _writing),
])
def test_sigterm_is_honoured_at_every_stage(speech, tmp_path, name, command, ready):
    wav, txt, _ = speech
    out = tmp_path / "out"
    out.mkdir()
    kind, _, output, *transcript = command
    args = [kind, str(wav), "-o", str(out / output)] + ([transcript[0], str(txt)] if transcript else [])
    code, took, said = _stop_at([sys.executable, "-m", "facegen", *args], out, ready)
    print(f"{name}: exit {code} {took:.2f} s after SIGTERM")
    assert code == 128 + signal.SIGTERM, (name, said)
    assert took <= 2.0, f"{name}: {took:.2f} s"
    assert said == ["facegen: stopped by SIGTERM"], (name, said)
    assert list(out.iterdir()) == [], name


def test_a_long_clips_fit_errors_are_measured_on_spread_frames(monkeypatch):
    from helpers import rig_clip

    anim = rig_clip(300)
    exact = solve.fit_arkit(anim)
    monkeypatch.setattr(solve, "ERROR_FRAMES_MEASURED", 100)  # every third frame
    sampled = solve.fit_arkit(anim)
    assert np.array_equal(sampled.weights, exact.weights)
    assert sampled.lip_error_mm == pytest.approx(exact.lip_error_mm, rel=0.05)
    assert sampled.face_error_mm == pytest.approx(exact.face_error_mm, rel=0.05)
    assert sampled.lip_error_mm != exact.lip_error_mm
