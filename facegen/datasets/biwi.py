"""The BIWI community layout (FaceFormer, CodeTalker): `Dataset` reads a dataset folder, `DatasetWriter`
writes one.

Layout of a dataset folder ROOT (names as the community uses them)::

    ROOT/wav/{subj}_e{NN}.wav             speech
    ROOT/vertices_npy/{subj}_e{NN}.npy    motion, [T, 3V] at 25 fps (float32 or float64; [T, V, 3] accepted)
    ROOT/curves/{subj}_e{NN}.npy          or, compactly, the rig curves of the motion [T, C] (facegen's
                                          synthetic corpora): posed on the fly with facegen.face.rig on the
                                          subject's template and the regions of BIWI.ply
    ROOT/templates.pkl                    {subj: [V, 3]} neutral faces (read with a restricted unpickler)
    ROOT/templates/{subj}.ply | .npy      the same, one file per subject (these win over templates.pkl)
    ROOT/BIWI.ply                         the face list (and a neutral face: the template of trained bundles)
    ROOT/regions/lve.txt, fdd.txt         lip region (LVE) and upper-face region (FDD), 0-based indices
    ROOT/text/{subj}_e{NN}.txt            transcripts (for the text modality)
    ROOT/alignments/{subj}_e{NN}.json     word timings you already have (.json, .TextGrid or .csv): used
                                          instead of forced alignment

Word alignments of transcripts are computed once with `facegen.align.align` and cached with the
features (see facegen.datasets.cache).

Region files map to bundle region names: lve.txt → "lips", fdd.txt → "upper_face"; any other
regions/<name>.txt keeps its name.

A sequence whose files are missing or unreadable is reported by name and skipped (`on_bad="skip"`,
the default) or stops the run (`on_bad="fail"`); a vertex file whose vertex count differs from its
subject's template is always an error. A Dataset's `reporter` (default: notes on stderr) hears of every
skipped sequence (its notes) and draws a bar while features are computed (when it draws bars).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterable
from collections.abc import Sequence as SequenceABC
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from facegen.atomic import atomic_path
from facegen.audio import FeatureConfig, write_wav
from facegen.datasets.cache import (
    BadSequence,
    FeatureCache,
    default_cache_dir,
    digest,
    read_json,
    read_sequence_audio,
    stat_key,
    write_json,
)
from facegen.datasets.splits import Splits
from facegen.datasets.templates import as_vertices, read_templates_pkl, write_templates_pkl
from facegen.errors import FacegenError
from facegen.face.mesh import Mesh, read_mesh, read_region, write_mesh, write_region
from facegen.face.regions import COMMUNITY_FILES, file_stem, region_name
from facegen.runtime import NOTES, SILENT, Reporter

ALIGNMENT_SUFFIXES = (".json", ".textgrid", ".csv")
LENGTH_RATIO = 0.8  # audio and motion shorter than this fraction of each other: the sequence is corrupt


@dataclass
class Sequence:
    """The files of one sequence (transcript and alignment may be absent)."""

    name: str
    subject: str
    wav: Path
    vertices: Path
    text: Path | None = None
    alignment: Path | None = None
    curves: Path | None = None  # rig curves instead of vertices (facegen's synthetic corpora)

    @property
    def motion(self) -> Path:
        """The file the motion is read from: the vertices, or the rig curves."""
        return self.curves if self.curves is not None else self.vertices


@dataclass
class Item:
    """A sequence ready for training or evaluation: features in memory, vertices read on demand."""

    seq: Sequence
    mel: np.ndarray  # [T, n_mels] float32
    text: np.ndarray | None  # [T, D] float32 or None
    num_frames: int
    template: np.ndarray  # [V, 3] float32, the subject's neutral face
    pose: Callable[[np.ndarray], np.ndarray] | None = None  # rig curves [T, C] -> vertices [T, V, 3]
    phones: np.ndarray | None = None  # [T, P] phone one-hot, set for models with a phone stream

    @property
    def name(self) -> str:
        return self.seq.name

    @property
    def subject(self) -> str:
        return self.seq.subject

    def vertices(self) -> np.ndarray:
        """The ground truth [T, 3V] float32: a writable copy read from the memory-mapped .npy, or the rig
        curves posed on the subject's face."""
        if self.seq.curves is not None and self.pose is not None:
            curves = np.load(self.seq.curves)[: self.num_frames]
            return self.pose(curves).reshape(self.num_frames, -1).astype(np.float32, copy=False)
        arr = np.load(self.seq.vertices, mmap_mode="r")
        return np.array(arr[: self.num_frames].reshape(self.num_frames, -1), dtype=np.float32)


class Dataset:
    """A dataset folder in the community layout (see the module docstring)."""

    def __init__(self, root: str | os.PathLike, *, cache_dir: str | os.PathLike | None = None,
                 on_bad: str = "skip", reporter: Reporter = NOTES) -> None:
        self.root = Path(root)
        if not self.root.is_dir():
            raise FacegenError(f"dataset folder {self.root} does not exist: pass a folder with wav/ and "
                               "vertices_npy/ (the BIWI community layout)")
        for sub in ("wav", "vertices_npy"):
            if not (self.root / sub).is_dir() and not (sub == "vertices_npy"
                                                       and (self.root / "curves").is_dir()):
                raise FacegenError(f"{self.root} has no {sub}/ folder: pass a dataset in the BIWI community "
                                   "layout (wav/, vertices_npy/, templates.pkl, BIWI.ply)")
        if on_bad not in ("skip", "fail"):
            raise ValueError(f"on_bad must be 'skip' or 'fail', not {on_bad!r}")
        self.on_bad = on_bad
        self.reporter = reporter
        self.cache_dir = Path(cache_dir) if cache_dir is not None else default_cache_dir(self.root)
        try:
            self.cache_dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise FacegenError(f"cannot create the cache folder {self.cache_dir} ({exc.strerror}): "
                               "pass a writable cache folder", param="cache_dir") from exc
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
                    out[path.stem] = as_vertices(arr, f"template {path}")
                elif path.suffix.lower() in (".ply", ".obj"):
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
                name = region_name(path.stem)
                if path.stem in COMMUNITY_FILES or name not in out:
                    out[name] = read_region(path)
        return out

    @cached_property
    def mesh(self) -> Mesh:
        """BIWI.ply (its vertices and faces) with the dataset's regions."""
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
        self.reporter.note(f"skipping sequence {name}: {reason}")

    def sequence(self, name: str) -> Sequence:
        subject = name.split("_")[0]
        text = self.root / "text" / f"{name}.txt"
        alignment = self._alignment_files.get(name)
        wav, npy = self.root / "wav" / f"{name}.wav", self.root / "vertices_npy" / f"{name}.npy"
        curves = self.root / "curves" / f"{name}.npy"
        return Sequence(name, subject, wav, npy, text if text.is_file() else None, alignment,
                        curves if curves.is_file() and not npy.is_file() else None)

    def sequences(self, names: Iterable[str]) -> list[Sequence]:
        """The sequences whose wav and npy files exist (others reported as bad). A dataset with curves/
        (facegen's voices corpus: each sentence said by one subject) holds any subset of subject x sentence:
        names with no file at all are simply not in it."""
        out = []
        sparse = (self.root / "curves").is_dir()
        present = ({p.stem for folder in ("wav", "curves", "vertices_npy") if (self.root / folder).is_dir()
                    for p in (self.root / folder).iterdir()} if sparse else set())
        for name in names:
            if sparse and name not in present:  # (a listing: 70,000 names of a sparse split in 0.1 s)
                continue
            seq = self.sequence(name)
            missing = [p.relative_to(self.root).as_posix() for p in (seq.wav, seq.motion)
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
        if seq.curves is not None:
            return self._curve_frames(seq)
        index = self._vertex_index
        key = stat_key(seq.vertices)
        entry = index.get(seq.name)
        if entry and entry.get("stat") == key and entry.get("num_vertices") == num_vertices:
            return int(entry["frames"])
        try:
            arr = np.load(seq.vertices, mmap_mode="r", allow_pickle=False)
        except (OSError, ValueError, EOFError) as exc:
            raise BadSequence(f"{seq.vertices.name} is not a readable .npy file ({exc})") from exc
        shape = arr.shape
        if arr.ndim == 3 and shape[2] == 3:
            v = shape[1]
        elif arr.ndim == 2 and shape[1] % 3 == 0:
            v = shape[1] // 3
        else:
            raise BadSequence(f"{seq.vertices.name} has shape {shape}, not [T, 3V]")
        if v != num_vertices:
            raise FacegenError(f"{seq.vertices} has {v} vertices per frame but the template of {seq.subject} "
                               f"has {num_vertices}: the vertex files and templates must share one topology")
        if shape[0] == 0:
            raise BadSequence(f"{seq.vertices.name} has no frames")
        if arr.dtype.kind != "f":
            raise BadSequence(f"{seq.vertices.name} holds {arr.dtype}, not floats")
        for start in range(0, shape[0], 64):
            if not np.isfinite(arr[start:start + 64]).all():
                raise BadSequence(f"{seq.vertices.name} contains NaN or infinite coordinates")
        index[seq.name] = {"stat": key, "num_vertices": num_vertices, "frames": int(shape[0])}
        self._vertex_index_dirty = True
        return int(shape[0])

    def _curve_frames(self, seq: Sequence) -> int:
        from facegen.face.rig import CHANNELS

        try:
            arr = np.load(seq.curves, allow_pickle=False)
        except (OSError, ValueError, EOFError) as exc:
            raise BadSequence(f"{seq.curves.name} is not a readable .npy file ({exc})") from exc
        if arr.ndim != 2 or arr.shape[1] != len(CHANNELS) or arr.shape[0] == 0 or not np.isfinite(arr).all():
            raise BadSequence(f"{seq.curves.name} has shape {arr.shape}: not [T, {len(CHANNELS)}] finite rig "
                              "curves")
        return int(arr.shape[0])

    def pose(self, subject: str) -> Callable[[np.ndarray], np.ndarray]:
        """Rig curves -> vertices on `subject`'s face (the rig built once per subject)."""
        if subject not in self._rigs:
            from facegen.face.rig import Rig

            mesh = self.mesh
            self._rigs[subject] = Rig(Mesh(self.templates[subject], mesh.faces, mesh.regions)).pose
        return self._rigs[subject]

    @cached_property
    def _rigs(self) -> dict:
        return {}

    @cached_property
    def _alignment_files(self) -> dict[str, Path]:
        """Each sequence's alignment file in alignments/ (the first of its name by sorted path whose suffix is
        one of ALIGNMENT_SUFFIXES), listed once."""
        folder, out = self.root / "alignments", {}
        if folder.is_dir():
            for path in sorted(folder.iterdir()):
                if path.suffix.lower() in ALIGNMENT_SUFFIXES:
                    out.setdefault(path.stem, path)
        return out

    @cached_property
    def _vertex_index(self) -> dict:
        return read_json(self.cache_dir / "vertices.json")

    def _save_vertex_index(self) -> None:
        if self._vertex_index_dirty:
            write_json(self.cache_dir / "vertices.json", self._vertex_index)
            self._vertex_index_dirty = False

    def phones(self, seq: Sequence, num_frames: int, fps: float) -> np.ndarray:
        """Per-frame phone one-hot [T, P]: the phones of the sequence's alignment JSON (with their "alphabet",
        as facegen's voices corpus and `facegen align --phones` write them), else pocketsphinx's phone
        alignment of its transcript (computed once and cached); a BadSequence with neither."""
        import json

        from facegen.phonetics import phone_frames

        data: dict = {}
        if seq.alignment is not None and seq.alignment.suffix.lower() == ".json":
            with contextlib.suppress(OSError, ValueError):
                data = json.loads(seq.alignment.read_text(encoding="utf-8"))
        if isinstance(data, dict) and isinstance(data.get("phones"), list):
            try:
                phones = [(p["phone"], p["start"], p["end"]) for p in data["phones"]]
            except (KeyError, TypeError) as exc:
                raise BadSequence(f"alignments/{seq.name}.json has malformed phones ({exc})") from exc
            return phone_frames(phones, num_frames, fps, data.get("alphabet", "cmu"))
        if seq.text is None:
            raise BadSequence(f"no phones in alignments/{seq.name}.json and no transcript "
                              f"text/{seq.name}.txt to align them from, for the phone stream")
        key = digest([stat_key(seq.wav), stat_key(seq.text)])
        cached = self.cache_dir / "phones" / f"{seq.name}-{key}.json"
        if not cached.is_file():
            from facegen import align
            from facegen.alignment_files import write_alignment

            samples, sr = read_sequence_audio(seq)
            try:
                words, found = align.align_phones(samples, sr, seq.text.read_text(encoding="utf-8",
                                                                                  errors="replace"))
            except FacegenError as exc:
                raise BadSequence(f"its phones could not be aligned ({exc})") from exc
            cached.parent.mkdir(parents=True, exist_ok=True)
            write_alignment(words, cached, phones=found)
        phones = [(p["phone"], p["start"], p["end"]) for p in json.loads(cached.read_text())["phones"]]
        return phone_frames(phones, num_frames, fps)

    def words(self, seq: Sequence, samples: np.ndarray, sr: int) -> list:
        """Word timings: the user's alignment file, else the transcript aligned once (and cached)."""
        from facegen import align
        from facegen.alignment_files import read_alignment, write_alignment

        duration = len(samples) / sr
        if seq.alignment is not None:
            return read_alignment(seq.alignment, duration=duration)
        if seq.text is None:
            raise BadSequence(f"no transcript text/{seq.name}.txt or alignment alignments/{seq.name}.json "
                               "for the text modality")
        transcript = seq.text.read_text(encoding="utf-8", errors="replace")
        key = digest([stat_key(seq.wav), stat_key(seq.text)])
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
             backend=None) -> list[Item]:
        """Features of every usable sequence (from the cache when it has them); bad ones reported. A bar is
        drawn when the dataset's reporter draws bars."""
        cache = FeatureCache(self.cache_dir, features, filters, backend)
        items = []
        reporter = self.reporter if sequences else SILENT
        bar = reporter.bar(sequences, desc="features", unit="seq", leave=False)
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
        except BadSequence as exc:
            self.bad(seq.name, str(exc))
            return None
        audio_frames = mel.shape[0]
        if min(audio_frames, frames) < LENGTH_RATIO * max(audio_frames, frames):
            self.bad(seq.name, f"the audio lasts {audio_frames} frames but the motion {frames} frames")
            return None
        n = min(audio_frames, frames)
        pose = self.pose(seq.subject) if seq.curves is not None else None
        return Item(seq, mel[:n], None if text is None else text[:n], n, template, pose)


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
        with atomic_path(self.root / "BIWI.ply") as tmp:
            write_mesh(mesh, tmp)
        self.write_regions(mesh.regions)

    def write_regions(self, regions: dict[str, np.ndarray]) -> None:
        """regions/<file>.txt per region (lips → lve.txt, upper_face → fdd.txt, others by name)."""
        for name, idx in regions.items():
            with atomic_path(self.root / "regions" / f"{file_stem(name)}.txt") as tmp:
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
            from facegen.alignment_files import write_alignment

            (self.root / "alignments").mkdir(exist_ok=True)
            write_alignment(words, self.root / "alignments" / f"{name}.json")  # atomically

    def write_wav(self, name: str, audio: np.ndarray, sample_rate: int) -> None:
        with atomic_path(self.root / "wav" / f"{name}.wav") as tmp:
            write_wav(audio, sample_rate, tmp)

    def write_transcript(self, name: str, transcript: str) -> None:
        (self.root / "text").mkdir(exist_ok=True)
        with atomic_path(self.root / "text" / f"{name}.txt") as tmp:
            tmp.write_text(transcript.strip() + "\n", encoding="utf-8")
