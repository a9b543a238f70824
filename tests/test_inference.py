"""Inference: block-wise forward equals one pass, bounded memory for long clips, devices, batches,
profiles."""

from __future__ import annotations

import itertools
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
import torch
from helpers import make_bundle

from facegen.animator import Animator
from facegen.batch import Job, animate_many, read_manifest
from facegen.errors import FacegenError
from facegen.inference import FrameStream, decoder_states, frame_stream, predict_frames, rest_offsets
from facegen.model import one_hot
from facegen.runtime import Reporter, select_device

REPO = Path(__file__).resolve().parents[1]
SENTENCES = ("What an excellent room you have, sir.", "Such expensive furnishings!",
             "We were amazed to find the old bakery still open on a quiet Sunday morning.")


@pytest.fixture(scope="module")
def face():
    from facegen.face.procedural import make_face

    return make_face()  # the procedural face: 23,370 vertices in the BIWI layout, no ../shared needed


@pytest.fixture(scope="module")
def bundle(face):
    """A paper-sized model whose random output layer moves the face by a few percent of its size."""
    b = make_bundle(face, None, speakers=("F2", "F3", "M3"), small=False, scale=0.02)
    with torch.no_grad():
        torch.nn.init.normal_(b.model.fc_out.bias, std=0.005)
    return b


def features(T: int, seed: int = 0, text_dim: int = 384) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(T)[:, None]
    mel = (-50 + 20 * np.sin(t / 7.0 + rng.uniform(0, 6, 128))
           + rng.normal(0, 5, (T, 128))).astype(np.float32)
    text = np.repeat(rng.normal(0, 1, (T // 10 + 1, text_dim)), 10, axis=0)[:T].astype(np.float32)
    return mel, text


def one_pass(bundle, mel, text, speaker) -> np.ndarray:
    phones = None
    # a model with the phone stream, fed silence (as decoder_states does by default)
    if bundle.config.n_phones:
        phones = torch.zeros(1, len(mel), bundle.config.n_phones)
        phones[..., 0] = 1.0
    with torch.inference_mode():
        out = bundle.model(torch.from_numpy(mel)[None], torch.from_numpy(text)[None],
                           one_hot(speaker, bundle.config.num_speakers), phones)
    return out[0].numpy()


def test_blockwise_equals_one_pass_at_seams(bundle, face):
    T = 640
    mel, text = features(T)
    ref = face.vertices[None] + one_pass(bundle, mel, text, 1) - rest_offsets(bundle, 1).reshape(-1, 3)
    motion = np.linalg.norm(ref - face.vertices[None], axis=-1).max() / face.size
    assert motion > 0.01, f"the test model must move the face (largest offset {motion:.3g} of its size)"

    states = decoder_states(bundle, mel, text, 1, fusion_frames=96)  # fusion blocks end at 96, 192, ...
    frames = frame_stream(bundle, states, face.vertices, block_frames=128, speaker=1)  # blocks at 128, 256..
    got = np.asarray(frames)
    assert got.shape == (T, face.num_vertices, 3) and got.dtype == np.float32
    err = np.linalg.norm(got - ref, axis=-1).max(axis=1) / face.size  # per frame, relative to the face size
    seams = sorted({s + d for s in list(range(96, T, 96)) + list(range(128, T, 128)) for d in (-1, 0)})
    print(f"largest vertex difference vs one pass: {err.max():.2e} of the face size "
          f"(at seams {err[seams].max():.2e}); largest motion {motion:.3f}")
    assert err[seams].max() <= 1e-3
    assert err.max() <= 1e-5  # the recurrences see the whole clip: the only difference is float rounding
    assert frames.blocks_computed == -(-T // 128)
    ahead = list(frames.blocks(100, ahead=True))  # the next block computed in a thread: the same blocks
    assert [s for s, _ in ahead] == list(range(0, T, 100)) and frames.blocks_computed == -(-T // 128) + 7
    # (a block computed in the worker thread may round differently in the last bit: the BLAS's threads split
    # the work differently while the caller's thread runs too)
    np.testing.assert_allclose(np.concatenate([b for _, b in ahead]), got, rtol=0, atol=1e-6 * face.size)
    assert all(b is not c for (_, b), (_, c) in itertools.pairwise(ahead))  # new arrays


def test_default_model_blockwise_equals_one_pass(clips):
    """The shipped (trained) model on real speech features: block-wise output == one pass."""
    from facegen.audio import load_audio, mel_features
    from facegen.bundle import default_bundle_path, load_bundle

    assert default_bundle_path().is_file(), "the built-in default model is committed: it must be there"
    bundle = load_bundle()
    wav = clips[1][2][0]
    mel = mel_features(*load_audio(wav), bundle.features, bundle.mel_filters)
    mel = np.concatenate([mel] * 4)  # ~15 s: several blocks
    text = features(len(mel), seed=2)[1] * 0.3
    rest = rest_offsets(bundle, 2).reshape(-1, 3)
    ref = bundle.template.vertices[None] + one_pass(bundle, mel, text, 2) - rest
    states = decoder_states(bundle, mel, text, 2, fusion_frames=50)
    got = np.asarray(frame_stream(bundle, states, bundle.template.vertices, block_frames=64, speaker=2))
    err = np.linalg.norm(got - ref, axis=-1).max() / bundle.template.size
    motion = np.linalg.norm(ref - bundle.template.vertices, axis=-1).max() / bundle.template.size
    print(f"default model, {len(mel)} frames: largest difference {err:.2e} of the face size (motion "
          f"{motion:.3f})")
    assert motion > 1e-3 and err <= 1e-5


def test_frame_stream_indexing(bundle, face):
    mel, text = features(300, seed=1)
    frames = predict_frames(bundle, mel, text, 0, template=face.vertices, block_frames=64)
    full = np.asarray(frames)
    assert isinstance(frames, FrameStream) and frames.shape == full.shape == (300, face.num_vertices, 3)
    assert len(frames) == 300 and frames.nbytes == full.nbytes
    # BLAS may round a block computed into a slice of a larger array differently in the last bit (SIMD
    # alignment): frames are compared to 1e-6 of the face's size, far below any visible difference
    def same(a, b):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-6 * face.size)
        return True

    computed = frames.blocks_computed
    for i in range(64, 128):  # frames read in order: one block computed, then reused
        assert same(frames[i], full[i])
    assert frames.blocks_computed == computed + 1
    assert same(frames[-1], full[-1])
    assert same(frames[10:200:3], full[10:200:3])
    assert same(frames[5, 7], full[5, 7])
    blocks = list(frames.blocks(100))
    assert [s for s, _ in blocks] == [0, 100, 200] and all(len(b) == 100 for _, b in blocks)
    assert same(np.concatenate([b for _, b in blocks]), full)
    with pytest.raises(IndexError):
        frames[300]


MEMORY_SCRIPT = textwrap.dedent("""
    import json, re, sys, time
    import numpy as np, torch

    def peak_mb():  # this process's own peak RSS (ru_maxrss would include the parent's, inherited at exec)
        return int(re.search(r"VmHWM:\\s+(\\d+)", open("/proc/self/status").read()).group(1)) / 1024

    sys.path.insert(0, {tests!r})
    from helpers import make_bundle
    from facegen.inference import predict_frames
    from facegen.face.procedural import make_face
    torch.set_num_threads(2)
    face = make_face()
    bundle = make_bundle(face, None, speakers=("A",), small=False, scale=0.02)
    T = int(sys.argv[1])
    rng = np.random.default_rng(0)
    mel = rng.normal(-50, 20, (T, 128)).astype(np.float32)
    text = rng.normal(0, 1, (T, 384)).astype(np.float32)
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")  # reset the peak: measure only what streaming adds
    before = peak_mb()
    t0 = time.perf_counter()
    frames = predict_frames(bundle, mel, text, 0, template=face.vertices)
    V = face.num_vertices
    with open(sys.argv[2], "wb") as f:  # .npy [T, 3V] written block by block
        np.lib.format.write_array_header_1_0(f, {{"descr": "<f4", "fortran_order": False, """
                                             """"shape": (T, 3 * V)}})
        for _, block in frames.blocks():
            f.write(block.tobytes())
    print(json.dumps({{"before_mb": before, "peak_mb": peak_mb(),
                      "seconds": time.perf_counter() - t0, "output_mb": frames.nbytes / 2**20,
                      "last": frames[T - 1][:4].reshape(-1).tolist()}}))
""")


@pytest.mark.skipif(not Path("/proc/self/clear_refs").exists(), reason="needs Linux /proc to measure RSS")
def test_long_clip_streams_in_bounded_memory(tmp_path):
    """3 minutes (4,500 frames, 1.2 GB of vertices) written block by block: RSS grows by far less."""
    T = 4500
    script = tmp_path / "stream.py"
    script.write_text(MEMORY_SCRIPT.format(tests=str(REPO / "tests")))
    out = tmp_path / "long.npy"
    proc = subprocess.run([sys.executable, str(script), str(T), str(out)], check=False, capture_output=True,
                          text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr
    r = json.loads(proc.stdout.strip().splitlines()[-1])
    growth = r["peak_mb"] - r["before_mb"]
    print(f"{T} frames ({r['output_mb']:.0f} MB of vertices) in {r['seconds']:.1f} s; peak RSS "
          f"{r['peak_mb']:.0f} MB, growth {growth:.0f} MB while streaming")
    assert growth < 400 and growth < 0.3 * r["output_mb"]
    data = np.load(out, mmap_mode="r")
    assert data.shape == (T, 3 * 23370)
    assert np.allclose(data[T - 1, :12], r["last"])


def test_device_selection_and_fallback():
    if torch.cuda.is_available():
        assert select_device("auto").type == "cuda"
        return
    # quietly (tests/test_fast_start.py: animate says nothing of it)
    assert select_device("auto").type == "cpu"
    assert select_device("cpu").type == "cpu"
    with pytest.raises(FacegenError, match="no CUDA GPU"):
        select_device("cuda")
    with pytest.raises(FacegenError, match="unknown device"):
        select_device("tpu")


@pytest.fixture(scope="module")
def clips(tmp_path_factory, face):
    """Three synthesised sentences of different lengths, with their true word timings as alignments."""
    from facegen.espeak import synthesize

    d = tmp_path_factory.mktemp("clips")
    out = []
    for i, sentence in enumerate(SENTENCES):
        speech = synthesize(sentence, pitch=40 + 10 * i, sample_rate=16000)
        wav = d / f"clip{i}.wav"
        sf.write(wav, speech.audio, 16000, subtype="PCM_16")
        words = d / f"clip{i}.json"
        words.write_text(json.dumps({"words": [{"word": w.text, "start": w.start, "end": w.end}
                                               for w in speech.words]}))
        out.append((wav, words))
    return d, out


def test_device_cuda_without_gpu_is_a_user_error(clips, tmp_path):
    if torch.cuda.is_available():
        pytest.skip("a CUDA GPU is present")
    wav, words = clips[1][0]
    proc = subprocess.run([sys.executable, "-m", "facegen", "animate", str(wav), "--alignment", str(words),
                           "--device", "cuda", "-o", str(tmp_path / "out.npy")],
                          check=False, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip().count("\n") == 0 and "no CUDA GPU" in proc.stderr, proc.stderr
    assert not list(tmp_path.iterdir())


def test_batch_equals_individual(bundle, clips):
    from facegen import animate

    _, items = clips
    jobs = [Job(audio=wav, output=wav.with_suffix(".npy"), alignment=words, speaker=str(i % 3))
            for i, (wav, words) in enumerate(items)]
    jobs.append(Job(audio=items[0][0].with_name("missing.wav"), output=Path("x.npy")))
    results = list(animate_many(jobs, animator=Animator(bundle, device="cpu"), batch_size=2))
    assert [job for job, _ in results] == jobs
    assert isinstance(results[-1][1], FacegenError) and "does not exist" in str(results[-1][1])
    for job, anim in results[:-1]:
        single = animate(job.audio, alignment=job.alignment, speaker=job.speaker, bundle=bundle, device="cpu")
        batched = np.asarray(anim.vertices)
        assert batched.shape == single.vertices.shape
        err = np.abs(batched - single.vertices).max() / single.size
        print(f"{job.audio.name}: {single.num_frames} frames, batched vs alone {err:.1e} of the face size")
        assert err < 1e-6
        assert anim.metadata["speaker"] == single.metadata["speaker"] == bundle.speakers[int(job.speaker)]
        assert anim.metadata["words"] == single.metadata["words"]


def test_run_batch_writes_every_output_and_reports_failures(bundle, clips, tmp_path):
    from facegen.batch import run_batch

    _, items = clips
    jobs = [Job(audio=wav, output=tmp_path / "out" / f"{wav.stem}.npy", alignment=words)
            for wav, words in items[:2]]
    jobs.append(Job(audio=items[2][0], output=tmp_path / "out" / "bad.npy", alignment=items[2][1],
                    speaker="Z9"))
    said = []
    results = run_batch(jobs, animator=Animator(bundle, device="cpu"),
                        reporter=Reporter(progress=said.append))
    assert [r.ok for r in results] == [True, True, False] and "unknown speaker" in results[2].error
    for r in results[:2]:
        head = r.job.output.with_name(r.job.output.stem + ".head.npy")  # the head's motion beside a .npy
        assert r.files == [r.job.output, r.job.output.with_suffix(".wav"), head]
        assert np.load(r.job.output).shape == (r.frames, 3 * 23370)
    assert not (tmp_path / "out" / "bad.npy").exists() and len(said) == 3 and said[0].startswith("[1/3]")


def test_read_manifest(tmp_path):
    (tmp_path / "a.txt").write_text("Hello there.")
    (tmp_path / "m.csv").write_text("audio,text,text_file,alignment,speaker,output\n"
                                    "a.wav,,a.txt,,F2,out/a.glb\n"
                                    "b.wav,Good morning,,,1,\n"
                                    "c.wav,,,c.json,,c.npy\n"
                                    "d.wav,,,,,\n")
    jobs = read_manifest(tmp_path / "m.csv", outdir=tmp_path / "o")
    assert [j.audio for j in jobs] == [tmp_path / n for n in ("a.wav", "b.wav", "c.wav", "d.wav")]
    assert [j.output for j in jobs] == [tmp_path / "o" / n for n in ("out/a.glb", "b.usdc", "c.npy",
                                                                     "d.usdc")]
    assert [j.text for j in jobs] == ["Hello there.", "Good morning", None, None]
    assert jobs[2].alignment == tmp_path / "c.json" and [j.speaker for j in jobs] == ["F2", "1", None, None]
    (tmp_path / "m.json").write_text(json.dumps({"jobs": [{"audio": "a.wav", "text": "Hi",
                                                           "output": "a.usda"}]}))
    (job,) = read_manifest(tmp_path / "m.json")
    assert job.output == tmp_path / "a.usda" and job.text == "Hi"
    (tmp_path / "bad.csv").write_text("audio,words\na.wav,hi\n")
    with pytest.raises(FacegenError, match="unknown column"):
        read_manifest(tmp_path / "bad.csv")
    (tmp_path / "bad2.csv").write_text("audio,output\na.wav,a.fbx\n")
    with pytest.raises(FacegenError, match="line 2.*unknown extension"):
        read_manifest(tmp_path / "bad2.csv")


def test_profile_env_prints_stage_timings(bundle, clips, tmp_path):
    from facegen.bundle import save_bundle

    wav, words = clips[1][0]
    model = tmp_path / "model.safetensors"
    save_bundle(bundle, model)
    env = dict(os.environ, FACEGEN_PROFILE="1")
    proc = subprocess.run([sys.executable, "-m", "facegen", "animate", str(wav), "--alignment", str(words),
                           "-m", str(model), "--device", "cpu", "-q", "-o", str(tmp_path / "out.usdc")],
                          check=False, capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stderr.strip().splitlines()[-1])
    stages = report["facegen_profile"]
    assert {"model_load", "audio", "alignment", "text_model_load", "text_features", "audio_features",
            "inference", "writing"} <= set(stages)
    assert all(v >= 0 for v in stages.values()) and stages["writing"] > 0
    assert report["max_rss_mb"] > 100


def test_silence_is_the_template(tmp_path):
    """The shipped network's answer to a quiet room is taken as its rest (rest_offsets): silence animates
    as the template, whose ARKit weights are all ~0 (it held mouthFunnel 0.06-0.14 before; issue 24)."""
    import soundfile as sf

    from facegen.animator import animate
    from facegen.arkit.solve import fit_arkit
    from facegen.bundle import load_bundle

    bundle = load_bundle()
    rng = np.random.default_rng(3)
    lips = bundle.template.regions["lips"]
    for db in (-55.0, -45.0):  # room noise at other levels than the one rest_offsets uses
        path = tmp_path / f"room{-db:.0f}.wav"
        sf.write(path, (rng.standard_normal(64000) * 10 ** (db / 20)).astype(np.float32), 16000)
        anim = animate(path, no_text=True, bundle=bundle)
        fit = fit_arkit(anim)
        moved = np.linalg.norm(np.asarray(anim.vertices)[:, lips] - bundle.template.vertices[lips], axis=-1)
        assert np.median(moved) / fit.shapes.mm < 0.3, db  # mm
        mouth = [i for i, name in enumerate(fit.names) if not name.startswith("eye")]  # the eyes live
        means = fit.weights.mean(0)
        assert means[mouth].max() < 0.04, (db, dict(zip(fit.names, means.round(3))))
    offsets = rest_offsets(bundle, 0)
    assert offsets.shape == (bundle.template.vertices.size,) and offsets is rest_offsets(bundle, 0)
