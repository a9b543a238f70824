"""The procedural face (facegen.face): vertex count, determinism, normalisation, regions, slits, speakers,
the committed templates (package data)."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

from facegen.errors import FacegenError
from facegen.face import procedural as F
from facegen.face.anatomy import speaker_params
from facegen.face.mesh import read_mesh, surface_area
from facegen.face.procedural import NUM_VERTICES, make_face, speaker_face
from facegen.face.regions import FACE_REGIONS, RIG_REGIONS, file_stem, region_name
from facegen.face.template import TEMPLATES, load_template, write_templates

REPO = Path(__file__).resolve().parents[1]
BIWI = REPO.parent / "shared" / "biwi" / "BIWI.ply"


@pytest.fixture(scope="module")
def face():
    return make_face()


def _face_normals(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]).astype(np.float64)
    area = np.linalg.norm(n, axis=1)
    return n / np.maximum(area, 1e-30)[:, None], area / 2


def test_exact_vertex_count_and_valid_triangles(face):
    assert face.vertices.shape == (NUM_VERTICES, 3) == (23370, 3)
    assert face.vertices.dtype == np.float32 and face.faces.dtype == np.int32
    assert face.faces.shape[1] == 3 and face.faces.min() == 0 and face.faces.max() == NUM_VERTICES - 1
    assert np.isfinite(face.vertices).all()
    used = np.zeros(NUM_VERTICES, bool)
    used[face.faces.ravel()] = True
    assert used.all()  # no floating vertex
    _, area = _face_normals(face.vertices, face.faces)
    assert area.min() > 0  # no degenerate triangle


def test_deterministic(face):
    again = make_face()
    digest = [hashlib.sha256(f.vertices.tobytes()).hexdigest() for f in (face, again)]
    assert digest[0] == digest[1]
    assert np.array_equal(face.faces, again.faces)


def test_normalised_like_biwi(face):
    v = face.vertices.astype(np.float64)
    assert surface_area(v, face.faces) == pytest.approx(1.0, abs=1e-5)
    assert np.abs(v.mean(0)).max() < 1e-5
    extent = v.max(0) - v.min(0)
    assert extent[1] > extent[0] > extent[2] > 0.2  # taller than wide, wider than deep


def test_biwi_like_proportions(face):
    if not BIWI.is_file():
        pytest.skip("../shared/biwi is not present")
    biwi = read_mesh(BIWI).vertices
    ours = face.vertices
    ratio = (ours.max(0) - ours.min(0)) / (biwi.max(0) - biwi.min(0))
    assert np.all((ratio > 0.7) & (ratio < 1.3)), ratio


def test_normals_face_outwards(face):
    n, area = _face_normals(face.vertices, face.faces)
    skin = np.isin(face.faces, np.arange(F.GRID_ROWS * F.GRID_COLUMNS)).all(1)
    forward = (n[:, 2] > 0) & skin
    assert area[forward].sum() / area[skin].sum() > 0.85
    assert (n[:, 2] * area).sum() / area.sum() > 0.5


def test_anatomy_in_order(face):
    v, r = face.vertices, face.regions
    skin = np.arange(F.GRID_ROWS * F.GRID_COLUMNS)
    tip = skin[np.argmax(v[skin, 2])]
    mouth_y = v[r["mouth_upper_margin"], 1].mean()
    eye_y = v[r["left_upper_lid_margin"], 1].mean()
    assert abs(v[tip, 0]) < 1e-6 and mouth_y < v[tip, 1] < eye_y  # the nose tip leads, between eyes and mouth
    assert v[r["brows"], 1].mean() > eye_y > mouth_y > v[r["jaw"], 1].min()
    assert v[r["forehead"], 1].mean() > v[r["brows"], 1].mean()
    # eyes left (+x) and right (-x), eyeballs behind their lids
    assert v[r["left_eyeball"], 0].mean() > 0.05 > -0.05 > v[r["right_eyeball"], 0].mean()
    assert v[r["left_eyeball"], 2].max() < v[r["left_upper_lid_margin"], 2].max() + 0.01


def test_left_right_symmetric(face):
    W = F.GRID_COLUMNS
    grid = face.vertices[: F.GRID_ROWS * W].reshape(F.GRID_ROWS, W, 3)
    mirrored = grid[:, ::-1] * np.array([-1, 1, 1], np.float32)
    assert np.abs(grid - mirrored).max() < 1e-5


def test_regions(face):
    r = face.regions
    for name in ("lips", "jaw", "upper_face", "brows", "forehead", "upper_lids", "lower_lids", "cheeks",
                 "nose", "left_eyeball", "right_eyeball", "mouth_cavity"):
        assert len(r[name]) > 20, name
        assert r[name].min() >= 0 and r[name].max() < NUM_VERTICES
        assert len(np.unique(r[name])) == len(r[name])
    s = {k: set(v.tolist()) for k, v in r.items()}
    assert not s["lips"] & s["upper_face"]
    assert not s["upper_lids"] & s["lower_lids"]
    assert not s["brows"] & s["upper_lids"]
    assert s["brows"] <= s["upper_face"] and s["upper_lids"] <= s["upper_face"]
    assert s["lower_lids"] <= s["upper_face"]
    assert not (s["left_eyeball"] | s["right_eyeball"] | s["mouth_cavity"]) & (s["lips"] | s["upper_face"])
    # the jaw carries the lower lip, not the upper lip
    assert s["mouth_lower_margin"] <= s["jaw"] and not s["mouth_upper_margin"] & s["jaw"]


def test_mouth_slit_separates_the_lips(face):
    r, f = face.regions, face.faces
    up, lo = r["mouth_upper_margin"], r["mouth_lower_margin"]
    assert len(up) == len(lo) > 30
    assert set(up.tolist()) | set(lo.tolist()) <= set(r["lips"].tolist())  # lips contain the slit boundary
    # no triangle joins an upper and a lower lip vertex of the slit (ends excepted): the mouth can open
    has_up = np.isin(f, up[1:-1]).any(1)
    has_lo = np.isin(f, lo[1:-1]).any(1)
    assert not (has_up & has_lo).any()
    # the slit vertices are on the boundary (edges used by one triangle)
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), 1)
    uniq, counts = np.unique(edges, axis=0, return_counts=True)
    boundary = set(uniq[counts == 1].ravel().tolist())
    assert set(up[1:-1].tolist()) <= boundary and set(lo[1:-1].tolist()) <= boundary
    v = face.vertices
    gap = v[up, 1] - v[lo, 1]
    assert gap.min() >= -1e-6 and gap.max() < 0.01  # lips closed or barely parted at rest


def test_eyes_open_at_rest_with_lids_that_can_close(face):
    v, r, f = face.vertices, face.regions, face.faces
    for side in ("left", "right"):
        up, lo = r[f"{side}_upper_lid_margin"], r[f"{side}_lower_lid_margin"]
        assert len(up) == len(lo) > 10
        gap = v[up, 1] - v[lo, 1]
        assert gap.max() > 0.02  # an open eye (about 8 mm of 23 cm)
        assert gap[0] < 0.2 * gap.max() and gap[-1] < 0.2 * gap.max()  # almond: corners nearly closed
        assert not (np.isin(f, up[1:-1]).any(1) & np.isin(f, lo[1:-1]).any(1)).any()


def test_speaker_faces_differ_but_keep_topology(face):
    a, b = speaker_face(0), speaker_face(1)
    assert a.vertices.shape == b.vertices.shape == face.vertices.shape
    assert np.array_equal(a.faces, face.faces) and np.array_equal(b.faces, face.faces)
    assert a.fingerprint() == face.fingerprint()
    assert set(a.regions) == set(face.regions)
    assert all(np.array_equal(a.regions[k], face.regions[k]) for k in face.regions)
    assert np.abs(a.vertices - b.vertices).mean() > 2e-3
    assert np.abs(a.vertices - face.vertices).mean() > 2e-3
    assert surface_area(b.vertices, b.faces) == pytest.approx(1.0, abs=1e-5)
    assert np.array_equal(speaker_face(1).vertices, b.vertices)
    assert speaker_params(3) == speaker_params(3) != speaker_params(4)


def test_speaker_index_must_not_be_negative():
    with pytest.raises(FacegenError, match="negative"):
        speaker_face(-1)


def test_region_names_are_those_of_the_face(face):
    assert sorted(face.regions) == list(FACE_REGIONS)
    assert set(RIG_REGIONS) < set(FACE_REGIONS)
    assert [file_stem("lips"), file_stem("upper_face"), file_stem("jaw")] == ["lve", "fdd", "jaw"]
    assert [region_name("lve"), region_name("fdd"), region_name("jaw")] == ["lips", "upper_face", "jaw"]


def test_committed_templates_match_the_code(face):
    assert TEMPLATES == REPO / "facegen" / "face" / "templates"  # inside the package: shipped as package data
    committed = load_template()
    assert committed.vertices.shape == face.vertices.shape
    assert np.allclose(committed.vertices, face.vertices, atol=1e-6)
    assert np.array_equal(committed.faces, face.faces)
    assert set(committed.regions) == set(face.regions)
    for name in face.regions:
        assert np.array_equal(committed.regions[name], face.regions[name]), name
    assert (TEMPLATES / "face.ply").stat().st_size < 1_000_000


def test_write_templates_round_trip(tmp_path, face):
    written = write_templates(tmp_path)
    assert {p.name for p in written} >= {"face.ply", "lve.txt", "fdd.txt", "jaw.txt", "brows.txt"}
    header = (tmp_path / "face.ply").read_bytes()[:400]
    assert b"binary_little_endian" in header and b"property float x" in header
    back = load_template(tmp_path)
    assert np.array_equal(back.vertices, face.vertices)
    assert np.array_equal(back.regions["lips"], face.regions["lips"])
    assert np.array_equal(back.regions["mouth_upper_margin"], face.regions["mouth_upper_margin"])  # ordered
    assert not list(tmp_path.glob(".*"))  # no temporary files left behind
