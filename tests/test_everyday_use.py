"""What a new user meets first (issue 22): other frame rates, silent clips, validating facegen's own .npy and
glTF output without naming the face, `info` on a file that is not a bundle, the words heard without a
transcript. Real model, real audio, real files."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from facegen.errors import FacegenError

ROOT = Path(__file__).resolve().parents[1]
WAV = ROOT / "examples" / "excellent_room.wav"
TEXT = (ROOT / "examples" / "excellent_room.txt").read_text()


def facegen(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "facegen", *map(str, args)], capture_output=True, text=True,
                          env={**os.environ, "HF_HUB_OFFLINE": "1"}, timeout=600, check=False)


@pytest.fixture(scope="module")
def animator():
    from facegen.animator import Animator

    return Animator()


@pytest.fixture(scope="module")
def at_25(animator):
    return animator.animate(WAV, text=TEXT)


# ---- frame rates -----------------------------------------------------------------------------------------


def test_states_at_rate_interpolates_between_network_frames():
    from facegen.inference import states_at_rate

    states = np.arange(10, dtype=np.float32)[:, None] * np.array([[1.0, -2.0]], np.float32)
    same = states_at_rate(states, 25.0, 25.0, 10)
    assert same is states
    up = states_at_rate(states, 25.0, 50.0, 20)
    assert up.shape == (20, 2)
    assert np.allclose(up[::2], states) and np.allclose(up[1:-1:2], (states[:-1] + states[1:]) / 2)
    assert np.allclose(up[-1], states[-1])  # past the last network frame: held
    down = states_at_rate(states, 25.0, 24.0, 9)
    assert np.allclose(down[:, 0], np.arange(9) * 25 / 24)  # frame i at time i / 24


@pytest.mark.parametrize("fps", [24.0, 30.0, 60.0])
def test_other_frame_rates_keep_the_motion(animator, at_25, fps):
    anim = animator.animate(WAV, text=TEXT, fps=fps)
    duration = len(at_25.audio) / at_25.sample_rate
    assert anim.fps == fps and anim.num_frames == round(duration * fps)
    # the same motion in time: frames at the 25 fps times agree with the 25 fps frames (interpolated between)
    from facegen.lipsync import aperture

    a25 = aperture(at_25.vertices, at_25.mesh)
    a = aperture(anim.vertices, anim.mesh)
    resampled = np.interp(np.arange(len(a25)) / 25.0, np.arange(len(a)) / fps, a)
    assert np.corrcoef(a25, resampled)[0, 1] > 0.97
    # cm: closures and peaks kept as far as this rate samples them (the 25 fps motion at this rate's frame
    # times: a peak between two 24 fps frames reads lower at 24 fps, by 0.06 cm on this clip)
    sampled = np.interp(np.arange(len(a)) / fps, np.arange(len(a25)) / 25.0, a25)
    assert abs(a.min() - sampled.min()) < 0.01 and abs(a.max() - sampled.max()) < 0.01
    assert a.min() < 0.05 and a.max() > 0.9 * a25.max()
    assert np.array_equal(anim.audio, at_25.audio)


def test_bad_frame_rates_name_the_parameter(animator):
    for bad in (0, -25, float("nan"), float("inf"), 1000, "30", True):
        with pytest.raises(FacegenError, match="frame rate") as info:
            animator.animate(WAV, text=TEXT, fps=bad)
        assert info.value.param == "fps"


def test_fps_reaches_every_format(tmp_path):
    done = facegen("animate", WAV, "--text-file", ROOT / "examples" / "excellent_room.txt", "--fps", "30",
                   "-q", "-o", tmp_path / "out.json")
    assert done.returncode == 0, done.stderr
    data = json.loads((tmp_path / "out.json").read_text())
    seconds = sf.info(str(WAV)).duration
    assert data["exportFps"] == 30 and data["numFrames"] == len(data["weightMat"]) == round(seconds * 30)
    refused = facegen("animate", WAV, "--no-text", "--fps", "0", "-o", tmp_path / "x.npy")
    assert refused.returncode == 2 and "--fps" in refused.stderr and len(refused.stderr.splitlines()) == 1
    assert not (tmp_path / "x.npy").exists()


# ---- silence ---------------------------------------------------------------------------------------------


def test_a_silent_clip_is_the_neutral_face(animator, tmp_path):
    wav = tmp_path / "quiet.wav"
    sf.write(wav, np.zeros(16000 * 2, np.float32), 16000)
    notes = []
    from facegen.runtime import Reporter

    anim = animator.animate(wav, reporter=Reporter(note=notes.append), fps=30)
    assert anim.num_frames == 60 and anim.metadata["words"] == []
    frames = np.asarray(anim.vertices)
    still = np.concatenate([anim.regions[r] for r in ("lips", "jaw", "mouth_cavity")])
    rest = np.broadcast_to(anim.template[still], (len(frames), len(still), 3))
    assert np.array_equal(frames[:, still], rest)  # the mouth at rest; a listening face blinks, looks around
    assert anim.metadata["blinks"]["times"] and anim.metadata["saccades"]
    assert any("idle clip" in n for n in notes)
    with pytest.raises(FacegenError, match="silent") as info:
        animator.animate(wav, text="hello there")
    assert "text" in info.value.params
    done = facegen("animate", wav, "-q", "-o", tmp_path / "idle.usdc")
    assert done.returncode == 0, done.stderr
    assert facegen("validate", tmp_path / "idle.usdc").returncode == 0


# ---- validate finds the face -----------------------------------------------------------------------------


def test_validate_finds_the_built_in_face(at_25, tmp_path):
    from facegen.exchange import write_animation

    write_animation(at_25, tmp_path / "out.npy")
    done = facegen("validate", tmp_path / "out.npy")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "built-in model's face" in done.stdout
    write_animation(at_25, tmp_path / "out.glb")
    done = facegen("validate", tmp_path / "out.glb", "--reference", tmp_path / "out.npy", "--json")
    assert done.returncode == 0, done.stdout + done.stderr
    checks = {c["name"]: c for c in json.loads(done.stdout)["checks"]}
    assert checks["reconstruction"]["ok"] and "against the reference" in checks["reconstruction"]["detail"]
    np.save(tmp_path / "other.npy", np.zeros((3, 30), np.float32))
    done = facegen("validate", tmp_path / "other.npy")
    assert done.returncode == 1 and "not the built-in model's face" in done.stdout


def test_info_on_a_file_that_is_not_a_bundle(tmp_path):
    for name, data in (("notes.safetensors", b"hello, this is text"), ("x.safetensors", b"\x00" * 64)):
        (tmp_path / name).write_bytes(data)
        done = facegen("info", tmp_path / name)
        assert done.returncode == 2 and "is not a model bundle" in done.stderr, done.stderr
        assert "re-download" not in done.stderr and len(done.stderr.strip().splitlines()) == 1


# ---- without a transcript --------------------------------------------------------------------------------


def test_the_words_heard_without_a_transcript_are_said(tmp_path):
    done = facegen("animate", WAV, "-o", tmp_path / "out.npy")
    assert done.returncode == 0, done.stderr
    heard = [line for line in done.stderr.splitlines() if line.startswith("facegen: heard: ")]
    assert len(heard) == 1 and len(heard[0].split()) >= 4, done.stderr


# ---- output folders


def test_animate_makes_the_output_folder_and_removes_it_when_nothing_is_written(tmp_path):
    done = facegen("animate", WAV, "--no-text", "-q", "-o", tmp_path / "new" / "deeper" / "out.npy")
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "new" / "deeper" / "out.npy").is_file()
    failed = facegen("animate", tmp_path / "missing.wav", "--no-text", "-o", tmp_path / "a" / "b" / "out.npy")
    assert failed.returncode == 2 and len(failed.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "a").exists()  # the folders made for it are gone again


# ---- batch: compact USD by default, other frame rates


def test_batch_writes_compact_usd_by_default_and_takes_fps(tmp_path):
    from pxr import Usd, UsdSkel

    manifest = tmp_path / "lines.csv"
    manifest.write_text(f"audio,text,output\n{WAV},\"{TEXT.strip()}\",line.usdc\n")
    done = facegen("batch", manifest, "-o", tmp_path / "compact", "--jobs", "1", "-q")
    assert done.returncode == 0, done.stderr
    stage = Usd.Stage.Open(str(tmp_path / "compact" / "line.usdc"))
    assert any(p.IsA(UsdSkel.Root) for p in stage.Traverse())  # UsdSkel blend shapes
    compact = (tmp_path / "compact" / "line.usdc").stat().st_size
    done = facegen("batch", manifest, "-o", tmp_path / "points", "--jobs", "1", "-q", "--usd-mode", "points",
                   "--fps", "30")
    assert done.returncode == 0, done.stderr
    stage = Usd.Stage.Open(str(tmp_path / "points" / "line.usdc"))
    seconds = sf.info(str(WAV)).duration
    assert stage.GetTimeCodesPerSecond() == 30 and stage.GetEndTimeCode() == round(seconds * 30) - 1
    assert not any(p.IsA(UsdSkel.Root) for p in stage.Traverse())
    assert (tmp_path / "points" / "line.usdc").stat().st_size > 5 * compact


def test_align_and_render_make_their_output_folders(tmp_path):
    done = facegen("align", WAV, "--text-file", ROOT / "examples" / "excellent_room.txt", "-o",
                   tmp_path / "new" / "words.json")
    assert done.returncode == 0, done.stderr
    assert json.loads((tmp_path / "new" / "words.json").read_text())["words"][0]["word"] == "What"


def test_audio_whose_header_lies_is_refused_before_it_is_read(tmp_path):
    from facegen.audio import load_audio

    sf.write(tmp_path / "one_hz.wav", np.zeros(47000, np.float32) + 0.1, 1, subtype="PCM_16")  # "13 hours"
    with pytest.raises(FacegenError, match="sample rate is 1 Hz"):
        load_audio(tmp_path / "one_hz.wav")
    stereo = np.stack([np.linspace(-0.5, 0.5, 48000), np.full(48000, 0.25)], axis=1).astype(np.float32)
    sf.write(tmp_path / "stereo.wav", stereo, 48000, subtype="FLOAT")
    mono, rate = load_audio(tmp_path / "stereo.wav")  # read block by block, the channels averaged
    assert rate == 48000 and mono.dtype == np.float32 and np.allclose(mono, stereo.mean(axis=1), atol=1e-7)


# ---- what the mismatch check says


def test_a_transcript_missing_its_end_says_so_and_foreign_words_get_the_language_hint(animator, tmp_path):
    with pytest.raises(FacegenError, match="outside its words, at the end") as info:
        animator.animate(WAV, text="What an excellent room you have, sir.")  # half of the line
    assert "English" not in str(info.value) and "text" in info.value.params
    from facegen.audio import write_wav
    from facegen.espeak import synthesize

    french = "Bonjour, je voudrais une chambre pour deux nuits, avec une grande fenêtre sur la mer."
    speech = synthesize(french, voice="fr")
    write_wav(speech.audio, speech.sample_rate, tmp_path / "fr.wav")
    with pytest.raises(FacegenError, match="not English: pass the transcript's language with --language"):
        animator.animate(tmp_path / "fr.wav", text=french)
    anim = animator.animate(tmp_path / "fr.wav", text=french, language="fr")  # and with it, it animates
    assert anim.metadata["language"] == "fr" and anim.metadata["transcript_match"]["problem"] is None


def test_stage_directions_are_kept_in_the_metadata_not_aligned(animator, tmp_path):
    anim = animator.animate(WAV, text="(calmly) " + TEXT + " [door closes]")
    assert anim.metadata["stage_directions"] == ["(calmly)", "[door closes]"]
    assert [w["word"] for w in anim.metadata["words"]][:2] == ["What", "an"]
    wav = tmp_path / "quiet.wav"
    sf.write(wav, np.zeros(16000, np.float32), 16000)
    idle = animator.animate(wav, text="(ten seconds of silence)")  # a script line for a silent take
    assert idle.metadata["words"] == [] and idle.metadata["stage_directions"] == ["(ten seconds of silence)"]


def test_an_mp3_reads_to_its_real_end(tmp_path):
    """MP3's frame count in the header is an estimate: block reading must stop at the real end (soundfile's
    `blocks` handed back uninitialised samples past it, so the MP3 delay measure failed now and then)."""
    import io

    from facegen.audio import load_audio
    from facegen.exchange import mp3

    probe = np.zeros(22050, np.float32)
    probe[4410:11025] = 0.3 * np.random.default_rng(1).standard_normal(6615).astype(np.float32)
    data = mp3._lame(probe, 22050, 32)
    decoded, rate = load_audio(data)
    expected, _ = sf.read(io.BytesIO(data), dtype="float32")
    assert rate == 22050 and np.array_equal(decoded, expected)
    assert 0 < mp3.measured_delay(22050, 32) < 4 * 1152
