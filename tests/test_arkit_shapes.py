"""The 52 ARKit blend shapes on facegen's procedural face: names, sizes in mm, regions, sides, cache."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from facegen.arkit import shapes as arkit
from facegen.arkit.deformers import JAW_OPEN_SCALE
from facegen.arkit.names import ARKIT_NAMES
from facegen.errors import FacegenError
from facegen.face.mesh import Mesh
from facegen.face.procedural import make_face, speaker_face
from facegen.face.regions import ARKIT_REGIONS, RIG_REGIONS
from facegen.face.rig import CHANNELS, LIP_DROP_CM, Rig


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """A fresh disk cache (XDG_CACHE_HOME) for this module's builds; the in-process memo emptied."""
    with pytest.MonkeyPatch.context() as mp:
        folder = tmp_path_factory.mktemp("xdg")
        mp.setenv("XDG_CACHE_HOME", str(folder))
        arkit._MEMO.clear()
        yield folder
        arkit._MEMO.clear()


@pytest.fixture(scope="module")
def face():
    return make_face()


@pytest.fixture(scope="module")
def shapes(cache, face):
    return arkit.arkit_shapes(face)


@pytest.fixture(scope="module")
def rig(face):
    return Rig(face)


def _pose(rig: Rig, **channels: float) -> np.ndarray:
    w = np.zeros((1, len(CHANNELS)), np.float32)
    for name, value in channels.items():
        w[0, CHANNELS.index(name)] = value
    return rig.pose(w)[0]


def _mirror(face: Mesh) -> np.ndarray:
    """Index of each vertex's mirror image (x -> -x) on the symmetric canonical face."""
    v = face.vertices.astype(np.float64)
    dist, idx = cKDTree(v).query(v * [-1, 1, 1])
    assert dist.max() < 1e-5
    return idx


def test_52_names_in_order_real_finite_offsets(shapes, face):
    assert shapes.names == ARKIT_NAMES and len(shapes.names) == 52
    assert shapes.offsets.shape == (52, face.num_vertices, 3) and shapes.offsets.dtype == np.float32
    assert np.isfinite(shapes.offsets).all()
    assert shapes.mm == pytest.approx(Rig(face).cm / 10)
    largest = np.linalg.norm(shapes.offsets, axis=2).max(1) / shapes.mm
    assert largest.min() > 1.5, dict(zip(ARKIT_NAMES, largest.round(2)))  # every shape moves >1.5 mm
    assert largest[ARKIT_NAMES.index("jawOpen")] == largest.max() < 80.0  # a mouth opened as wide as it goes
    assert np.delete(largest, ARKIT_NAMES.index("jawOpen")).max() < 40.0
    assert not shapes.offsets.flags.writeable  # the cached arrays cannot be changed by a caller


def test_the_hidden_offsets_are_the_jaws_arc_off_jaw_opens_line(shapes, face, rig):
    """Shapes.hidden: the bulge of the rig's jaw turn off the straight line from closed to fully turned, at
    half way (up to about 1 mm at the chin, nothing off the jaw)."""
    assert shapes.hidden.shape == (1, face.num_vertices, 3) and shapes.hidden.dtype == np.float32
    assert not shapes.hidden.flags.writeable
    arc = shapes.hidden[0]
    half = rig.jaw_turn(0.5) - 0.5 * (rig.jaw_turn(0.0) + rig.jaw_turn(1.0))
    assert np.abs(arc - half).max() < 1e-6
    size = np.linalg.norm(arc, axis=1) / shapes.mm
    assert 0.5 < size.max() < 1.5
    assert size[rig.fields["jaw"] < 1e-4].max() < 1e-6  # only what the jaw turns
    turn = shapes.offset("jawOpen")  # 0.1 of the way along jawOpen's line the jaw moves far more than that
    assert size.max() < 0.1 * np.linalg.norm(turn, axis=1).max() / shapes.mm


def test_jaw_open_drops_the_chin_and_parts_the_lips_leaving_the_brows(shapes, face):
    r, v, mm = face.regions, face.vertices, shapes.mm
    jaw_open = shapes.offset("jawOpen")
    mu, ml = r["mouth_upper_margin"], r["mouth_lower_margin"]
    c_up, c_lo = mu[len(mu) // 2], ml[len(ml) // 2]
    gap = (jaw_open[c_up, 1] - jaw_open[c_lo, 1]) / mm
    assert 30.0 < gap < 52.0  # ~4 cm between the lips: as wide as a mouth opens (JAW_OPEN_SCALE x the rig's)
    jaw = r["jaw"][(np.abs(v[r["jaw"], 0]) < 1e-4) & (v[r["jaw"], 1] < v[c_lo, 1] - 25 * mm)]
    chin = jaw[np.argmax(v[jaw, 2])]  # the most prominent point of the chin
    assert -60.0 < jaw_open[chin, 1] / mm < -20.0
    assert np.abs(jaw_open[r["brows"]]).max() < 1e-7 and np.abs(jaw_open[r["forehead"]]).max() < 1e-7


def test_pucker_closes_the_lips_and_pushes_them_forward_funnel_parts_them(shapes, face):
    """ARKit's mouthPucker is a kiss (closed lips contracted and pushed forward), mouthFunnel the lips forward
    and apart: the centres of the lip margins stay within 1 mm of each other at pucker 1 (the rig's rounding
    alone parts them ~4 mm), move forward at least 2 mm, and part by more than 3 mm at funnel 1."""
    r, mm = face.regions, shapes.mm
    mu, ml = r["mouth_upper_margin"], r["mouth_lower_margin"]
    c_up, c_lo = mu[len(mu) // 2], ml[len(ml) // 2]

    def gap(name: str) -> float:  # how far the shape parts the lip centres (mm)
        offset = shapes.offset(name)
        return float(offset[c_up, 1] - offset[c_lo, 1]) / mm

    pucker = shapes.offset("mouthPucker")
    assert abs(gap("mouthPucker")) < 1.0, gap("mouthPucker")
    assert min(pucker[c_up, 2], pucker[c_lo, 2]) / mm > 2.0
    assert gap("mouthFunnel") > 3.0


def test_stretch_draws_the_corners_out_further_than_speech_does(shapes, face, rig):
    """mouthStretch keeps ARKit's meaning now that the rig's speech spreading is calibrated on real speakers
    (rig.WIDE_SPREAD): at weight 1 the mouth is 0.9-1.4 cm wider, where the rig's lip_wide widens it 0.1-0.4
    cm. Speech's spreading is a part of the full stretch (rig.STRETCH_SPREAD), all of its offsets, so a spread
    vowel solves to a small mouthStretch alone. mouthPucker is the rig's rounding with the lips shut, 0.3-0.8
    cm narrower."""
    from facegen.face.rig import STRETCH_SPREAD, WIDE_SPREAD
    from facegen.lipsync import mouth_width

    v = face.vertices
    rest = mouth_width(v[None], face)[0]

    def width(offsets: np.ndarray) -> float:
        return float(mouth_width((v + offsets)[None], face)[0] - rest)

    stretch = shapes.offset("mouthStretchLeft") + shapes.offset("mouthStretchRight")
    spread = _pose(rig, lip_wide=1.0) - v
    assert 0.9 <= width(stretch) <= 1.4 and 0.1 <= width(spread) <= 0.4
    assert -0.8 <= width(shapes.offset("mouthPucker")) <= -0.3
    assert np.abs(shapes.offset("mouthPucker") - (_pose(rig, lip_round=1.0, lip_close=1.0) - v)).max() < 1e-6
    assert np.abs(stretch - STRETCH_SPREAD / WIDE_SPREAD * spread).max() < 1e-4 * shapes.mm  # 0.1 um


def test_blink_left_closes_the_left_eye_only(shapes, face):
    r, v = face.regions, face.vertices
    blink = v + shapes.offset("eyeBlinkLeft")
    up, lo = r["left_upper_lid_margin"], r["left_lower_lid_margin"]
    assert v[up, 0].mean() > 0  # left = +x
    rest_gap = np.linalg.norm(v[up] - v[lo], axis=1).max()
    assert rest_gap > 5 * shapes.mm
    assert np.linalg.norm(blink[up] - blink[lo], axis=1).max() < 0.05 * rest_gap
    other = np.concatenate([r["right_upper_lid_margin"], r["right_lower_lid_margin"], r["right_eyeball"]])
    assert np.abs(shapes.offset("eyeBlinkLeft")[other]).max() < 1e-4 * shapes.mm


def test_brows(shapes, face):
    v, mm = face.vertices, shapes.mm
    brows = face.regions["brows"]
    x = v[brows, 0] / (10 * mm)  # cm
    inner, outer_left, outer_right = brows[np.abs(x) < 1.2], brows[x > 4.2], brows[x < -4.2]
    up = shapes.offset("browInnerUp")[:, 1] / mm
    outer_both = np.concatenate([outer_left, outer_right])
    assert up[inner].mean() > 4.0 and up[inner].mean() > 3 * up[outer_both].mean()
    outer = shapes.offset("browOuterUpLeft")[:, 1] / mm
    assert outer[outer_left].mean() > 4.0 and outer[inner].mean() < 1.0
    assert np.abs(outer[outer_right]).max() < 0.01
    assert 4.0 < shapes.offset("browInnerUp")[brows, 1].max() / mm < 8.0  # ~6 mm
    down = shapes.offset("browDownRight")[:, 1] / mm
    assert down[brows[(x < -0.5) & (x > -3)]].mean() < -2.0 and np.abs(down[outer_left]).max() < 0.01


def test_smile_left_raises_the_left_corner(shapes, face):
    mu = face.regions["mouth_upper_margin"]
    left, right = (mu[-1], mu[0]) if face.vertices[mu[-1], 0] > 0 else (mu[0], mu[-1])
    smile = shapes.offset("mouthSmileLeft") / shapes.mm
    assert smile[left, 1] > 4.0 and smile[left, 0] > 1.0  # up and out
    assert abs(smile[right]).max() < 0.01
    frown = shapes.offset("mouthFrownRight") / shapes.mm
    assert frown[right, 1] < -3.0 and abs(frown[left]).max() < 0.01
    mouth_left = shapes.offset("mouthLeft") / shapes.mm
    assert mouth_left[mu, 0].min() > 5.0  # the whole mouth to the character's left


def test_left_and_right_mirror_each_other(shapes, face):
    mirror = _mirror(face)
    # the rig's jaw weights inside the mouth cavity are not mirror-symmetric (its grid's triangles are not):
    # compare the rest of the face
    seen = np.setdiff1d(np.arange(face.num_vertices), face.regions["mouth_cavity"])
    pairs = [n for n in ARKIT_NAMES if n.endswith("Left")]
    assert len(pairs) == 20  # 18 Left/Right pairs, mouthLeft/mouthRight, jawLeft/jawRight
    tol = 0.02 * shapes.mm
    for name in pairs:
        left, right = shapes.offset(name), shapes.offset(name[:-4] + "Right")
        assert np.abs(left[mirror] * [-1, 1, 1] - right)[seen].max() < tol, name
    for name in ("jawOpen", "mouthFunnel", "mouthPucker", "browInnerUp", "cheekPuff", "mouthRollUpper",
                 "mouthShrugLower", "tongueOut", "jawForward"):
        off = shapes.offset(name)
        assert np.abs(off[mirror] * [-1, 1, 1] - off)[seen].max() < tol, name


def test_left_plus_right_is_the_rig_motion(shapes, face, rig):
    v = face.vertices
    pairs = {"eyeBlink": {"blink": 1.0}, "eyeWide": {"lid_widen": 1.0}, "browDown": {"brow_frown": 1.0},
             "mouthUpperUp": {"upper_lip_raise": 1.0}}
    for name, channels in pairs.items():
        both = shapes.offset(name + "Left") + shapes.offset(name + "Right")
        assert np.abs(both - (_pose(rig, **channels) - v)).max() < 1e-6, name
    brows = sum(shapes.offset(name) for name in ("browInnerUp", "browOuterUpLeft", "browOuterUpRight"))
    assert np.abs(brows - (_pose(rig, brow_raise=1.0) - v)).max() < 1e-6
    # jawOpen is the jaw's turn alone, on its scale (the rig's jaw_open also drops the lower lip on its own:
    # that is mouthLowerDown's); mouthClose shuts the lips against that jaw
    turn = rig.jaw_turn(1.0)
    close = _pose(rig, jaw_open=1.0, lip_close=1.0) - turn
    assert np.abs(shapes.offset("mouthClose") - JAW_OPEN_SCALE * close).max() < 1e-6
    assert np.abs(shapes.offset("jawOpen") - JAW_OPEN_SCALE * (turn - v)).max() < 1e-6
    # the rest is the lower lip's own drop, LIP_DROP_CM straight down: mouthLowerDown's deformation (0.55 cm)
    lip = _pose(rig, jaw_open=1.0) - turn
    lower_down = shapes.offset("mouthLowerDownLeft") + shapes.offset("mouthLowerDownRight")
    assert np.abs(lip - LIP_DROP_CM / 0.55 * lower_down).max() < 0.01 * shapes.mm
    assert np.all(lip[face.regions["mouth_lower_margin"], 1] < 0)


def test_eye_look_turns_the_eyeballs(shapes, face, rig):
    r, v, mm = face.regions, face.vertices, shapes.mm
    left, right = r["left_eyeball"], r["right_eyeball"]
    pole = left[np.argmax(v[left, 2])]
    assert shapes.offset("eyeLookInLeft")[pole, 0] < -3 * mm  # towards the nose
    assert shapes.offset("eyeLookOutLeft")[pole, 0] > 3 * mm
    assert shapes.offset("eyeLookUpLeft")[pole, 1] > 3 * mm
    assert shapes.offset("eyeLookDownLeft")[pole, 1] < -3 * mm
    assert np.abs(shapes.offset("eyeLookInLeft")[right]).max() < 1e-7
    # the eyeball's points slide over its ellipsoid
    centre, axes = rig.eye_centres[0], rig.eye_axes[0]
    turned = v[left] + shapes.offset("eyeLookUpLeft")[left]
    assert np.abs(np.linalg.norm((turned - centre) / axes, axis=1) - 1).max() < 0.01
    # up / down: the upper lid follows the gaze
    up = r["left_upper_lid_margin"]
    down_lid = shapes.offset("eyeLookDownLeft")[up, 1].mean()
    up_lid = shapes.offset("eyeLookUpLeft")[up, 1].mean()
    assert down_lid < -1 * mm < 0 < up_lid


def test_tongue_out_on_a_face_without_tongue_pushes_the_lower_lip_not_the_jaw(shapes, face):
    mu, ml = face.regions["mouth_upper_margin"], face.regions["mouth_lower_margin"]
    c_up, c_lo = mu[len(mu) // 2], ml[len(ml) // 2]
    tongue = shapes.offset("tongueOut") / shapes.mm
    assert 1.0 < tongue[c_up, 1] - tongue[c_lo, 1] < 5.0  # the lower lip down a little, the upper one stays
    assert tongue[c_lo, 2] > 3.0  # and pushed forward
    jaw = shapes.offset("jawOpen")
    cosine = float((tongue * jaw).sum() / np.linalg.norm(tongue) / np.linalg.norm(jaw))
    assert abs(cosine) < 0.3  # not a second jawOpen: the fit must not trade one for the other


def test_missing_regions_are_named(face):
    assert set(RIG_REGIONS) < set(ARKIT_REGIONS)  # checked before the (lazily imported) rig is built
    regions = {k: v for k, v in face.regions.items() if k not in ("nose", "jaw")}
    with pytest.raises(FacegenError, match="jaw, nose") as err:
        arkit.arkit_shapes(Mesh(face.vertices, face.faces, regions))
    assert "\n" not in str(err.value)


def test_cache_in_process_and_on_disk(shapes, face, cache):
    assert arkit.arkit_shapes(make_face()) is shapes  # memoised by the mesh's digest
    files = sorted((cache / "facegen" / "arkit").glob("shapes-*.safetensors"))
    assert [f.name for f in files] == [f"shapes-{arkit.mesh_digest(face)}.safetensors"]
    arkit._MEMO.clear()
    again = arkit.arkit_shapes(face)  # read from disk
    assert again is not shapes and again.names == shapes.names and again.mm == shapes.mm
    assert np.array_equal(again.offsets, shapes.offsets) and np.array_equal(again.hidden, shapes.hidden)
    files[0].write_bytes(b"not a safetensors file")  # a damaged cache file is rebuilt
    arkit._MEMO.clear()
    rebuilt = arkit.arkit_shapes(face)
    assert np.array_equal(rebuilt.offsets, shapes.offsets)
    assert arkit._read(files[0], face.num_vertices) is not None  # and rewritten


def test_speaker_faces_get_their_own_shapes(shapes, cache):
    other = arkit.arkit_shapes(speaker_face(3))
    assert other.names == ARKIT_NAMES and np.isfinite(other.offsets).all()
    assert not np.array_equal(other.offsets, shapes.offsets)
    assert 0.8 < other.mm / shapes.mm < 1.25
    gap = other.offset("jawOpen")
    assert np.linalg.norm(gap, axis=1).max() / other.mm > 10.0
