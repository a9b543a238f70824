"""The dataset's cache folder: where it is, the keys of its entries, and the feature cache.

Features (mel and text per sequence) and word alignments are computed once and cached, keyed by the
feature configuration, the text backend and the files' sizes and modification times, in
ROOT/.facegen_cache/ (or the `cache_dir` given; when ROOT is read-only, in ~/.cache/facegen/).
Deleting the cache folder is always safe.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from facegen.atomic import atomic_path
from facegen.audio import FeatureConfig, load_audio, mel_features
from facegen.errors import FacegenError
from facegen.runtime import cache_dir

if TYPE_CHECKING:
    from facegen.datasets.biwi import Dataset, Sequence

CACHE_VERSION = 1


def stat_key(path: Path | None) -> list:
    """A file's name, size and modification time (empty for no file): a cache entry's key part."""
    if path is None:
        return []
    st = path.stat()
    return [path.name, st.st_size, st.st_mtime_ns]


def digest(obj) -> str:
    """A short hash of a JSON-able key."""
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:20]


def default_cache_dir(root: Path) -> Path:
    """ROOT/.facegen_cache when writable, else a folder for ROOT under ~/.cache/facegen/datasets."""
    cache = root / ".facegen_cache"
    try:
        cache.mkdir(exist_ok=True)
        if os.access(cache, os.W_OK):
            return cache
    except OSError:
        pass
    return cache_dir("datasets", f"{root.name}-{digest(str(root.resolve()))[:8]}")


class BadSequence(Exception):
    """A sequence whose files cannot be used (reported and skipped, or fatal with on_bad="fail")."""


def read_json(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


def write_json(path: Path, data: dict) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(data))


class FeatureCache:
    """Mel and text features per sequence, stored as safetensors in the dataset's cache folder."""

    def __init__(self, folder: Path, features: FeatureConfig, filters: np.ndarray, backend=None) -> None:
        self.folder = Path(folder) / "features"
        self.folder.mkdir(parents=True, exist_ok=True)
        self.config = features
        self.filters = np.ascontiguousarray(filters, np.float32)
        self.backend = backend
        filters_hash = hashlib.sha256(self.filters.tobytes()).hexdigest()
        self._mel_key = [CACHE_VERSION, features.mel_dict(), filters_hash]

    def _get(self, path: Path) -> np.ndarray | None:
        from safetensors.numpy import load_file

        if not path.is_file():
            return None
        try:
            return load_file(str(path))["x"]
        except Exception:  # noqa: BLE001 - a damaged cache entry is simply recomputed
            return None

    def _put(self, path: Path, x: np.ndarray) -> None:
        from safetensors.numpy import save_file

        with atomic_path(path) as tmp:
            save_file({"x": np.ascontiguousarray(x, np.float32)}, str(tmp))

    def features(self, dataset: Dataset, seq: Sequence) -> tuple[np.ndarray, np.ndarray | None]:
        """(mel [Ta, n_mels], text [Ta, D] or None) for the sequence's audio length Ta."""
        samples = sr = None
        mel_path = self.folder / f"{seq.name}.mel-{digest(self._mel_key + [stat_key(seq.wav)])}.safetensors"
        mel = self._get(mel_path)
        if mel is None:
            samples, sr = read_sequence_audio(seq)
            mel = mel_features(samples, sr, self.config, self.filters)
            self._put(mel_path, mel)
        if self.backend is None:
            return mel, None
        from facegen.text import text_features

        words_key = [stat_key(seq.wav), stat_key(seq.text), stat_key(seq.alignment)]
        words_path = self.folder / f"{seq.name}.words-{digest(words_key)}.json"
        words_json = read_json(words_path).get("words")
        if words_json is None:
            if samples is None:
                samples, sr = read_sequence_audio(seq)
            try:
                words = dataset.words(seq, samples, sr)
            except FacegenError as exc:
                raise BadSequence(f"no word timings ({exc})") from exc
            words_json = [[w.text, float(w.start), float(w.end)] for w in words]
            write_json(words_path, {"words": words_json})
        text_key = [CACHE_VERSION, self.backend.id, self.backend.dim, self.config.fps, mel.shape[0],
                    words_json, list(self.config.text_window)]
        text_path = self.folder / f"{seq.name}.text-{digest(text_key)}.safetensors"
        text = self._get(text_path)
        if text is None:
            from facegen.words import Word

            words = [Word(t, s, e) for t, s, e in words_json]
            text = text_features(words, self.backend, mel.shape[0], self.config)
            self._put(text_path, text)
        return mel, text


def read_sequence_audio(seq: Sequence) -> tuple[np.ndarray, int]:
    """The sequence's speech (mono samples, rate); BadSequence when unreadable or shorter than a frame."""
    try:
        samples, sr = load_audio(seq.wav)
    except FacegenError as exc:
        raise BadSequence(f"{seq.wav.name} is not readable audio") from exc
    if len(samples) < sr * 0.04:
        raise BadSequence(f"{seq.wav.name} is shorter than one frame")
    return samples, sr
