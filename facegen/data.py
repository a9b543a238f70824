"""Datasets in the BIWI community layout (FaceFormer, CodeTalker): splits, features, writing, raw BIWI import.

Layout of a dataset folder ROOT (names as the community uses them)::

    ROOT/wav/{subj}_e{NN}.wav             speech
    ROOT/vertices_npy/{subj}_e{NN}.npy    motion, [T, 3V] at 25 fps (float32 or float64; [T, V, 3] accepted)
    ROOT/templates.pkl                    {subj: [V, 3]} neutral faces (read with a restricted unpickler)
    ROOT/templates/{subj}.ply | .npy      the same, one file per subject (these win over templates.pkl)
    ROOT/BIWI.ply                         the face list (and a neutral face: the template of trained bundles)
    ROOT/regions/lve.txt, fdd.txt         lip region (LVE) and upper-face region (FDD), 0-based indices
    ROOT/text/{subj}_e{NN}.txt            transcripts (for the text modality)
    ROOT/alignments/{subj}_e{NN}.json     word timings you already have (.json, .TextGrid or .csv): used
                                          instead of forced alignment

Word alignments of transcripts are computed once with `facegen.align.align` and cached, like the
features (mel and text per sequence, keyed by the feature configuration, the text backend and the
files' sizes and modification times), in ROOT/.facegen_cache/ (or `cache_dir`; when ROOT is read-only,
in ~/.cache/facegen/). Deleting the cache folder is always safe.

Region files map to bundle region names: lve.txt → "lips", fdd.txt → "upper_face"; any other
regions/<name>.txt keeps its name.

Default splits are the community's (and the paper's): subjects F2 F3 F4 M3 M4 M5 with sentences
e01–e32 for training, e33–e36 for validation and e37–e40 for test A; e37–e40 of the other eight
subjects (F1 F5 F6 F7 F8 M1 M2 M6) are test B.

A sequence whose files are missing or unreadable is reported by name and skipped (`on_bad="skip"`,
the default) or stops the run (`on_bad="fail"`); a vertex file whose vertex count differs from its
subject's template is always an error.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import pickle
import re
import sys
import tarfile
from collections.abc import Callable, Iterable
from collections.abc import Sequence as SequenceABC
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from facegen.atomic import atomic_path
from facegen.audio import FeatureConfig
from facegen.errors import FacegenError
from facegen.mesh import Mesh, read_region, write_region

TRAIN_SUBJECTS = ("F2", "F3", "F4", "M3", "M4", "M5")
TEST_B_SUBJECTS = ("F1", "F5", "F6", "F7", "F8", "M1", "M2", "M6")
SPLITS = ("train", "val", "test-a", "test-b")
REGION_FILES = {"lve": "lips", "fdd": "upper_face"}  # community file stem → region name in bundles
ALIGNMENT_SUFFIXES = (".json", ".textgrid", ".csv")
CACHE_VERSION = 1
LENGTH_RATIO = 0.8  # audio and motion shorter than this fraction of each other: the sequence is corrupt

Warn = Callable[[str], None]


def warn_stderr(message: str) -> None:
    print(f"facegen: warning: {message}", file=sys.stderr)


# ------------------------------------------------------------------------------------------------ splits
def parse_numbers(spec: str | Iterable[int]) -> tuple[int, ...]:
    """Sentence numbers from "1-32", "1,3,5-7" or "e33-e36" (or an iterable of ints), sorted, unique."""
    if not isinstance(spec, str):
        return tuple(sorted({int(n) for n in spec}))
    out: set[int] = set()
    for part in re.split(r"[,\s]+", spec.strip()):
        if not part:
            continue
        m = re.fullmatch(r"e?(\d+)(?:-e?(\d+))?", part, re.IGNORECASE)
        if not m:
            raise FacegenError(f"cannot read sentence numbers {spec!r}: write them like 1-32 or 1,3,5-7")
        lo, hi = int(m.group(1)), int(m.group(2) or m.group(1))
        if hi < lo:
            raise FacegenError(f"sentence range {part!r} is backwards: write it low-high, e.g. 33-36")
        out.update(range(lo, hi + 1))
    return tuple(sorted(out))


def parse_subjects(spec: str | Iterable[str]) -> tuple[str, ...]:
    """Subject names from "F2 F3 M3" or "F2,F3" (or an iterable), order kept, duplicates removed."""
    items = re.split(r"[,\s]+", spec.strip()) if isinstance(spec, str) else [str(s) for s in spec]
    return tuple(dict.fromkeys(s for s in items if s))


def sequence_name(subject: str, sentence: int) -> str:
    return f"{subject}_e{sentence:02d}"


@dataclass(frozen=True)
class Splits:
    """Which subjects and sentences make the train, val, test-a and test-b splits.

    The training subjects are the model's speakers (in this order). test-a: the test sentences of the
    training subjects; test-b: the test sentences of the other subjects.
    """

    train_subjects: tuple[str, ...] = TRAIN_SUBJECTS
    test_subjects: tuple[str, ...] = TEST_B_SUBJECTS
    train_sentences: tuple[int, ...] = tuple(range(1, 33))
    val_sentences: tuple[int, ...] = tuple(range(33, 37))
    test_sentences: tuple[int, ...] = tuple(range(37, 41))

    def __post_init__(self) -> None:
        for name in ("train_subjects", "test_subjects"):
            object.__setattr__(self, name, parse_subjects(getattr(self, name)))
        for name in ("train_sentences", "val_sentences", "test_sentences"):
            object.__setattr__(self, name, parse_numbers(getattr(self, name)))
        if not self.train_subjects:
            raise FacegenError("no training subjects: give at least one, e.g. --train-subjects 'F2 F3'")
        both = set(self.train_subjects) & set(self.test_subjects)
        if both:
            raise FacegenError(f"subjects {' '.join(sorted(both))} are both training and test-b subjects: "
                               "a subject belongs to one side only")
        sets = {"train": self.train_sentences, "val": self.val_sentences, "test": self.test_sentences}
        for a, b in (("train", "val"), ("train", "test"), ("val", "test")):
            common = set(sets[a]) & set(sets[b])
            if common:
                raise FacegenError(f"sentences {_ranges(common)} are in both the {a} and {b} sentences: "
                                   "the splits must not overlap")

    @classmethod
    def from_options(cls, train_subjects: str | None = None, test_subjects: str | None = None,
                     train_sentences: str | None = None, val_sentences: str | None = None,
                     test_sentences: str | None = None) -> Splits:
        """Defaults for every option left as None (what the CLI passes)."""
        options = {"train_subjects": train_subjects, "test_subjects": test_subjects,
                   "train_sentences": train_sentences, "val_sentences": val_sentences,
                   "test_sentences": test_sentences}
        given = {k: v for k, v in options.items() if v is not None}
        return cls(**given)

    def subjects(self, split: str) -> tuple[str, ...]:
        check_split(split)
        return self.test_subjects if split == "test-b" else self.train_subjects

    def sentences(self, split: str) -> tuple[int, ...]:
        check_split(split)
        return {"train": self.train_sentences, "val": self.val_sentences}.get(split, self.test_sentences)

    def names(self, split: str) -> list[str]:
        """Sequence names of a split, subject by subject: F2_e01, F2_e02, …"""
        return [sequence_name(s, n) for s in self.subjects(split) for n in self.sentences(split)]

    def to_dict(self) -> dict:
        return {"train_subjects": list(self.train_subjects), "test_subjects": list(self.test_subjects),
                "train_sentences": _ranges(self.train_sentences),
                "val_sentences": _ranges(self.val_sentences),
                "test_sentences": _ranges(self.test_sentences)}

    @classmethod
    def from_dict(cls, d: dict) -> Splits:
        return cls(**d)


def check_split(split: str) -> None:
    if split not in SPLITS:
        raise FacegenError(f"unknown split {split!r}: choose one of {', '.join(SPLITS)}")


def _ranges(numbers: Iterable[int]) -> str:
    """1,2,3,5 → "1-3,5"."""
    nums = sorted(set(numbers))
    parts: list[str] = []
    i = 0
    while i < len(nums):
        j = i
        while j + 1 < len(nums) and nums[j + 1] == nums[j] + 1:
            j += 1
        parts.append(str(nums[i]) if i == j else f"{nums[i]}-{nums[j]}")
        i = j + 1
    return ",".join(parts)


# ------------------------------------------------------------------------- templates.pkl, safely
def _allowed_globals() -> dict[tuple[str, str], object]:
    """The only callables a templates.pkl may name: what pickled numpy arrays need, nothing else."""
    try:
        from numpy._core import multiarray, numeric
    except ImportError:  # numpy < 2
        from numpy.core import multiarray, numeric  # type: ignore[no-redef]

    def latin1_encode(obj, encoding="utf-8"):  # protocol-2 pickles store bytes as latin-1 text
        if not isinstance(obj, str) or encoding not in ("latin1", "latin-1"):
            raise pickle.UnpicklingError("_codecs.encode is allowed only for latin-1 text")
        return obj.encode("latin1")

    allowed: dict[tuple[str, str], object] = {("numpy", "ndarray"): np.ndarray, ("numpy", "dtype"): np.dtype,
                                              ("_codecs", "encode"): latin1_encode}
    for mod in ("numpy.core", "numpy._core"):
        allowed[(f"{mod}.multiarray", "_reconstruct")] = multiarray._reconstruct
        allowed[(f"{mod}.numeric", "_frombuffer")] = numeric._frombuffer
    return allowed


class _TemplateUnpickler(pickle.Unpickler):
    """Unpickles dicts, strings and numpy arrays only; any other class or function is refused unloaded."""

    def find_class(self, module: str, name: str):
        fn = _allowed_globals().get((module, name))
        if fn is None:
            raise pickle.UnpicklingError(f"it names {module}.{name}, which is not a numpy array part")
        return fn

    def persistent_load(self, pid):
        raise pickle.UnpicklingError("it uses persistent ids")


def read_templates_pkl(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read the community's templates.pkl ({subject: [V, 3] array}) without executing anything.

    Only dicts, strings and numpy arrays (and the numpy functions that rebuild arrays) are accepted;
    anything else is refused with FacegenError before it is created.
    """
    path = Path(path)
    try:
        with open(path, "rb") as f:
            data = _TemplateUnpickler(f, encoding="latin1").load()
    except OSError as exc:
        raise FacegenError(f"cannot read {path} ({exc.strerror}): check the file") from exc
    except Exception as exc:  # UnpicklingError and whatever a malformed stream raises
        raise FacegenError(
            f"refusing to load {path}: {exc}; a templates.pkl may hold only a dict of numpy arrays "
            "(re-create it, or put the templates in templates/<subject>.npy)"
        ) from exc
    if not isinstance(data, dict):
        raise FacegenError(f"{path} holds a {type(data).__name__}, not a dict of templates: re-create it")
    out: dict[str, np.ndarray] = {}
    for key, value in data.items():
        if not isinstance(key, str) or not isinstance(value, np.ndarray) or value.dtype.kind not in "fiu":
            raise FacegenError(f"{path}: entry {key!r} is not a numeric numpy array: re-create the file")
        out[key] = _as_vertices(value, f"{path} entry {key!r}")
    return out


def _as_vertices(value: np.ndarray, what: str) -> np.ndarray:
    v = np.asarray(value, dtype=np.float32)
    if v.ndim == 1 and v.size % 3 == 0:
        v = v.reshape(-1, 3)
    if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] == 0:
        raise FacegenError(f"{what} has shape {value.shape}, not [V, 3]: re-create it")
    if not np.isfinite(v).all():
        raise FacegenError(f"{what} has NaN or infinite coordinates: re-create it")
    return np.ascontiguousarray(v)


def write_templates_pkl(templates: dict[str, np.ndarray], path: str | os.PathLike) -> None:
    """Write {subject: [V, 3] float32} as the community's templates.pkl (readable by read_templates_pkl)."""
    data = {str(k): np.ascontiguousarray(v, np.float32) for k, v in templates.items()}
    with atomic_path(path) as tmp:
        tmp.write_bytes(pickle.dumps(data, protocol=4))


# ------------------------------------------------------------------------------------------- dataset
@dataclass
class Sequence:
    """The files of one sequence (transcript and alignment may be absent)."""

    name: str
    subject: str
    wav: Path
    vertices: Path
    text: Path | None = None
    alignment: Path | None = None


@dataclass
class Item:
    """A sequence ready for training or evaluation: features in memory, vertices read on demand."""

    seq: Sequence
    mel: np.ndarray  # [T, n_mels] float32
    text: np.ndarray | None  # [T, D] float32 or None
    num_frames: int
    template: np.ndarray  # [V, 3] float32, the subject's neutral face

    @property
    def name(self) -> str:
        return self.seq.name

    @property
    def subject(self) -> str:
        return self.seq.subject

    def vertices(self) -> np.ndarray:
        """The ground truth [T, 3V] float32, a writable copy read from the memory-mapped .npy."""
        arr = np.load(self.seq.vertices, mmap_mode="r")
        return np.array(arr[: self.num_frames].reshape(self.num_frames, -1), dtype=np.float32)


def _stat(path: Path | None) -> list:
    if path is None:
        return []
    st = path.stat()
    return [path.name, st.st_size, st.st_mtime_ns]


def _digest(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:20]


def _default_cache_dir(root: Path) -> Path:
    cache = root / ".facegen_cache"
    try:
        cache.mkdir(exist_ok=True)
        if os.access(cache, os.W_OK):
            return cache
    except OSError:
        pass
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "facegen" / "datasets" / f"{root.name}-{_digest(str(root.resolve()))[:8]}"


class Dataset:
    """A dataset folder in the community layout (see the module docstring)."""

    def __init__(self, root: str | os.PathLike, *, cache_dir: str | os.PathLike | None = None,
                 on_bad: str = "skip", warn: Warn | None = warn_stderr) -> None:
        self.root = Path(root)
        if not self.root.is_dir():
            raise FacegenError(f"dataset folder {self.root} does not exist: pass a folder with wav/ and "
                               "vertices_npy/ (the BIWI community layout)")
        for sub in ("wav", "vertices_npy"):
            if not (self.root / sub).is_dir():
                raise FacegenError(f"{self.root} has no {sub}/ folder: pass a dataset in the BIWI community "
                                   "layout (wav/, vertices_npy/, templates.pkl, BIWI.ply)")
        if on_bad not in ("skip", "fail"):
            raise ValueError(f"on_bad must be 'skip' or 'fail', not {on_bad!r}")
        self.on_bad = on_bad
        self.warn = warn or (lambda _msg: None)
        self.cache_dir = Path(cache_dir) if cache_dir is not None else _default_cache_dir(self.root)
        try:
            self.cache_dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise FacegenError(f"cannot create the cache folder {self.cache_dir} ({exc.strerror}): "
                               "pass --cache-dir to a writable folder") from exc
        self.skipped: list[tuple[str, str]] = []  # (sequence, reason)
        self._vertex_index_dirty = False

    # ------------------------------------------------------------------ static parts
    @cached_property
    def templates(self) -> dict[str, np.ndarray]:
        """Every subject's neutral face [V, 3] float32 (templates/ files win over templates.pkl)."""
        out: dict[str, np.ndarray] = {}
        pkl = self.root / "templates.pkl"
        if pkl.is_file():
            out.update(read_templates_pkl(pkl))
        folder = self.root / "templates"
        if folder.is_dir():
            for path in sorted(folder.iterdir()):
                if path.suffix.lower() == ".npy":
                    try:
                        arr = np.load(path, allow_pickle=False)
                    except (OSError, ValueError) as exc:
                        raise FacegenError(f"cannot read template {path} ({exc}): re-create it") from exc
                    out[path.stem] = _as_vertices(arr, f"template {path}")
                elif path.suffix.lower() in (".ply", ".obj"):
                    from facegen.mesh import read_mesh

                    out[path.stem] = read_mesh(path).vertices
        return out

    def template(self, subject: str) -> np.ndarray:
        if subject not in self.templates:
            raise FacegenError(f"no template for subject {subject} in {self.root}/templates.pkl or "
                               f"templates/{subject}.npy: add one")
        return self.templates[subject]

    @cached_property
    def regions(self) -> dict[str, np.ndarray]:
        """Regions from ROOT/regions/*.txt: lve.txt → "lips", fdd.txt → "upper_face", others by name."""
        out: dict[str, np.ndarray] = {}
        folder = self.root / "regions"
        if folder.is_dir():
            for path in sorted(folder.glob("*.txt")):
                name = REGION_FILES.get(path.stem, path.stem)
                if path.stem in REGION_FILES or name not in out:
                    out[name] = read_region(path)
        return out

    @cached_property
    def mesh(self) -> Mesh:
        """BIWI.ply (its vertices and faces) with the dataset's regions."""
        from facegen.mesh import read_mesh

        path = self.root / "BIWI.ply"
        if not path.is_file():
            raise FacegenError(f"{path} is missing: the dataset needs the face list (BIWI.ply of the "
                               "community layout, e.g. from the CodeTalker repository)")
        mesh = read_mesh(path)
        for name, idx in self.regions.items():
            if idx.size and (idx.min() < 0 or idx.max() >= mesh.num_vertices):
                raise FacegenError(f"region {name} of {self.root}/regions has indices outside the mesh's "
                                   f"{mesh.num_vertices} vertices: use region files made for this mesh")
        mesh.regions = dict(self.regions)
        return mesh

    # ------------------------------------------------------------------ sequences
    def bad(self, name: str, reason: str) -> None:
        """Report a sequence that cannot be used: skipped with a warning, or an error (on_bad="fail")."""
        if self.on_bad == "fail":
            raise FacegenError(f"sequence {name}: {reason} (fix or remove it, or skip bad sequences)")
        self.skipped.append((name, reason))
        self.warn(f"skipping sequence {name}: {reason}")

    def sequence(self, name: str) -> Sequence:
        subject = name.split("_")[0]
        text = self.root / "text" / f"{name}.txt"
        alignment = None
        folder = self.root / "alignments"
        if folder.is_dir():
            for path in sorted(folder.glob(f"{name}.*")):
                if path.suffix.lower() in ALIGNMENT_SUFFIXES:
                    alignment = path
                    break
        wav, npy = self.root / "wav" / f"{name}.wav", self.root / "vertices_npy" / f"{name}.npy"
        return Sequence(name, subject, wav, npy, text if text.is_file() else None, alignment)

    def sequences(self, names: Iterable[str]) -> list[Sequence]:
        """The sequences whose wav and npy files exist (others reported as bad)."""
        out = []
        for name in names:
            seq = self.sequence(name)
            missing = [p.relative_to(self.root).as_posix() for p in (seq.wav, seq.vertices)
                       if not p.is_file()]
            if missing:
                self.bad(name, f"{' and '.join(missing)} missing")
                continue
            out.append(seq)
        return out

    def split(self, split: str, splits: Splits | None = None) -> list[Sequence]:
        return self.sequences((splits or Splits()).names(split))

    # ------------------------------------------------------------------ per-sequence data
    def vertex_frames(self, seq: Sequence, num_vertices: int) -> int:
        """Frames of the sequence's vertex file after checking it (shape, finite values); cached by stat."""
        index = self._vertex_index
        key = _stat(seq.vertices)
        entry = index.get(seq.name)
        if entry and entry.get("stat") == key and entry.get("num_vertices") == num_vertices:
            return int(entry["frames"])
        try:
            arr = np.load(seq.vertices, mmap_mode="r", allow_pickle=False)
        except (OSError, ValueError, EOFError) as exc:
            raise _BadSequence(f"{seq.vertices.name} is not a readable .npy file ({exc})") from exc
        shape = arr.shape
        if arr.ndim == 3 and shape[2] == 3:
            v = shape[1]
        elif arr.ndim == 2 and shape[1] % 3 == 0:
            v = shape[1] // 3
        else:
            raise _BadSequence(f"{seq.vertices.name} has shape {shape}, not [T, 3V]")
        if v != num_vertices:
            raise FacegenError(f"{seq.vertices} has {v} vertices per frame but the template of {seq.subject} "
                               f"has {num_vertices}: the vertex files and templates must share one topology")
        if shape[0] == 0:
            raise _BadSequence(f"{seq.vertices.name} has no frames")
        if arr.dtype.kind != "f":
            raise _BadSequence(f"{seq.vertices.name} holds {arr.dtype}, not floats")
        for start in range(0, shape[0], 64):
            if not np.isfinite(arr[start:start + 64]).all():
                raise _BadSequence(f"{seq.vertices.name} contains NaN or infinite coordinates")
        index[seq.name] = {"stat": key, "num_vertices": num_vertices, "frames": int(shape[0])}
        self._vertex_index_dirty = True
        return int(shape[0])

    @cached_property
    def _vertex_index(self) -> dict:
        return _read_json(self.cache_dir / "vertices.json")

    def _save_vertex_index(self) -> None:
        if self._vertex_index_dirty:
            _write_json(self.cache_dir / "vertices.json", self._vertex_index)
            self._vertex_index_dirty = False

    def words(self, seq: Sequence, samples: np.ndarray, sr: int) -> list:
        """Word timings: the user's alignment file, else the transcript aligned once (and cached)."""
        from facegen import align
        from facegen.words import read_alignment, write_alignment

        duration = len(samples) / sr
        if seq.alignment is not None:
            return read_alignment(seq.alignment, duration=duration)
        if seq.text is None:
            raise _BadSequence(f"no transcript text/{seq.name}.txt or alignment alignments/{seq.name}.json "
                               "for the text modality")
        transcript = seq.text.read_text(encoding="utf-8", errors="replace")
        key = _digest([_stat(seq.wav), _stat(seq.text)])
        cached = self.cache_dir / "alignments" / f"{seq.name}-{key}.json"
        if cached.is_file():
            with contextlib.suppress(FacegenError):  # a damaged cache entry is recomputed
                return read_alignment(cached, duration=duration)
        if not transcript.strip():
            return []
        words = align.align(samples, sr, transcript)
        cached.parent.mkdir(parents=True, exist_ok=True)
        write_alignment(words, cached)  # atomically
        return words

    def load(self, sequences: SequenceABC[Sequence], features: FeatureConfig, filters: np.ndarray,
             backend=None, progress: bool = False) -> list[Item]:
        """Features of every usable sequence (from the cache when it has them); bad ones reported."""
        from tqdm import tqdm

        cache = FeatureCache(self.cache_dir, features, filters, backend)
        items = []
        bar = tqdm(sequences, desc="features", unit="seq", disable=not progress or not sequences,
                   file=sys.stderr, leave=False)
        try:
            for seq in bar:
                item = self._load_one(seq, cache)
                if item is not None:
                    items.append(item)
        finally:
            self._save_vertex_index()
        return items

    def _load_one(self, seq: Sequence, cache: FeatureCache) -> Item | None:
        if seq.subject not in self.templates:
            self.bad(seq.name, f"no template for subject {seq.subject} (templates.pkl or templates/)")
            return None
        template = self.templates[seq.subject]
        try:
            frames = self.vertex_frames(seq, template.shape[0])
            mel, text = cache.features(self, seq)
        except _BadSequence as exc:
            self.bad(seq.name, str(exc))
            return None
        audio_frames = mel.shape[0]
        if min(audio_frames, frames) < LENGTH_RATIO * max(audio_frames, frames):
            self.bad(seq.name, f"the audio lasts {audio_frames} frames but the motion {frames} frames")
            return None
        n = min(audio_frames, frames)
        return Item(seq, mel[:n], None if text is None else text[:n], n, template)


class _BadSequence(Exception):
    """A sequence whose files cannot be used (reported and skipped, or fatal with on_bad="fail")."""


def _read_json(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


def _write_json(path: Path, data: dict) -> None:
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
        self._mel_key = [CACHE_VERSION, features.to_dict(), filters_hash]

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
        from facegen.audio import mel_features

        samples = sr = None
        mel_path = self.folder / f"{seq.name}.mel-{_digest(self._mel_key + [_stat(seq.wav)])}.safetensors"
        mel = self._get(mel_path)
        if mel is None:
            samples, sr = _read_audio(seq)
            mel = mel_features(samples, sr, self.config, self.filters)
            self._put(mel_path, mel)
        if self.backend is None:
            return mel, None
        from facegen.text import text_features

        words_key = [_stat(seq.wav), _stat(seq.text), _stat(seq.alignment)]
        words_path = self.folder / f"{seq.name}.words-{_digest(words_key)}.json"
        words_json = _read_json(words_path).get("words")
        if words_json is None:
            if samples is None:
                samples, sr = _read_audio(seq)
            try:
                words = dataset.words(seq, samples, sr)
            except FacegenError as exc:
                raise _BadSequence(f"no word timings ({exc})") from exc
            words_json = [[w.text, float(w.start), float(w.end)] for w in words]
            _write_json(words_path, {"words": words_json})
        text_key = [CACHE_VERSION, self.backend.id, self.backend.dim, self.config.fps, mel.shape[0],
                    words_json]
        text_path = self.folder / f"{seq.name}.text-{_digest(text_key)}.safetensors"
        text = self._get(text_path)
        if text is None:
            from facegen.words import Word

            words = [Word(t, s, e) for t, s, e in words_json]
            text = text_features(words, self.backend, mel.shape[0], self.config.fps)
            self._put(text_path, text)
        return mel, text


def _read_audio(seq: Sequence) -> tuple[np.ndarray, int]:
    from facegen.audio import load_audio

    try:
        samples, sr = load_audio(seq.wav)
    except FacegenError as exc:
        raise _BadSequence(f"{seq.wav.name} is not readable audio") from exc
    if len(samples) < sr * 0.04:
        raise _BadSequence(f"{seq.wav.name} is shorter than one frame")
    return samples, sr


# ------------------------------------------------------------------------------------------- writing
class DatasetWriter:
    """Write a dataset in the community layout (import-biwi and the synthetic corpus use it).

    Every file is written atomically. Vertex files are float32 [T, 3V]; templates go to templates.pkl.
    """

    def __init__(self, root: str | os.PathLike) -> None:
        self.root = Path(root)
        try:
            for sub in ("wav", "vertices_npy", "regions"):
                (self.root / sub).mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise FacegenError(f"cannot create the dataset folder {self.root} ({exc.strerror}): "
                               "choose a writable place") from exc

    def write_mesh(self, mesh: Mesh) -> None:
        """BIWI.ply and its regions (lips → regions/lve.txt, upper_face → regions/fdd.txt, others by name)."""
        from facegen.mesh import write_mesh

        with atomic_path(self.root / "BIWI.ply") as tmp:
            write_mesh(mesh, tmp)
        names = {v: k for k, v in REGION_FILES.items()}
        for name, idx in mesh.regions.items():
            with atomic_path(self.root / "regions" / f"{names.get(name, name)}.txt") as tmp:
                write_region(idx, tmp)

    def write_regions(self, regions: dict[str, np.ndarray]) -> None:
        names = {v: k for k, v in REGION_FILES.items()}
        for name, idx in regions.items():
            with atomic_path(self.root / "regions" / f"{names.get(name, name)}.txt") as tmp:
                write_region(idx, tmp)

    def write_templates(self, templates: dict[str, np.ndarray]) -> None:
        write_templates_pkl(templates, self.root / "templates.pkl")

    def write_sequence(self, name: str, vertices: np.ndarray, *, audio: np.ndarray | None = None,
                       sample_rate: int | None = None, transcript: str | None = None,
                       words: list | None = None) -> None:
        """vertices [T, V, 3] or [T, 3V]; audio mono float samples (written as 16-bit PCM WAV)."""
        v = np.ascontiguousarray(np.asarray(vertices, np.float32).reshape(len(vertices), -1))
        with atomic_path(self.root / "vertices_npy" / f"{name}.npy") as tmp:
            np.save(tmp, v)
        if audio is not None:
            self.write_wav(name, audio, int(sample_rate or 16000))
        if transcript is not None:
            self.write_transcript(name, transcript)
        if words is not None:
            from facegen.words import write_alignment

            (self.root / "alignments").mkdir(exist_ok=True)
            write_alignment(words, self.root / "alignments" / f"{name}.json")  # atomically

    def write_wav(self, name: str, audio: np.ndarray, sample_rate: int) -> None:
        import soundfile as sf

        with atomic_path(self.root / "wav" / f"{name}.wav") as tmp:
            sf.write(str(tmp), np.asarray(audio, np.float32), sample_rate, subtype="PCM_16", format="WAV")

    def write_transcript(self, name: str, transcript: str) -> None:
        (self.root / "text").mkdir(exist_ok=True)
        with atomic_path(self.root / "text" / f"{name}.txt") as tmp:
            tmp.write_text(transcript.strip() + "\n", encoding="utf-8")


# ---------------------------------------------------------------------------------- raw BIWI import
ROTATE_X_PI = np.array([[1.0, 0.0, 0.0],  # the community's rotx for theta = pi (applied as V @ rotx)
                        [0.0, np.cos(np.pi), -np.sin(np.pi)],
                        [0.0, np.sin(np.pi), np.cos(np.pi)]])
NORMALISATIONS = ("frame", "template")
_SUBJECT = re.compile(r"^([FM]\d+)(?=$|[_\-. ])", re.IGNORECASE)
_ARCHIVE = re.compile(r"\.(tar|tgz|tar\.gz)$", re.IGNORECASE)
_SENTENCE = re.compile(r"^(e?)0*(\d{1,3})$", re.IGNORECASE)


def read_vl(data: bytes, what: str = ".vl frame") -> np.ndarray:
    """One raw BIWI frame: uint32 vertex count, then float32 x y z per vertex (little-endian) → [V, 3]."""
    if len(data) < 4:
        raise FacegenError(f"{what} is empty or truncated")
    n = int(np.frombuffer(data[:4], "<u4")[0])
    if n == 0 or len(data) < 4 + 12 * n:
        raise FacegenError(f"{what} says {n} vertices but holds {(len(data) - 4) // 12}")
    return np.frombuffer(data[4:4 + 12 * n], "<f4").reshape(n, 3).astype(np.float32)


def write_vl(vertices: np.ndarray, path: str | os.PathLike) -> None:
    """Write a frame in the raw BIWI .vl format (for tests and tools)."""
    v = np.ascontiguousarray(vertices, "<f4")
    Path(path).write_bytes(np.array([v.shape[0]], "<u4").tobytes() + v.tobytes())


def read_obj(path: str | os.PathLike) -> Mesh:
    """An OBJ template with its vertex order kept exactly (texture coordinates and materials ignored).

    The order must match the .vl frames, so vertices are never split at texture seams or merged.
    """
    from trimesh.exchange.obj import load_obj

    try:
        with open(path) as f:
            loaded = load_obj(f, maintain_order=True, skip_materials=True)
        geometry = next(iter(loaded["geometry"].values())) if "geometry" in loaded else loaded
        vertices = np.asarray(geometry["vertices"], np.float32)
        faces = np.asarray(geometry["faces"], np.int32)
    except Exception as exc:  # trimesh raises many types on bad files
        raise FacegenError(f"cannot read the OBJ template {path} ({exc}): check the file") from exc
    if vertices.ndim != 2 or len(vertices) == 0 or faces.ndim != 2 or len(faces) == 0:
        raise FacegenError(f"OBJ template {path} has no vertices or no triangles")
    return Mesh(vertices, faces)


def surface_area(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Total triangle area (the community's sum of mixed-Voronoi vertex areas equals it)."""
    v = np.asarray(vertices, np.float64)
    e1 = v[faces[:, 1]] - v[faces[:, 0]]
    e2 = v[faces[:, 2]] - v[faces[:, 0]]
    return float(0.5 * np.linalg.norm(np.cross(e1, e2), axis=1).sum())


def normalise(vertices: np.ndarray, faces: np.ndarray,
              reference: tuple[np.ndarray, float] | None = None) -> np.ndarray:
    """The community's BIWI normalisation of one mesh: rotate π about x, centre, scale to unit area.

    As CodeTalker's creatDataset_BIWI.m / process_BIWI_template.m: V ← V·Rx(π) (row vectors), then
    V ← V − mean(V), then V ← V / sqrt(total surface area). With `reference` = (mean, sqrt_area) of
    the rotated template, frames use the template's centre and scale instead of their own.
    Returns float32 [V, 3].
    """
    v = np.asarray(vertices, np.float64) @ ROTATE_X_PI
    if reference is None:
        v = v - v.mean(axis=0)
        v = v / np.sqrt(surface_area(v, faces))
    else:
        mean, scale = reference
        v = (v - mean) / scale
    return v.astype(np.float32)


@dataclass
class ImportReport:
    out: Path
    subjects: list[str] = field(default_factory=list)
    sequences: list[str] = field(default_factory=list)
    skipped: list[tuple[str, str]] = field(default_factory=list)
    neutral_ignored: int = 0

    def summary(self) -> str:
        lines = [f"imported {len(self.sequences)} sequences of {len(self.subjects)} subjects into {self.out}"]
        if self.neutral_ignored:
            lines.append(f"ignored {self.neutral_ignored} neutral takes (names without 'e'; the community "
                         "layout uses the emotional takes e01-e40)")
        lines += [f"skipped {name}: {reason}" for name, reason in self.skipped]
        return "\n".join(lines)


def _sentence_of(stem: str) -> tuple[bool, int] | None:
    """("e01" → (True, 1)); ("01" → (False, 1)); None when the name is not a sentence."""
    m = _SENTENCE.match(stem.strip())
    if not m:
        m = re.match(r"^.*?[_\- ](e?)0*(\d{1,3})$", stem.strip(), re.IGNORECASE)  # e.g. "F1_e01"
    if not m:
        return None
    return bool(m.group(1)), int(m.group(2))


def _vl_frames(source: Path) -> list[tuple[str, bytes]] | None:
    """(member name, bytes) of every .vl frame in a folder or tar archive, in frame order; None if none."""
    frames: list[tuple[str, bytes]] = []
    if source.is_dir():
        frames = [(p.name, p.read_bytes()) for p in source.rglob("*")
                  if p.suffix.lower() == ".vl" and p.is_file()]
    else:
        try:
            with tarfile.open(source, "r:*") as tar:
                for member in tar:
                    if member.isfile() and member.name.lower().endswith(".vl"):
                        f = tar.extractfile(member)
                        if f is not None:
                            frames.append((Path(member.name).name, f.read()))
        except (tarfile.TarError, OSError, EOFError) as exc:
            raise FacegenError(f"{source.name} is not a readable tar archive ({exc})") from exc
    if not frames:
        return None
    return sorted(frames, key=lambda f: _natural_key(f[0]))


def _natural_key(name: str) -> list:
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]


def _find_videos(raw: Path) -> dict[tuple[str, int], Path]:
    """videos/F1_e01.flv (or videos/F1/e01.flv, …) → {(subject, sentence)} for the emotional takes."""
    out: dict[tuple[str, int], Path] = {}
    folder = raw / "videos"
    if not folder.is_dir():
        return out
    for path in sorted(folder.rglob("*")):
        if path.suffix.lower() not in (".flv", ".mp4", ".avi", ".wav") or not path.is_file():
            continue
        m = re.search(r"([FM]\d+)[_\-]?(e?)0*(\d{1,3})$", path.stem, re.IGNORECASE)
        if m:
            subject, emotional, number = m.group(1).upper(), bool(m.group(2)), int(m.group(3))
        else:
            parsed = _sentence_of(path.stem)
            sm = _SUBJECT.match(path.parent.name)
            if not parsed or not sm:
                continue
            subject, (emotional, number) = sm.group(1).upper(), parsed
        if emotional:
            out.setdefault((subject, number), path)
    return out


def _extract_audio(video: Path, wav: Path, sample_rate: int) -> None:
    import subprocess

    import imageio_ffmpeg

    ffmpeg = imageio_ffmpeg.get_ffmpeg_exe()
    with atomic_path(wav) as tmp:
        cmd = [ffmpeg, "-nostdin", "-v", "error", "-y", "-i", str(video), "-vn", "-ac", "1",
               "-ar", str(sample_rate), "-acodec", "pcm_s16le", "-f", "wav", str(tmp)]
        done = subprocess.run(cmd, check=False, capture_output=True, text=True)
        if done.returncode != 0 or not tmp.is_file():
            msg = (done.stderr.strip().splitlines() or ["no audio stream"])[-1]
            raise FacegenError(f"ffmpeg could not extract the audio of {video.name} ({msg})")


def read_transcripts(path: str | os.PathLike) -> dict[int | str, str]:
    """Sentence transcripts from a file or a folder.

    A file: lines "e01 text", "01 text" or "1: text" — or just one sentence per line, in order — giving
    {sentence number: text}. A folder: one file per sentence (e01.txt, 01.txt → {1: text}) and/or per
    sequence (F1_e01.txt → {"F1_e01": text}, which wins over the sentence's text for that sequence).
    """
    path = Path(path)
    if path.is_dir():
        out: dict[int | str, str] = {}
        for file in sorted(path.glob("*.txt")):
            text = " ".join(file.read_text(encoding="utf-8", errors="replace").split())
            m = re.fullmatch(r"([FM]\d+)_e0*(\d{1,3})", file.stem, re.IGNORECASE)
            if m:
                out[sequence_name(m.group(1).upper(), int(m.group(2)))] = text
            elif (parsed := _sentence_of(file.stem)) is not None:
                out[parsed[1]] = text
        return out
    if not path.is_file():
        raise FacegenError(f"transcripts {path} do not exist: pass a file with one sentence per line or "
                           "a folder of .txt files")
    lines = [ln.strip() for ln in path.read_text(encoding="utf-8").splitlines() if ln.strip()]
    numbered = [re.match(r"^e?0*(\d{1,3})[\s:.)\t-]+(.+)$", ln, re.IGNORECASE) for ln in lines]
    if lines and all(numbered):
        return {int(m.group(1)): m.group(2).strip() for m in numbered if m}
    return {i + 1: ln for i, ln in enumerate(lines)}


def import_biwi(raw: str | os.PathLike, out: str | os.PathLike, *, normalisation: str = "frame",
                transcripts: str | os.PathLike | None = None, regions: str | os.PathLike | None = None,
                subjects: Iterable[str] | None = None, sample_rate: int = 44100, progress: bool = False,
                warn: Warn | None = warn_stderr) -> ImportReport:
    """Convert the raw BIWI release (no MATLAB) into the community layout in `out`.

    Reads RAW/rigid_scans/<subj>.obj (templates), RAW/faces/<subj>/<take>.tar|.tgz|.tar.gz or
    RAW/faces/<subj>/<take>/ folders of .vl frames, and RAW/videos/<subj>_<take>.flv (or
    videos/<subj>/<take>.flv), whose audio ffmpeg (from imageio-ffmpeg) extracts to mono 16-bit WAV.

    Take names: "e01" … "e40" (the emotional takes, what the community and the paper use) become
    sequence <subj>_e01 …; names without the "e" ("01" …, the neutral takes) are ignored and counted.
    When both an archive and a folder (or a .tar and a .tgz) exist for a take, the first that holds
    .vl files is used: folder, then .tar, then .tgz / .tar.gz. Frames are ordered by the number in
    their file name (frame_001.vl, frame_002.vl, …).

    Normalisation (`normalisation="frame"`, the community's exactly: CodeTalker's creatDataset_BIWI.m
    and process_BIWI_template.m): every mesh — each template and each frame on its own — is rotated by
    π about x, centred on its own mean vertex and divided by the square root of its own total surface
    area. `normalisation="template"` instead centres and scales a subject's frames with the mean and
    area of that subject's (rotated) template, so the frames keep the template's frame of reference.

    Also writes templates.pkl, BIWI.ply (the mean of the normalised templates, with their face list),
    text/<name>.txt from `transcripts` (a file or folder, see read_transcripts), and copies lve.txt and
    fdd.txt from `regions` (a folder, e.g. CodeTalker's BIWI/regions) into regions/.
    """
    from tqdm import tqdm

    raw, out = Path(raw), Path(out)
    warn = warn or (lambda _msg: None)
    if normalisation not in NORMALISATIONS:
        raise FacegenError(f"unknown normalisation {normalisation!r}: choose one of "
                           f"{', '.join(NORMALISATIONS)}")
    for sub in ("rigid_scans", "faces"):
        if not (raw / sub).is_dir():
            raise FacegenError(f"{raw} has no {sub}/ folder: pass the folder of the raw BIWI release "
                               "(rigid_scans/, faces/, videos/)")
    if not (raw / "videos").is_dir():
        raise FacegenError(f"{raw} has no videos/ folder: the audio is taken from the BIWI videos (.flv)")
    sentences_text = read_transcripts(transcripts) if transcripts else {}
    wanted = {s.upper() for s in parse_subjects(subjects)} if subjects else None

    # templates
    meshes: dict[str, Mesh] = {}
    for path in sorted((raw / "rigid_scans").rglob("*.obj")):
        m = _SUBJECT.match(path.stem)
        if m and (wanted is None or m.group(1).upper() in wanted):
            meshes.setdefault(m.group(1).upper(), read_obj(path))
    if not meshes:
        raise FacegenError(f"no subject templates (F1.obj, M1.obj, …) in {raw}/rigid_scans: "
                           "check the folder")
    first = next(iter(meshes.values()))
    for subject, mesh in meshes.items():
        if mesh.num_vertices != first.num_vertices or not np.array_equal(mesh.faces, first.faces):
            raise FacegenError(f"the template of {subject} has a different topology from the others: "
                               "all BIWI templates share one mesh")
    faces = first.faces
    templates = {s: normalise(m.vertices, faces) for s, m in sorted(meshes.items())}
    references = {}
    for s, m in meshes.items():
        rotated = np.asarray(m.vertices, np.float64) @ ROTATE_X_PI
        centre = rotated.mean(axis=0)
        references[s] = (centre, np.sqrt(surface_area(rotated - centre, faces)))

    writer = DatasetWriter(out)
    report = ImportReport(out=out, subjects=sorted(meshes))
    writer.write_templates(templates)
    writer.write_mesh(Mesh(np.mean(np.stack(list(templates.values())), axis=0).astype(np.float32), faces))
    if regions is not None:
        for stem, region in REGION_FILES.items():
            src = Path(regions) / f"{stem}.txt"
            if not src.is_file():
                raise FacegenError(f"{src} is missing: pass the folder with lve.txt and fdd.txt as --regions")
            idx = read_region(src)
            if idx.size and (idx.min() < 0 or idx.max() >= first.num_vertices):
                raise FacegenError(f"{src} has vertex indices outside the {first.num_vertices} vertices "
                                   "of the mesh: pass the region files of this topology")
            writer.write_regions({region: idx})
    else:
        warn("no --regions given: copy lve.txt and fdd.txt into regions/ before evaluating "
             "(LVE and FDD need them)")

    videos = _find_videos(raw)
    takes: list[tuple[str, int, list[Path]]] = []
    for subject in sorted(meshes):
        folder = raw / "faces" / subject
        if not folder.is_dir():
            warn(f"no faces/{subject} folder: subject {subject} has a template but no sequences")
            continue
        by_take: dict[int, list[Path]] = {}
        for entry in sorted(folder.iterdir()):
            stem = _ARCHIVE.sub("", entry.name) if entry.is_file() else entry.name
            if entry.is_file() and stem == entry.name:
                continue  # not an archive
            parsed = _sentence_of(stem)
            if parsed is None:
                continue
            emotional, number = parsed
            if not emotional:
                report.neutral_ignored += 1
                continue
            by_take.setdefault(number, []).append(entry)
        for number, entries in sorted(by_take.items()):
            entries.sort(key=lambda e: 0 if e.is_dir() else 1 if e.suffix.lower() == ".tar" else 2)
            takes.append((subject, number, entries))

    bar = tqdm(takes, desc="import", unit="seq", disable=not progress, file=sys.stderr)
    for subject, number, entries in bar:
        name = sequence_name(subject, number)
        try:
            frames = None
            for entry in entries:
                frames = _vl_frames(entry)
                if frames:
                    break
            if not frames:
                raise FacegenError("no .vl frames in " + ", ".join(e.name for e in entries))
            video = videos.get((subject, number))
            if video is None:
                raise FacegenError(f"no video with its audio (videos/{name}.flv)")
            ref = references[subject] if normalisation == "template" else None
            motion = np.empty((len(frames), first.num_vertices * 3), np.float32)
            for t, (member, data) in enumerate(frames):
                v = read_vl(data, f"{member} of {name}")
                if v.shape[0] != first.num_vertices:
                    raise FacegenError(f"{member} has {v.shape[0]} vertices, the template "
                                       f"{first.num_vertices}")
                motion[t] = normalise(v, faces, ref).reshape(-1)
            if video.suffix.lower() == ".wav":
                import shutil

                with atomic_path(out / "wav" / f"{name}.wav") as tmp:
                    shutil.copyfile(video, tmp)
            else:
                _extract_audio(video, out / "wav" / f"{name}.wav", sample_rate)
            writer.write_sequence(name, motion)
            transcript = sentences_text.get(name, sentences_text.get(number))
            if transcript:
                writer.write_transcript(name, transcript)
            report.sequences.append(name)
        except FacegenError as exc:
            report.skipped.append((name, str(exc)))
            warn(f"skipping {name}: {exc}")
    if not report.sequences:
        raise FacegenError(f"no sequence of {raw} could be imported: see the messages above")
    return report
