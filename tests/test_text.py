"""Text features: LM backends (tiny GPT-2 with the real BPE, packaged MiniLM in plain torch checked against
transformers), frame layout, smoothing."""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import pytest
import torch
from helpers import make_tiny_gpt2
from transformers import AutoTokenizer

from facegen.audio import FeatureConfig
from facegen.errors import FacegenError
from facegen.text import (
    _minilm_folder,
    frame_features,
    load_text_backend,
    smooth_frames,
    text_features,
    zero_features,
)


def features(fps: float, window: tuple[int, int] = (8, 7)) -> FeatureConfig:
    """A FeatureConfig with this fps and text smoothing window."""
    return FeatureConfig(fps=fps, text_window=window)


@dataclass
class W:
    """Same fields as facegen.words.Word."""

    text: str
    start: float
    end: float


@pytest.fixture(scope="module")
def gpt2_dir(tmp_path_factory):
    return make_tiny_gpt2(tmp_path_factory.mktemp("tiny_gpt2"), n_positions=64)


@pytest.fixture(scope="module")
def gpt2(gpt2_dir):
    return load_text_backend("gpt2", gpt2_dir)


@pytest.fixture(scope="module")
def minilm():
    return load_text_backend("minilm")


def naive_smooth(x: np.ndarray, before: int = 8, after: int = 7) -> np.ndarray:
    out = np.zeros_like(x)
    for t in range(len(x)):
        lo, hi = max(0, t - before), min(len(x), t + after + 1)
        out[t] = x[lo:hi].mean(axis=0)
    return out


# ---------------------------------------------------------------- GPT-2 path (tiny random weights)


def ids(backend, text: str) -> list[int]:
    return backend.tokenize(text).ids.tolist()


def hidden(backend, token_ids) -> np.ndarray:
    return backend.forward(np.array([token_ids], np.int64))[0]


def test_tiny_gpt2_has_real_gpt2_tokenizer(gpt2_dir, gpt2):
    tok = AutoTokenizer.from_pretrained(gpt2_dir, local_files_only=True)
    assert tok("hello world")["input_ids"] == [31373, 995]
    assert ids(gpt2, "hello world") == [31373, 995]
    assert ids(gpt2, " world") == [995]  # leading-space convention ("Ġworld")
    tokens = gpt2.tokenize("hello world")
    assert tokens.offsets.tolist() == [[0, 5], [5, 11]] and not tokens.special.any()


def test_gpt2_backend_dims_and_id(gpt2):
    assert gpt2.id == "gpt2"
    assert gpt2.dim == 32
    assert gpt2.max_tokens == 64


def test_gpt2_pools_the_mean_of_each_words_tokens(gpt2):
    words = ["Hello,", "world!", "Antidisestablishmentarianism", "is", "long."]
    vecs = gpt2.word_vectors(words)
    assert vecs.shape == (5, 32) and vecs.dtype == np.float32
    assert np.isfinite(vecs).all()

    # Reference: GPT-2 BPE of the sentence = concatenation of each word with a leading space
    # (except the first); run the model once and average each word's token states.
    groups = [ids(gpt2, w if i == 0 else " " + w) for i, w in enumerate(words)]
    assert [len(g) for g in groups][:3] == [2, 2, len(groups[2])] and len(groups[2]) > 2
    joined = [i for g in groups for i in g]
    assert ids(gpt2, " ".join(words)) == joined
    states = hidden(gpt2, joined)
    bounds = np.cumsum([0] + [len(g) for g in groups])
    expected = np.stack([states[a:b].mean(axis=0) for a, b in itertools.pairwise(bounds)])
    np.testing.assert_allclose(vecs, expected, atol=1e-5)


def test_gpt2_vectors_are_contextual_and_deterministic(gpt2):
    a = gpt2.word_vectors(["I", "sat", "by", "the", "river", "bank"])[-1]
    b = gpt2.word_vectors(["I", "paid", "into", "my", "savings", "bank"])[-1]
    assert np.abs(a - b).max() > 1e-3
    again = gpt2.word_vectors(["I", "sat", "by", "the", "river", "bank"])[-1]
    np.testing.assert_array_equal(a, again)


def test_gpt2_long_text_is_windowed(tmp_path):
    folder = make_tiny_gpt2(tmp_path / "short_ctx", n_positions=16)
    backend = load_text_backend("gpt2", folder)
    assert backend.max_tokens == 16
    words = ("the cat sat on the mat and the dog ran in the park " * 10).split()  # 130 one-token words
    assert len(ids(backend, " ".join(words))) == 130
    vecs = backend.word_vectors(words)
    assert vecs.shape == (130, 32) and np.isfinite(vecs).all()
    assert (np.abs(vecs).sum(axis=1) > 0).all()
    # GPT-2 is causal and the first window starts at the text's start, so the first half-window of
    # tokens (8 here) must equal the states of the text cut to those words.
    np.testing.assert_allclose(vecs[:8], backend.word_vectors(words[:8]), atol=1e-5)
    # windows of 16 tokens start every 8 tokens; each token keeps the state from the window where it
    # is farthest from an edge: token 12 from window 8..23 (4 from its start), token 60 from 56..71
    all_ids = ids(backend, " ".join(words))
    for token, start in ((12, 8), (60, 56)):
        state = hidden(backend, all_ids[start : start + 16])[token - start]
        np.testing.assert_allclose(vecs[token], state, atol=1e-5)
    # later tokens come from later windows with shifted positions: they differ from any 16-token run
    assert np.abs(vecs[60] - vecs[8]).max() > 1e-4


def test_empty_and_blank_words(gpt2):
    assert gpt2.word_vectors([]).shape == (0, 32)
    vecs = gpt2.word_vectors(["", "hello", "  "])
    assert vecs.shape == (3, 32)
    assert not vecs[0].any() and not vecs[2].any() and vecs[1].any()
    np.testing.assert_allclose(vecs[1], gpt2.word_vectors(["hello"])[0], atol=1e-6)


# ---------------------------------------------------------------- MiniLM (packaged, offline default)


def test_minilm_vectors(minilm):
    assert minilm.id == "minilm" and minilm.dim == 384 and minilm.max_tokens == 512
    words = ["Hello,", "world.", "Unbelievable!", "ok"]
    vecs = minilm.word_vectors(words)
    assert vecs.shape == (4, 384) and vecs.dtype == np.float32
    assert np.isfinite(vecs).all()
    # token states, not one pooled sentence embedding: the words differ
    assert np.abs(vecs[0] - vecs[1]).max() > 1e-2
    # "Unbelievable!" is [unbelievable] [!]: its vector is the mean of two token states, not either one
    tokens = minilm.tokenize(" ".join(words))
    assert [minilm.tokenize.tokenizer.id_to_token(i) for i in tokens.ids[5:7]] == ["unbelievable", "!"]
    # [CLS] hello , world . unbelievable ! ok [SEP]
    assert tokens.special.tolist() == [True] + [False] * 7 + [True]
    states = hidden(minilm, tokens.ids.tolist())
    np.testing.assert_allclose(vecs[2], states[5:7].mean(axis=0), atol=1e-5)
    np.testing.assert_allclose(vecs[0], states[1:3].mean(axis=0), atol=1e-5)


SENTENCES = [
    "Hello, world. Unbelievable!",
    "We were amazed to find the old bakery still open on a quiet Sunday morning.",
    "Café naïve résumé: état 1984 — 3.5 km/h, it's J.R.R. Tolkien's!",
    "a",
    "the river bank flooded " * 40,  # 161 tokens: past the 128 the tokenizer.json truncates and pads to
]


@pytest.fixture(scope="module")
def reference():
    """transformers' own tokenizer and BertModel on the packaged files: the reference for facegen.minilm."""
    from transformers import AutoModel

    folder = _minilm_folder()
    return AutoTokenizer.from_pretrained(folder, local_files_only=True), AutoModel.from_pretrained(
        folder, local_files_only=True, dtype=torch.float32).eval()


@pytest.mark.parametrize("sentence", SENTENCES)
def test_minilm_equals_transformers(minilm, reference, sentence):
    tokenizer, model = reference
    ref = tokenizer(sentence, return_offsets_mapping=True, return_special_tokens_mask=True)
    tokens = minilm.tokenize(sentence)
    assert tokens.ids.tolist() == ref["input_ids"]
    assert tokens.offsets.tolist() == [list(o) for o in ref["offset_mapping"]]
    assert tokens.special.tolist() == [bool(m) for m in ref["special_tokens_mask"]]
    with torch.inference_mode():
        expected = model(input_ids=torch.tensor([ref["input_ids"]])).last_hidden_state[0].numpy()
    states = hidden(minilm, ref["input_ids"])
    assert states.shape == expected.shape == (len(ref["input_ids"]), 384)
    np.testing.assert_allclose(states, expected, atol=1e-5, rtol=0)
    assert np.abs(expected).max() > 0.1  # real states, not zeros


def test_minilm_word_vectors_equal_the_transformers_backend(minilm):
    """The same folder loaded as a plain model folder goes through transformers' AutoModel."""
    from facegen.minilm import MiniLM

    through_transformers = load_text_backend(_minilm_folder())
    assert isinstance(minilm.forward, MiniLM) and not isinstance(through_transformers.forward, MiniLM)
    assert through_transformers.dim == 384 and through_transformers.max_tokens == minilm.max_tokens == 512
    words = ["The", "quick", "brown", "fox,", "amazed,", "jumped", "over", "3", "lazy", "dogs'",
             "résumés!"] * 3
    np.testing.assert_allclose(minilm.word_vectors(words), through_transformers.word_vectors(words),
                               atol=1e-5)


def test_minilm_loads_without_transformers():
    import subprocess
    import sys

    code = ("import sys; from facegen.text import load_text_backend; b = load_text_backend('minilm'); "
            "v = b.word_vectors(['hello', 'world']); "
            "print(v.shape, sorted(m for m in ('transformers', 'scipy') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "(2, 384) []"


def test_minilm_missing_or_broken_files_are_one_line(tmp_path):
    import shutil

    from facegen.minilm import load_minilm

    with pytest.raises(FacegenError, match="tokenizer.json are missing from .*a text model folder") as err:
        load_minilm(tmp_path)
    assert err.value.param == "text_model"
    for name in ("config.json", "tokenizer.json"):
        shutil.copy(f"{_minilm_folder()}/{name}", tmp_path / name)
    (tmp_path / "model.safetensors").write_bytes(b"\x00" * 64)
    with pytest.raises(FacegenError, match="cannot read the MiniLM files in .*pass a text model folder"):
        load_minilm(tmp_path)


def test_minilm_contextual_and_cached(minilm):
    a = minilm.word_vectors(["the", "river", "bank", "flooded"])[2]
    b = minilm.word_vectors(["the", "bank", "approved", "my", "loan"])[1]
    assert np.linalg.norm(a - b) > 0.1 * np.linalg.norm(a)
    assert load_text_backend("minilm") is minilm
    assert load_text_backend() is minilm


def test_minilm_long_transcript(minilm):
    words = ("we walked along the quiet river at dawn while the city slept " * 60).split()  # 720 words
    vecs = minilm.word_vectors(words)
    assert vecs.shape == (720, 384) and np.isfinite(vecs).all()
    assert (np.abs(vecs).sum(axis=1) > 0).all()


# ---------------------------------------------------------------- missing weights


def test_missing_weights_name_text_model_option(tmp_path):
    with pytest.raises(
        FacegenError, match="GPT-2 weights for 'openai-community/gpt2-not-here'.*pass a local folder"
    ) as err:
        load_text_backend("openai-community/gpt2-not-here")
    assert err.value.param == "text_model"  # the CLI says --text-model
    with pytest.raises(FacegenError, match="not available offline.*pass a local folder"):
        load_text_backend("facegen-tests/no-such-model")
    with pytest.raises(FacegenError, match="does not exist.*pass a local folder"):
        load_text_backend("gpt2", tmp_path / "nowhere")
    (tmp_path / "empty").mkdir()
    with pytest.raises(FacegenError, match="cannot load a text model.*pass a local folder") as err:
        load_text_backend("gpt2", tmp_path / "empty")
    assert err.value.param == "text_model"


def test_gpt2_not_in_cache_names_text_model_option():
    try:
        backend = load_text_backend("gpt2")
    except FacegenError as exc:
        assert str(exc) == ("GPT-2 weights for 'gpt2' are not available offline: pass a local folder with a "
                            "GPT-2 model")
        assert exc.param == "text_model"
    else:  # real GPT-2 happens to be in the local HF cache
        assert backend.dim == 768


# ---------------------------------------------------------------- frame layout and smoothing


def test_frame_layout_exact():
    eye = np.eye(5, dtype=np.float32)
    words = [
        W("a", 0.00, 0.30),  # centres 0.05 0.15 0.25 -> frames 0 1 2
        W("b", 0.50, 0.72),  # centres 0.55 0.65 (0.75 >= end) -> frames 5 6
        W("c", 1.011, 1.019),  # no centre inside -> its midpoint's frame 10
        W("d", 1.85, 2.50),  # runs past the end: frames 18 19
        W("e", 3.00, 3.50),  # wholly after the last frame: dropped
    ]
    raw = frame_features(words, eye, num_frames=20, config=features(10, (0, 0)))
    assert raw.shape == (20, 5) and raw.dtype == np.float32
    owner = np.full(20, -1)
    owner[[0, 1, 2]], owner[[5, 6]], owner[10], owner[[18, 19]] = 0, 1, 2, 3
    expected = np.zeros((20, 5), np.float32)
    expected[owner >= 0] = eye[owner[owner >= 0]]
    np.testing.assert_array_equal(raw, expected)
    # gaps are exactly zero before smoothing
    assert not raw[[3, 4, 7, 8, 9, 11, 17]].any()

    smoothed = frame_features(words, eye, num_frames=20, config=features(10))
    np.testing.assert_allclose(smoothed, naive_smooth(expected), atol=1e-6)
    # frame 0: window frames 0..7 (8 present): three 'a' frames, two 'b' frames
    np.testing.assert_allclose(smoothed[0], [3 / 8, 2 / 8, 0, 0, 0], atol=1e-6)
    # frame 10: window 2..17 (16 frames): one 'a', two 'b', one 'c'
    np.testing.assert_allclose(smoothed[10], [1 / 16, 2 / 16, 1 / 16, 0, 0], atol=1e-6)
    # frame 19: window 11..19 (9 present): two 'd'
    np.testing.assert_allclose(smoothed[19], [0, 0, 0, 2 / 9, 0], atol=1e-6)


def test_the_smoothing_window_is_the_feature_configs():
    """The window comes from the FeatureConfig passed in (a bundle's), the paper's 8 before / 7 after by
    default; an older bundle's header without it reads as that default."""
    rng = np.random.default_rng(3)
    words = [W("a", 0.0, 0.3), W("b", 0.5, 0.9), W("c", 1.2, 1.5)]
    vectors = rng.normal(size=(3, 4)).astype(np.float32)
    raw = frame_features(words, vectors, 40, features(25.0, (0, 0)))
    smoothed = frame_features(words, vectors, 40, features(25.0, (3, 1)))
    np.testing.assert_allclose(smoothed, naive_smooth(raw, 3, 1), atol=1e-6)
    np.testing.assert_allclose(frame_features(words, vectors, 40, FeatureConfig()), naive_smooth(raw, 8, 7),
                               atol=1e-6)
    assert FeatureConfig().text_window == (8, 7)
    header = FeatureConfig(text_window=(3, 1)).to_dict()
    assert header["text_window"] == [3, 1] and FeatureConfig.from_dict(header).text_window == (3, 1)
    old = {k: v for k, v in header.items() if k != "text_window"}
    assert FeatureConfig.from_dict(old) == FeatureConfig()


def test_word_frames_read_in_slices_equal_the_array_to_the_bit():
    """The network's long pass reads the text features 4,096 frames at a time from a WordFrames (the words'
    vectors and each frame's word: two hours are 276 MB as an array); every slice, in order, across the
    smoothing's own 4,096-frame blocks, and read again from the start, is the array's to the bit."""
    from facegen.text import SMOOTH_FRAMES, word_frames

    rng = np.random.default_rng(5)
    n = 3 * SMOOTH_FRAMES + 517
    starts = np.sort(rng.uniform(0, n / 25, 900))
    words = [W(f"w{i}", a, a + rng.uniform(0.05, 0.6)) for i, a in enumerate(starts)]
    vectors = rng.normal(size=(len(words), 384)).astype(np.float32)
    whole = frame_features(words, vectors, n, FeatureConfig())
    lazy = word_frames(words, vectors, n, FeatureConfig())
    assert lazy.shape == whole.shape == (n, 384) and len(lazy) == n
    for step in (4096, 1000):
        parts = np.concatenate([lazy[s:s + step] for s in range(0, n, step)])
        np.testing.assert_array_equal(parts, whole)
    np.testing.assert_array_equal(lazy[100:300], whole[100:300])  # backwards: starts again
    np.testing.assert_array_equal(np.asarray(lazy), whole)
    assert np.ascontiguousarray(lazy, np.float32).dtype == np.float32
    assert 0.05 < float(np.abs(whole).mean()) and not np.isnan(whole).any()  # not all zeros
    with pytest.raises(TypeError):
        lazy[5]


def test_frame_centre_rule_at_boundaries():
    eye = np.eye(2, dtype=np.float32)
    # at 25 fps frame t's centre is (t + 0.5) / 25: 0.02, 0.06, 0.10, ...
    raw = frame_features([W("x", 0.02, 0.10), W("y", 0.10, 0.18)], eye, 6, features(25.0, (0, 0)))
    np.testing.assert_array_equal(raw[:, 0], [1, 1, 0, 0, 0, 0])  # start inclusive, end exclusive
    np.testing.assert_array_equal(raw[:, 1], [0, 0, 1, 1, 0, 0])


def test_overlapping_words_later_wins():
    eye = np.eye(2, dtype=np.float32)
    raw = frame_features([W("x", 0.0, 0.4), W("y", 0.2, 0.3)], eye, 5, features(10.0, (0, 0)))
    np.testing.assert_array_equal(raw.argmax(axis=1), [0, 0, 1, 0, 0])


def test_smoothing_divides_by_frames_present():
    x = np.full((30, 3), 2.5, np.float32)
    np.testing.assert_allclose(smooth_frames(x), x, atol=1e-6)  # no fading at the ends
    rng = np.random.default_rng(0)
    y = rng.normal(size=(40, 4)).astype(np.float32)
    np.testing.assert_allclose(smooth_frames(y), naive_smooth(y), atol=1e-5)
    np.testing.assert_allclose(smooth_frames(y, (3, 1)), naive_smooth(y, 3, 1), atol=1e-5)
    assert smooth_frames(np.zeros((0, 4), np.float32)).shape == (0, 4)


def test_ten_minutes_of_words():
    rng = np.random.default_rng(1)
    n_words, dim, frames, fps = 1500, 384, 15_000, 25.0
    starts = np.sort(rng.uniform(0, 600, n_words))
    words = [W("w", s, s + d) for s, d in zip(starts, rng.uniform(0.05, 0.6, n_words), strict=True)]
    vectors = rng.normal(size=(n_words, dim)).astype(np.float32)
    feats = frame_features(words, vectors, frames, features(fps))
    assert feats.shape == (frames, dim) and feats.dtype == np.float32
    raw = frame_features(words, vectors, frames, features(fps, (0, 0)))
    for t in (0, 5, 7_777, 14_995, 14_999):
        lo, hi = max(0, t - 8), min(frames, t + 8)
        np.testing.assert_allclose(feats[t], raw[lo:hi].mean(axis=0), atol=1e-4)


def test_frame_features_checks_vector_count():
    with pytest.raises(ValueError):
        frame_features([W("a", 0, 1)], np.zeros((2, 3), np.float32), 10, features(25.0))


def test_text_features_end_to_end(minilm):
    words = [W("Hello", 0.10, 0.45), W("there,", 0.50, 0.80), W("friend.", 0.95, 1.40)]
    feats = text_features(words, minilm, num_frames=75, config=features(25.0))
    assert feats.shape == (75, 384) and feats.dtype == np.float32
    vecs = minilm.word_vectors([w.text for w in words])
    np.testing.assert_allclose(feats, frame_features(words, vecs, 75, features(25.0)), atol=1e-6)
    # last spoken frame is 34 (centre 1.38 s); frames from 34 + 8 + 1 on see only silence
    assert feats[43:].any(axis=1).sum() == 0 and feats[42].any()
    assert text_features([], minilm, 10, features(25.0)).shape == (10, 384)
    z = zero_features(75, 384)
    assert z.shape == (75, 384) and z.dtype == np.float32 and not z.any()
