"""Import of the raw BIWI release (no MATLAB) into the community layout: .vl frames (in folders or tar
archives), OBJ templates, the audio of the videos (ffmpeg), transcripts, and the community's normalisation.
"""

from __future__ import annotations

import os
import re
import shutil
import tarfile
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from facegen.atomic import atomic_path
from facegen.datasets.biwi import DatasetWriter
from facegen.datasets.splits import parse_subjects, sequence_name
from facegen.errors import FacegenError
from facegen.face.mesh import Mesh, read_mesh, read_region, surface_area, unit_area
from facegen.face.regions import COMMUNITY_FILES
from facegen.processes import run_tool
from facegen.runtime import NOTES, Reporter

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


def normalise_biwi(vertices: np.ndarray, faces: np.ndarray,
                   reference: tuple[np.ndarray, float] | None = None) -> np.ndarray:
    """The community's BIWI normalisation of one mesh: rotate π about x, centre, scale to unit area.

    As CodeTalker's creatDataset_BIWI.m / process_BIWI_template.m: V ← V·Rx(π) (row vectors), then
    V ← V − mean(V), then V ← V / sqrt(total surface area) (facegen.face.mesh.unit_area). With `reference` =
    (mean, sqrt_area) of the rotated template, frames use the template's centre and scale instead of
    their own. Returns float32 [V, 3].
    """
    return unit_area(np.asarray(vertices, np.float64) @ ROTATE_X_PI, faces, reference).astype(np.float32)


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
    """(member name, bytes) of every .vl frame in a folder or tar archive, in frame order; None if none.
    Sizes are checked (from the file system or the tar header) before anything is read."""
    frames: list[tuple[str, bytes]] = []
    total = 0

    def admit(name: str, size: int) -> None:
        nonlocal total
        total += size
        if size > MAX_VL_BYTES or total > MAX_SEQUENCE_BYTES:
            raise FacegenError(f"{source.name}: {name} is {size / 1e6:.0f} MB ({total / 1e6:.0f} MB so far), "
                               f"more than any BIWI frame (~0.3 MB each, at most {MAX_VL_BYTES >> 20} MB) or "
                               f"sequence (at most {MAX_SEQUENCE_BYTES >> 20} MB): check the archive")

    if source.is_dir():
        for p in source.rglob("*"):
            if p.suffix.lower() == ".vl" and p.is_file():
                admit(p.name, p.stat().st_size)
                frames.append((p.name, p.read_bytes()))
    else:
        try:
            with tarfile.open(source, "r:*") as tar:
                for member in tar:
                    if member.isfile() and member.name.lower().endswith(".vl"):
                        admit(member.name, member.size)
                        f = tar.extractfile(member)
                        if f is not None:
                            frames.append((Path(member.name).name, f.read(member.size)))
        except (tarfile.TarError, OSError, EOFError) as exc:
            raise FacegenError(f"{source.name} is not a readable tar archive ({exc})") from exc
    if not frames:
        return None
    return sorted(frames, key=lambda f: _natural_key(f[0]))


MAX_VL_BYTES = 4 << 20  # one .vl frame: BIWI's are 23,370 x 3 float32 (~0.3 MB)
MAX_SEQUENCE_BYTES = 768 << 20  # one sequence's frames (BIWI's longest take: ~0.1 GB)


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
    with atomic_path(wav) as tmp:
        done = run_tool("ffmpeg", ["-nostdin", "-v", "error", "-y", "-i", video, "-vn", "-ac", "1",
                                   "-ar", str(sample_rate), "-acodec", "pcm_s16le", "-f", "wav", tmp],
                        text=True)
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
                subjects: Iterable[str] | None = None, sample_rate: int = 44100,
                reporter: Reporter = NOTES) -> ImportReport:
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

    `reporter`: a progress bar over the takes when it draws bars; skipped takes and a missing `regions` are
    its notes (default: on stderr).
    """

    raw, out = Path(raw), Path(out)
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
            meshes.setdefault(m.group(1).upper(), read_mesh(path))  # order kept: the .vl frames' order
    if not meshes:
        raise FacegenError(f"no subject templates (F1.obj, M1.obj, …) in {raw}/rigid_scans: "
                           "check the folder")
    first = next(iter(meshes.values()))
    for subject, mesh in meshes.items():
        if mesh.num_vertices != first.num_vertices or not np.array_equal(mesh.faces, first.faces):
            raise FacegenError(f"the template of {subject} has a different topology from the others: "
                               "all BIWI templates share one mesh")
    faces = first.faces
    templates = {s: normalise_biwi(m.vertices, faces) for s, m in sorted(meshes.items())}
    references = {}
    for s, m in meshes.items():
        rotated = np.asarray(m.vertices, np.float64) @ ROTATE_X_PI
        centre = rotated.mean(axis=0)
        references[s] = (centre, np.sqrt(surface_area(rotated - centre, faces)))

    region_idx = {}
    if regions is not None:
        for stem, region in COMMUNITY_FILES.items():
            src = Path(regions) / f"{stem}.txt"
            if not src.is_file():
                raise FacegenError(f"{src} is missing: pass the folder with lve.txt and fdd.txt as the "
                                   "regions",
                                   param="regions")
            idx = read_region(src)
            if idx.size and (idx.min() < 0 or idx.max() >= first.num_vertices):
                raise FacegenError(f"{src} has vertex indices outside the {first.num_vertices} vertices "
                                   "of the mesh: pass the region files of this topology")
            region_idx[region] = idx
    else:
        reporter.note("no region files given: copy lve.txt and fdd.txt into regions/ before evaluating "
                      "(LVE and FDD need them)")
    fresh = not out.exists() or (out.is_dir() and not any(out.iterdir()))
    try:
        return _import_takes(raw, out, meshes, templates, faces, references, region_idx, normalisation,
                             sentences_text, sample_rate, reporter)
    except BaseException:
        if fresh and out.is_dir():  # nothing half-imported is left: the folder was new (or empty)
            shutil.rmtree(out, ignore_errors=True)
        raise


def _import_takes(raw: Path, out: Path, meshes: dict, templates: dict, faces: np.ndarray, references: dict,
                  region_idx: dict, normalisation: str, sentences_text: dict, sample_rate: int,
                  reporter: Reporter) -> ImportReport:
    """The writing half of import_biwi (its inputs checked)."""
    first = next(iter(meshes.values()))
    writer = DatasetWriter(out)
    report = ImportReport(out=out, subjects=sorted(meshes))
    writer.write_templates(templates)
    writer.write_mesh(Mesh(np.mean(np.stack(list(templates.values())), axis=0).astype(np.float32), faces))
    if region_idx:
        writer.write_regions(region_idx)

    videos = _find_videos(raw)
    takes: list[tuple[str, int, list[Path]]] = []
    for subject in sorted(meshes):
        folder = raw / "faces" / subject
        if not folder.is_dir():
            reporter.note(f"no faces/{subject} folder: subject {subject} has a template but no sequences")
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

    bar = reporter.bar(takes, desc="import", unit="seq")
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
                motion[t] = normalise_biwi(v, faces, ref).reshape(-1)
            if video.suffix.lower() == ".wav":
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
            reporter.note(f"skipping {name}: {exc}")
    if not report.sequences:
        raise FacegenError(f"no sequence of {raw} could be imported: see the messages above")
    return report
