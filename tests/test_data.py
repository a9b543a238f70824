"""Datasets in the BIWI community layout: splits, safe templates.pkl, features and their cache, bad
files, and the raw BIWI import (on tiny raw files made here in the release's formats)."""

from __future__ import annotations

import io
import os
import pickle
import subprocess
import tarfile
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from helpers import TOY_SPLITS, grid_face, make_dataset

from facegen.audio import FeatureConfig, mel_filters
from facegen.datasets.biwi import Dataset, DatasetWriter
from facegen.datasets.raw import import_biwi, read_transcripts, read_vl, write_vl
from facegen.datasets.splits import Splits, parse_numbers
from facegen.datasets.templates import read_templates_pkl, write_templates_pkl
from facegen.errors import FacegenError
from facegen.face.mesh import Mesh
from facegen.runtime import SILENT, Reporter

FPS = 25
SR = 16000


@pytest.fixture(scope="module")
def toy(tmp_path_factory) -> Path:
    return make_dataset(tmp_path_factory.mktemp("toy"))


@pytest.fixture(scope="module")
def gpt2_backend(tmp_path_factory):
    from helpers import make_tiny_gpt2

    from facegen.text import load_text_backend

    folder = make_tiny_gpt2(tmp_path_factory.mktemp("gpt2"), n_positions=64)
    return load_text_backend(str(folder))


def test_default_splits_are_the_communitys():
    s = Splits()
    assert len(s.names("train")) == 192 and len(s.names("val")) == 24
    assert len(s.names("test-a")) == 24 and len(s.names("test-b")) == 32
    assert s.names("train")[:2] == ["F2_e01", "F2_e02"] and s.names("train")[-1] == "M5_e32"
    assert s.names("val")[0] == "F2_e33" and s.names("test-a")[-1] == "M5_e40"
    assert s.names("test-b")[0] == "F1_e37" and {n[:2] for n in s.names("test-b")} == {
        "F1", "F5", "F6", "F7", "F8", "M1", "M2", "M6"}
    assert Splits.from_dict(s.to_dict()) == s


def test_split_options_parse_and_refuse_overlaps():
    assert parse_numbers("1-3,5, e7-e8") == (1, 2, 3, 5, 7, 8)
    s = Splits.from_options(train_subjects="F2,M3", train_sentences="1-10", val_sentences="11",
                            test_sentences="12-13")
    assert s.names("val") == ["F2_e11", "M3_e11"] and s.test_subjects == Splits().test_subjects
    with pytest.raises(FacegenError, match="both the train and val"):
        Splits(train_sentences="1-33")
    with pytest.raises(FacegenError, match="both training and test-b"):
        Splits(test_subjects=("F2", "F1"))
    with pytest.raises(FacegenError, match="like 1-32"):
        parse_numbers("one-two")
    with pytest.raises(FacegenError, match="unknown split"):
        Splits().names("test-c")


@pytest.mark.parametrize("protocol", [2, 3, 4, 5])
def test_templates_pkl_written_by_any_protocol_is_read(tmp_path, protocol):
    data = {"F1": np.arange(12, dtype=np.float64).reshape(4, 3), "M1": np.ones((4, 3), np.float32)}
    path = tmp_path / "templates.pkl"
    path.write_bytes(pickle.dumps(data, protocol=protocol))
    out = read_templates_pkl(path)
    assert sorted(out) == ["F1", "M1"] and out["F1"].dtype == np.float32
    np.testing.assert_array_equal(out["F1"], data["F1"])
    write_templates_pkl(out, tmp_path / "again.pkl")
    np.testing.assert_array_equal(read_templates_pkl(tmp_path / "again.pkl")["M1"], data["M1"])


class _Exploit:
    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def test_malicious_templates_pkl_is_refused_without_running(tmp_path):
    marker = tmp_path / "pwned"
    path = tmp_path / "templates.pkl"
    path.write_bytes(pickle.dumps({"F1": np.zeros((4, 3)), "evil": _Exploit(marker)}))
    with pytest.raises(FacegenError, match=r"refusing to load .*(posix|os)\.system"):
        read_templates_pkl(path)
    assert not marker.exists()
    # other objects, object arrays and non-dicts are refused too
    path.write_bytes(pickle.dumps({"F1": __import__("collections").OrderedDict(a=1)}))
    with pytest.raises(FacegenError, match="collections.OrderedDict"):
        read_templates_pkl(path)
    path.write_bytes(pickle.dumps({"F1": np.array(["a", 1], dtype=object)}))
    with pytest.raises(FacegenError, match="not a numeric numpy array"):
        read_templates_pkl(path)
    path.write_bytes(pickle.dumps([np.zeros((4, 3))]))
    with pytest.raises(FacegenError, match="not a dict"):
        read_templates_pkl(path)


def test_dataset_parts(toy):
    ds = Dataset(toy, reporter=SILENT)
    assert sorted(ds.templates) == ["F1", "F2", "F3"] and ds.template("F2").shape == (200, 3)
    assert ds.mesh.num_vertices == 200 and set(ds.mesh.regions) == {"lips", "upper_face"}
    assert (toy / "regions" / "lve.txt").is_file() and (toy / "regions" / "fdd.txt").is_file()
    seqs = ds.split("train", TOY_SPLITS)
    assert [s.name for s in seqs] == [f"{s}_e{n:02d}" for s in ("F2", "F3") for n in range(1, 5)]
    assert seqs[0].alignment == toy / "alignments" / "F2_e01.json" and seqs[0].text.is_file()
    assert [s.name for s in ds.split("test-b", TOY_SPLITS)] == ["F1_e06", "F1_e07"]


def test_templates_folder_wins_over_pkl(tmp_path):
    root = make_dataset(tmp_path / "d", subjects=("F2",), sentences=[1], with_alignments=False)
    (root / "templates").mkdir()
    np.save(root / "templates" / "F2.npy", np.full((200, 3), 0.5, np.float32))
    np.save(root / "templates" / "M9.npy", np.zeros(600, np.float32))  # flat [3V] is accepted too
    ds = Dataset(root, reporter=SILENT)
    assert ds.template("F2")[0, 0] == 0.5 and ds.template("M9").shape == (200, 3)
    with pytest.raises(FacegenError, match="no template for subject F7"):
        ds.template("F7")


def test_features_are_computed_once_and_cached(toy, gpt2_backend):
    feats = FeatureConfig()
    filters = mel_filters(feats)
    ds = Dataset(toy, cache_dir=toy / "cache1", reporter=SILENT)
    seqs = ds.split("train", TOY_SPLITS)[:3]
    items = ds.load(seqs, feats, filters, gpt2_backend)
    assert [it.name for it in items] == ["F2_e01", "F2_e02", "F2_e03"]
    it = items[0]
    assert it.num_frames == round((1.0 + 0.08) * FPS) == it.mel.shape[0] == it.text.shape[0]
    assert it.mel.shape[1] == 128 and it.text.shape[1] == gpt2_backend.dim
    from facegen.alignment_files import read_alignment
    from facegen.text import text_features

    words = read_alignment(toy / "alignments" / "F2_e01.json")
    np.testing.assert_array_equal(it.text, text_features(words, gpt2_backend, it.num_frames, feats))
    assert it.vertices().shape == (it.num_frames, 600) and it.vertices().dtype == np.float32
    cached = sorted(p.name for p in (toy / "cache1" / "features").iterdir())
    assert sum(".mel-" in n for n in cached) == 3 and sum(".text-" in n for n in cached) == 3
    stamps = {p: p.stat().st_mtime_ns for p in (toy / "cache1" / "features").iterdir()}

    again = Dataset(toy, cache_dir=toy / "cache1", reporter=SILENT).load(seqs, feats, filters, gpt2_backend)
    np.testing.assert_array_equal(again[1].mel, items[1].mel)
    np.testing.assert_array_equal(again[1].text, items[1].text)
    # read, not redone
    assert {p: p.stat().st_mtime_ns for p in (toy / "cache1" / "features").iterdir()} == stamps

    # a changed wav file is noticed (size/mtime in the key): its mel is recomputed into a new entry
    wav = toy / "wav" / "F2_e01.wav"
    os.utime(wav, ns=(wav.stat().st_atime_ns, wav.stat().st_mtime_ns + 10**9))
    Dataset(toy, cache_dir=toy / "cache1", reporter=SILENT).load(seqs[:1], feats, filters, gpt2_backend)
    assert sum(".mel-" in p.name for p in (toy / "cache1" / "features").iterdir()) == 4
    # audio-only loading needs no text backend and no transcript
    audio_only = Dataset(toy, cache_dir=toy / "cache1", reporter=SILENT).load(seqs, feats, filters, None)
    assert audio_only[0].text is None


def _corrupt_copy(tmp_path: Path) -> Path:
    root = make_dataset(tmp_path / "bad", subjects=("F2", "F3"), sentences=range(1, 5))
    (root / "vertices_npy" / "F2_e02.npy").write_bytes(b"this is not a numpy file")
    (root / "wav" / "F3_e01.wav").unlink()
    v = np.load(root / "vertices_npy" / "F3_e03.npy")
    v[3, 7] = np.nan
    np.save(root / "vertices_npy" / "F3_e03.npy", v)
    (root / "wav" / "F3_e04.wav").write_bytes(b"RIFF garbage")
    return root


def test_bad_sequences_are_reported_by_name_and_skipped(tmp_path):
    root = _corrupt_copy(tmp_path)
    messages: list[str] = []
    ds = Dataset(root, reporter=Reporter(note=messages.append))
    seqs = ds.split("train", TOY_SPLITS)
    feats = FeatureConfig()
    items = ds.load(seqs, feats, mel_filters(feats))
    assert [it.name for it in items] == ["F2_e01", "F2_e03", "F2_e04", "F3_e02"]
    reasons = dict(ds.skipped)
    assert set(reasons) == {"F2_e02", "F3_e01", "F3_e03", "F3_e04"}
    assert "wav/F3_e01.wav missing" in reasons["F3_e01"]
    assert "F2_e02.npy is not a readable .npy" in reasons["F2_e02"]
    assert "NaN" in reasons["F3_e03"] and "F3_e04.wav is not readable audio" in reasons["F3_e04"]
    assert len(messages) == 4 and all(m.startswith("skipping sequence") for m in messages)
    with pytest.raises(FacegenError, match="sequence F3_e01: wav/F3_e01.wav missing"):
        Dataset(root, on_bad="fail", reporter=SILENT).split("train", TOY_SPLITS)
    with pytest.raises(FacegenError, match="sequence F2_e02"):
        ds2 = Dataset(root, on_bad="fail", reporter=SILENT)
        ds2.load(ds2.sequences(["F2_e01", "F2_e02"]), feats, mel_filters(feats))


def test_text_needs_a_transcript_or_alignment(tmp_path, gpt2_backend):
    root = make_dataset(tmp_path / "d", subjects=("F2",), sentences=[1, 2], with_alignments=False,
                        with_text=False)
    ds = Dataset(root, reporter=SILENT)
    feats = FeatureConfig()
    assert ds.load(ds.sequences(["F2_e01", "F2_e02"]), feats, mel_filters(feats), gpt2_backend) == []
    assert "no transcript text/F2_e01.txt" in dict(ds.skipped)["F2_e01"]


def test_vertex_count_mismatch_is_a_named_error(tmp_path):
    root = make_dataset(tmp_path / "d", subjects=("F2",), sentences=[1, 2], with_alignments=False)
    np.save(root / "vertices_npy" / "F2_e02.npy", np.zeros((20, 3 * 199), np.float32))
    ds = Dataset(root, reporter=SILENT)
    feats = FeatureConfig()
    with pytest.raises(FacegenError, match=r"F2_e02.npy has 199 vertices per frame but the template of F2 "
                                           r"has 200"):
        ds.load(ds.sequences(["F2_e01", "F2_e02"]), feats, mel_filters(feats))


def test_audio_and_motion_lengths_must_roughly_agree(tmp_path):
    root = make_dataset(tmp_path / "d", subjects=("F2",), sentences=[1], with_alignments=False)
    v = np.load(root / "vertices_npy" / "F2_e01.npy")
    np.save(root / "vertices_npy" / "F2_e01.npy", np.concatenate([v, v, v]))  # 3x as long as the audio
    ds = Dataset(root, reporter=SILENT)
    feats = FeatureConfig()
    assert ds.load(ds.sequences(["F2_e01"]), feats, mel_filters(feats)) == []
    assert "the audio lasts 27 frames but the motion 81 frames" in ds.skipped[0][1]
    np.save(root / "vertices_npy" / "F2_e01.npy", v[:-2])  # two frames short: truncated to the shorter
    item = Dataset(root, cache_dir=tmp_path / "c2", reporter=SILENT).load(ds.sequences(["F2_e01"]), feats,
                                                                    mel_filters(feats))[0]
    assert item.num_frames == 25 and item.mel.shape[0] == 25


def test_missing_dataset_parts_are_explained(tmp_path):
    with pytest.raises(FacegenError, match="does not exist"):
        Dataset(tmp_path / "nope")
    (tmp_path / "d" / "wav").mkdir(parents=True)
    with pytest.raises(FacegenError, match="no vertices_npy/ folder"):
        Dataset(tmp_path / "d")
    (tmp_path / "d" / "vertices_npy").mkdir()
    with pytest.raises(FacegenError, match="BIWI.ply is missing"):
        Dataset(tmp_path / "d", reporter=SILENT).mesh  # noqa: B018


def test_transcripts_are_aligned_once_and_cached(tmp_path, gpt2_backend, monkeypatch):
    from facegen.espeak import synthesize

    speech = synthesize("please open the window", rate=160)
    writer = DatasetWriter(tmp_path / "d")
    mesh = grid_face()
    writer.write_mesh(mesh)
    writer.write_templates({"F2": mesh.vertices})
    frames = round(speech.duration * FPS)
    writer.write_sequence("F2_e01", np.repeat(mesh.vertices[None], frames, 0), audio=speech.audio,
                          sample_rate=speech.sample_rate, transcript="Please open the window.")
    ds = Dataset(tmp_path / "d", reporter=SILENT)
    seq = ds.sequences(["F2_e01"])[0]
    words = ds.words(seq, speech.audio, speech.sample_rate)
    assert [w.text for w in words] == ["Please", "open", "the", "window"]
    truth = {w.text.lower(): w for w in speech.words}
    for w in words:
        assert abs(w.start - truth[w.text.lower()].start) < 0.15 and w.end > w.start
    assert len(list((ds.cache_dir / "alignments").glob("F2_e01-*.json"))) == 1
    import facegen.align

    def no_second_alignment(*_args, **_kw):
        raise AssertionError("the cached alignment was not used")

    monkeypatch.setattr(facegen.align, "align", no_second_alignment)
    assert [w.text for w in ds.words(seq, speech.audio, speech.sample_rate)] == [w.text for w in words]
    feats = FeatureConfig()
    item = ds.load([seq], feats, mel_filters(feats), gpt2_backend)[0]
    assert item.text.shape == (item.num_frames, gpt2_backend.dim) and np.abs(item.text).sum() > 0


# ------------------------------------------------------------------------------ raw BIWI import
def _obj_text(mesh: Mesh) -> str:
    """An OBJ like BIWI's rigid_scans templates: texture coordinates on every face corner."""
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in mesh.vertices]
    lines += [f"vt {u:.4f} {v:.4f}" for u, v in np.random.default_rng(1).random((len(mesh.vertices) + 7, 2))]
    lines += [f"f {a + 1}/{a + 3} {b + 1}/{b + 1} {c + 1}/{c + 2}" for a, b, c in mesh.faces]
    return "\n".join(lines) + "\n"


def _raw_frames(template: np.ndarray, frames: int, scale: float) -> list[np.ndarray]:
    """Raw frames in BIWI's units and orientation: the template with the lower rows moving."""
    out = []
    for t in range(frames):
        v = template.copy()
        v[:60, 1] += scale * np.sin(t)
        out.append(v)
    return out


def _tar(path: Path, frames: list[np.ndarray], mode: str = "w") -> None:
    with tarfile.open(path, mode) as tar:
        for i, v in enumerate(frames):
            buf = io.BytesIO()
            buf.write(np.array([len(v)], "<u4").tobytes() + np.ascontiguousarray(v, "<f4").tobytes())
            info = tarfile.TarInfo(f"{path.stem.split('.')[0]}/frame_{i + 1:03d}.vl")
            info.size = buf.tell()
            buf.seek(0)
            tar.addfile(info, buf)


def _flv(path: Path, seconds: float, freq: float) -> None:
    import imageio_ffmpeg

    cmd = [imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-y", "-f", "lavfi", "-i",
           f"color=c=gray:s=64x64:d={seconds}:r=25", "-f", "lavfi", "-i",
           f"sine=frequency={freq}:sample_rate=44100:duration={seconds}", "-c:v", "flv", "-c:a", "libmp3lame",
           "-shortest", str(path)]
    subprocess.run(cmd, check=True, capture_output=True)


@pytest.fixture(scope="module")
def raw_biwi(tmp_path_factory) -> Path:
    """A tiny raw BIWI release: templates in mm, frames as .vl in tar/tgz/folders, FLV videos."""
    raw = tmp_path_factory.mktemp("raw")
    base = grid_face()
    mm = Mesh(base.vertices * 180 + np.array([5, 20, -700], np.float32), base.faces)
    for d in ("rigid_scans", "faces/F2/e02", "faces/F3", "videos/F3"):
        (raw / d).mkdir(parents=True)
    (raw / "rigid_scans" / "F2.obj").write_text(_obj_text(mm))
    (raw / "rigid_scans" / "F3.obj").write_text(_obj_text(Mesh(mm.vertices * 1.05, mm.faces)))
    (raw / "rigid_scans" / "F3_texture.png").write_bytes(b"\x89PNG")
    _tar(raw / "faces" / "F2" / "e01.tar", _raw_frames(mm.vertices, 5, 3.0))
    (raw / "faces" / "F2" / "e01.tgz").write_bytes(b"not the frames")  # the other archive of the take
    for i, v in enumerate(_raw_frames(mm.vertices, 4, 2.0)):
        write_vl(v, raw / "faces" / "F2" / "e02" / f"frame_{i + 1:03d}.vl")
    _tar(raw / "faces" / "F2" / "01.tar", _raw_frames(mm.vertices, 3, 1.0))  # a neutral take
    _tar(raw / "faces" / "F3" / "e01.tgz", _raw_frames(mm.vertices * 1.05, 6, 2.5), mode="w:gz")
    _tar(raw / "faces" / "F3" / "e02.tar", _raw_frames(mm.vertices * 1.05, 3, 1.0))  # no video: skipped
    _flv(raw / "videos" / "F2_e01.flv", 0.2, 300)
    _flv(raw / "videos" / "F2_e02.flv", 0.16, 400)
    _flv(raw / "videos" / "F3" / "e01.flv", 0.24, 500)
    (raw / "regions").mkdir()
    (raw / "regions" / "lve.txt").write_text(", ".join(map(str, range(60))))
    (raw / "regions" / "fdd.txt").write_text(", ".join(map(str, range(140, 200))))
    (raw / "sentences.txt").write_text("e01 Open the window.\ne02 Close the door.\n")
    return raw


def _area(v: np.ndarray, faces: np.ndarray) -> float:
    import trimesh

    return float(trimesh.Trimesh(v, faces, process=False).area)


def test_vl_format_round_trip(tmp_path):
    v = np.random.default_rng(0).normal(size=(7, 3)).astype(np.float32)
    write_vl(v, tmp_path / "f.vl")
    raw = (tmp_path / "f.vl").read_bytes()
    assert len(raw) == 4 + 7 * 12 and int.from_bytes(raw[:4], "little") == 7
    np.testing.assert_array_equal(read_vl(raw), v)
    with pytest.raises(FacegenError, match="says 7 vertices but holds 6"):
        read_vl(raw[:-12])


def test_import_biwi_writes_the_community_layout(raw_biwi, tmp_path):
    messages: list[str] = []
    out = tmp_path / "BIWI"
    report = import_biwi(raw_biwi, out, transcripts=raw_biwi / "sentences.txt", regions=raw_biwi / "regions",
                         reporter=Reporter(note=messages.append))
    assert report.subjects == ["F2", "F3"] and report.sequences == ["F2_e01", "F2_e02", "F3_e01"]
    assert report.neutral_ignored == 1 and [n for n, _ in report.skipped] == ["F3_e02"]
    assert "videos/F3_e02.flv" in report.skipped[0][1] and any("F3_e02" in m for m in messages)

    base = grid_face()
    templates = read_templates_pkl(out / "templates.pkl")
    t = templates["F2"].astype(np.float64)
    # normalised: centred, unit area, and rotated by pi about x (x kept, y and z flipped)
    np.testing.assert_allclose(t.mean(0), 0, atol=1e-6)
    assert _area(t, base.faces) == pytest.approx(1.0, rel=1e-5)
    raw_v = base.vertices.astype(np.float64) * 180
    expect = (raw_v - raw_v.mean(0)) * np.array([1, -1, -1]) / np.sqrt(_area(raw_v, base.faces))
    np.testing.assert_allclose(t, expect, atol=2e-6)

    v = np.load(out / "vertices_npy" / "F2_e01.npy")
    assert v.shape == (5, 600) and v.dtype == np.float32
    frames = v.reshape(5, 200, 3).astype(np.float64)
    for f in frames:  # every frame normalised on its own, as the community's scripts do
        np.testing.assert_allclose(f.mean(0), 0, atol=1e-6)
        assert _area(f, base.faces) == pytest.approx(1.0, rel=1e-5)
    # the moving rows moved (the motion went up in raw y, so down after the rotation)
    assert frames[1, :60, 1].mean() - frames[0, :60, 1].mean() < -1e-3
    assert np.load(out / "vertices_npy" / "F2_e02.npy").shape == (4, 600)
    assert np.load(out / "vertices_npy" / "F3_e01.npy").shape == (6, 600)

    audio, sr = sf.read(out / "wav" / "F3_e01.wav")
    assert sr == 44100 and audio.ndim == 1 and abs(len(audio) / sr - 0.24) < 0.06
    spectrum = np.abs(np.fft.rfft(audio))
    assert abs(np.argmax(spectrum) * sr / len(audio) - 500) < 15

    assert (out / "text" / "F2_e01.txt").read_text().strip() == "Open the window."
    assert (out / "text" / "F3_e01.txt").read_text().strip() == "Open the window."
    assert (out / "regions" / "lve.txt").read_text().startswith("0, 1, 2")
    ds = Dataset(out, reporter=SILENT)
    assert ds.mesh.num_vertices == 200 and np.array_equal(ds.mesh.faces, base.faces)
    assert len(ds.mesh.regions["lips"]) == 60
    np.testing.assert_allclose(ds.mesh.vertices, (templates["F2"] + templates["F3"]) / 2, atol=1e-5)


def test_transcripts_from_a_file_or_a_folder(tmp_path):
    (tmp_path / "list.txt").write_text("The first one.\nThe second one.\n")
    assert read_transcripts(tmp_path / "list.txt") == {1: "The first one.", 2: "The second one."}
    (tmp_path / "numbered.txt").write_text("e02 Two.\n1: One.\n")
    assert read_transcripts(tmp_path / "numbered.txt") == {2: "Two.", 1: "One."}
    folder = tmp_path / "texts"
    folder.mkdir()
    (folder / "e01.txt").write_text("Open the\nwindow.\n")
    (folder / "F2_e01.txt").write_text("Open the door.")
    assert read_transcripts(folder) == {1: "Open the window.", "F2_e01": "Open the door."}
    with pytest.raises(FacegenError, match="do not exist"):
        read_transcripts(tmp_path / "nope.txt")


def test_import_biwi_template_normalisation(raw_biwi, tmp_path):
    out = tmp_path / "B2"
    texts = tmp_path / "texts"
    texts.mkdir()
    (texts / "e01.txt").write_text("Open the window.")
    (texts / "F2_e02.txt").write_text("Only for F2.")
    import_biwi(raw_biwi, out, normalisation="template", subjects=["F2"], transcripts=texts, reporter=SILENT)
    assert (out / "text" / "F2_e01.txt").read_text().strip() == "Open the window."
    assert (out / "text" / "F2_e02.txt").read_text().strip() == "Only for F2."
    assert sorted(read_templates_pkl(out / "templates.pkl")) == ["F2"]
    template = read_templates_pkl(out / "templates.pkl")["F2"]
    v = np.load(out / "vertices_npy" / "F2_e01.npy").reshape(-1, 200, 3)
    # frame 0 of the raw sequence is the template itself (sin 0 = 0): identical after normalisation
    np.testing.assert_allclose(v[0], template, atol=1e-6)
    # later frames share the template's centre and scale: the static rows do not move at all
    np.testing.assert_allclose(v[2, 60:], template[60:], atol=1e-6)


def test_import_biwi_refuses_what_is_not_a_release(tmp_path):
    with pytest.raises(FacegenError, match="no rigid_scans/ folder"):
        import_biwi(tmp_path, tmp_path / "out")
    (tmp_path / "rigid_scans").mkdir()
    (tmp_path / "faces").mkdir()
    (tmp_path / "videos").mkdir()
    with pytest.raises(FacegenError, match="no subject templates"):
        import_biwi(tmp_path, tmp_path / "out")
    with pytest.raises(FacegenError, match="unknown normalisation"):
        import_biwi(tmp_path, tmp_path / "out", normalisation="mean")


def test_failed_import_leaves_no_folder(tmp_path):
    """Every take fails (frames of another topology): the new dataset folder is not left half-written."""
    raw = tmp_path / "raw"
    for d in ("rigid_scans", "faces/F2/e01", "videos"):
        (raw / d).mkdir(parents=True)
    face = grid_face()
    (raw / "rigid_scans" / "F2.obj").write_text(_obj_text(Mesh(face.vertices * 180, face.faces)))
    write_vl(np.zeros((7, 3), np.float32), raw / "faces" / "F2" / "e01" / "frame_001.vl")
    (raw / "videos" / "F2_e01.wav").write_bytes(b"RIFF")
    out = tmp_path / "dataset"
    with pytest.raises(FacegenError, match="no sequence of .* could be imported"):
        import_biwi(raw, out, reporter=SILENT)
    assert not out.exists()
    out.mkdir()
    (out / "mine.txt").write_text("kept")
    with pytest.raises(FacegenError):
        import_biwi(raw, out, reporter=SILENT)
    assert (out / "mine.txt").read_text() == "kept"  # a folder that had files keeps them
