"""Lip-sync metrics (facegen.lipsync) on the real procedural face and its rig."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import rig_weights

from facegen.errors import FacegenError
from facegen.face.rig import JAW_MAX_ANGLE, LIP_DROP_CM, Rig
from facegen.lipsync import (
    FaceGeometry,
    aperture,
    bilabial_midpoints,
    format_lipsync,
    lipsync_metrics,
    mouth_width,
    speech_mask,
    upper_face_response,
)
from facegen.synth.reference import rig_reference
from facegen.words import Word

FPS = 25.0
# espeak mnemonics (the rig's phone set): "_" pause, p a b i: m A: then a pause
PHONES = [("_", 0.0, 0.2), ("p", 0.2, 0.28), ("a", 0.28, 0.45), ("b", 0.45, 0.52), ("i:", 0.52, 0.7),
          ("m", 0.7, 0.78), ("A:", 0.78, 1.0), ("_", 1.0, 1.4)]
T = 35  # 1.4 s


@pytest.fixture(scope="module")
def face():
    from facegen.face.template import load_template

    return load_template()


@pytest.fixture(scope="module")
def rig(face):
    return Rig(face)


def test_rest_aperture_of_the_template(face, rig):
    geo = FaceGeometry.of(face)
    assert geo.cm == pytest.approx(rig.cm, rel=1e-9)  # 1 cm as the rig measures it
    assert len(geo.upper) == len(geo.lower) == 17  # the middle third of 47 margin pairs
    rest = aperture(face.vertices[None], face)
    assert rest.shape == (1,)
    assert rest[0] == pytest.approx(0.0978, abs=5e-4)  # cm: the slit of the neutral face is ~1 mm


def test_opening_the_jaw_raises_the_aperture_by_its_rotation(face, rig):
    ap = aperture(rig.pose(rig_weights(3, jaw_open=np.array([0.0, 0.5, 1.0]))), face)
    assert ap[0] == pytest.approx(aperture(face.vertices[None], face)[0], abs=1e-6)
    # the lower margin turns about the hinge by JAW_MAX_ANGLE and drops up to LIP_DROP_CM further on its
    # own; the upper one stays
    geo = FaceGeometry.of(face)
    hinge = face.vertices[face.regions["jaw_hinge"]].mean(0)
    y, z = (face.vertices[geo.lower, 1] - hinge[1]), (face.vertices[geo.lower, 2] - hinge[2])
    turn = float(np.mean(y - (y * np.cos(JAW_MAX_ANGLE) - z * np.sin(JAW_MAX_ANGLE)))) / rig.cm
    assert turn == pytest.approx(1.64, abs=0.01)
    assert ap[2] - ap[0] == pytest.approx(1.93, abs=0.01)  # "about 2 cm between the lips"
    assert 0.8 * LIP_DROP_CM < ap[2] - ap[0] - turn <= LIP_DROP_CM
    assert ap[0] < ap[1] < ap[2]


def test_a_hand_made_shift_of_the_lower_margin(face):
    geo = FaceGeometry.of(face)
    v = np.repeat(face.vertices[None], 2, 0).copy()
    v[1, face.regions["mouth_lower_margin"], 1] -= 0.3 * geo.cm
    ap = aperture(v, face)
    assert ap[1] - ap[0] == pytest.approx(0.3, abs=1e-5)


def test_mouth_width_reads_the_corners_and_how_rounding_and_spreading_move_them(face, rig):
    """Corner to corner across the face: the neutral face's mouth is ~4.9 cm wide; a hand-made shift of the
    rightmost margin vertex widens it by exactly that much; the rig's spread lips widen it, its rounded lips
    narrow it, the jaw alone leaves it (docs/real_faces.md: width read geometrically)."""
    geo = FaceGeometry.of(face)
    rest = mouth_width(face.vertices[None], face)
    assert rest.shape == (1,) and 4.5 < rest[0] < 5.3
    v = np.repeat(face.vertices[None], 2, 0).copy()
    right = geo.margins[np.argmax(face.vertices[geo.margins, 0])]
    v[1, right, 0] += 0.2 * geo.cm
    assert mouth_width(v, face)[1] - rest[0] == pytest.approx(0.2, abs=1e-6)
    wide, rounded, jaw = mouth_width(rig.pose(rig_weights(3, lip_wide=np.array([1.0, 0, 0]),
                                                          lip_round=np.array([0, 1.0, 0]),
                                                          jaw_open=np.array([0, 0, 1.0]))), face) - rest[0]
    assert wide > 0.15 and rounded < -0.3 and abs(jaw) < 0.05, (wide, rounded, jaw)


@pytest.fixture(scope="module")
def talking():
    """The rig's reference animation of PHONES (default face), its speech mask and bilabial midpoints."""
    return rig_reference(PHONES, [], T, FPS), speech_mask(PHONES, T, FPS), bilabial_midpoints(PHONES, FPS)


def test_an_animation_against_itself(face, talking):
    v, speech, mid = talking
    assert v.shape == (T, face.num_vertices, 3) and v.dtype == np.float32
    assert np.array_equal(rig_reference(PHONES, [], T, FPS, face), v)  # the default face, deterministic
    m = lipsync_metrics(v, v, face, FPS, speech=speech, bilabials=mid)
    assert m["aperture_r"] == pytest.approx(1.0)
    assert m["aperture_best_r"] == pytest.approx(1.0) and m["aperture_best_lag"] == 0
    assert m["aperture_median_ratio"] == pytest.approx(1.0) and m["aperture_p95_ratio"] == pytest.approx(1.0)
    assert m["open_frames"] > 5 and m["aperture_median_mm"] > 2.0
    assert m["crossed_lips_rate"] == 0.0


@pytest.mark.parametrize("shift", [2, -3])
def test_a_time_shifted_copy_is_found_at_its_lag(face, talking, shift):
    v, speech, _ = talking
    late = np.roll(v, shift, axis=0)  # late[t] = v[t - shift]
    m = lipsync_metrics(late, v, face, FPS, speech=speech)
    assert m["aperture_r"] < 0.8
    assert m["aperture_best_lag"] == shift
    assert m["aperture_best_r"] > 0.99  # only the wrapped frames differ
    assert m["aperture_best_r"] > m["aperture_r"] + 0.15


def test_crossed_lips_are_detected(face):
    geo = FaceGeometry.of(face)
    v = np.repeat(face.vertices[None], 20, 0).copy()
    v[5:10, face.regions["mouth_upper_margin"], 1] -= 0.25 * geo.cm  # 2.5 mm down: 1.5 mm below the lower
    m = lipsync_metrics(v, np.repeat(face.vertices[None], 20, 0), face, FPS)
    assert aperture(v[5:6], face)[0] == pytest.approx(-0.152, abs=1e-3)
    assert m["crossed_lips_rate"] == pytest.approx(5 / 20)


def test_the_rig_seals_the_lips_on_p_b_m_and_an_open_mouth_does_not(face, rig, talking):
    v, speech, mid = talking
    assert list(mid) == [6, 12, 18]  # midpoints of p (0.24 s), b (0.485 s), m (0.74 s)
    m = lipsync_metrics(v, v, face, FPS, speech=speech, bilabials=mid)
    assert m["bilabials"] == 3 and m["bilabial_closure_rate"] == 1.0
    assert m["bilabial_aperture_mm"] == pytest.approx(0.0, abs=1e-3)
    held_open = rig.pose(rig_weights(T, jaw_open=0.5))
    m = lipsync_metrics(held_open, v, face, FPS, speech=speech, bilabials=mid)
    assert m["bilabial_closure_rate"] == 0.0 and m["bilabial_aperture_mm"] > 5
    assert m["ref_bilabial_closure_rate"] == 1.0
    assert m["rest_aperture_mm"] > 5  # the held-open mouth is not at rest outside speech


def test_stillness(face, rig, talking):
    v, speech, _ = talking
    still = np.repeat(face.vertices[None], T, 0)
    m = lipsync_metrics(still, v, face, FPS, speech=speech)
    assert m["rest_motion_mm"] == 0.0
    assert m["rest_aperture_mm"] == pytest.approx(0.978, abs=5e-3)
    assert m["aperture_r"] is None  # a constant aperture has no correlation
    chewing = rig.pose(rig_weights(T, jaw_open=0.3 + 0.3 * np.sin(np.arange(T))))
    m = lipsync_metrics(chewing, v, face, FPS, speech=speech)
    assert m["rest_motion_mm"] > 1.0
    m = lipsync_metrics(still, v, face, FPS)  # without a speech mask: no stillness measures
    assert m["rest_motion_mm"] is None and m["rest_aperture_mm"] is None


def test_upper_face_motion(face, rig, talking):
    v, speech, _ = talking
    brows = rig.pose(rig_weights(T, brow_raise=np.where(speech, 0.6, 0.2)))
    m = lipsync_metrics(brows, v, face, FPS, speech=speech)
    assert m["upper_face_speech_mm"] > m["upper_face_rest_mm"] > 0.1
    assert m["upper_face_speech_ratio"] == pytest.approx(3.0, rel=1e-3)  # brow_raise is a linear offset
    low, high = rig.pose(rig_weights(T, brow_raise=0.2)), rig.pose(rig_weights(T, brow_raise=0.6))
    assert upper_face_response(low, high, face) == pytest.approx(3.0, rel=1e-3)


def test_emotional_words_raise_the_upper_face(face, rig):
    words = [("we", 0.2, 0.45), ("saw", 0.45, 0.7), ("it", 0.7, 1.0)]
    neutral = rig_reference(PHONES, words, T, FPS)
    emotional = rig_reference(PHONES, [words[0], Word("amazing", 0.45, 0.7), words[2]], T, FPS)
    assert np.array_equal(aperture(neutral, face), aperture(emotional, face))  # the words move no lip
    assert upper_face_response(neutral, emotional, face) == float("inf")  # the rig: no words, no motion
    fidgety = rig.pose(rig_weights(T, brow_raise=0.1))  # a neutral face that moves a little
    assert 1.5 < upper_face_response(fidgety, emotional, face) < 10
    assert upper_face_response(neutral, neutral, face) == pytest.approx(1.0)
    m = lipsync_metrics(neutral, neutral, face, FPS, emotional=emotional)
    assert m["upper_face_response"] > 1.5


def test_speech_mask_and_bilabials():
    # pauses are not speech; the pad reaches 0.1 s beyond each phone; a tiny phone marks its nearest frame
    mask = speech_mask([("_", 0.0, 0.5), ("a", 0.5, 0.6), ("SIL", 0.6, 1.0)], 30, 10.0, pad=0.1)
    assert list(np.nonzero(mask)[0]) == [4, 5, 6, 7]
    assert list(np.nonzero(speech_mask([("t", 0.803, 0.807)], 30, 10.0, pad=0.0))[0]) == [8]
    assert list(np.nonzero(speech_mask([Word("hello", 0.0, 0.5)], 20, FPS, pad=0.0))[0]) == list(range(13))
    # espeak mnemonics (stress marks allowed) or CMU phones, as the rig reads them
    phones = [("'b", 0.0, 0.1), ("m-", 0.1, 0.2), ("p", 0.2, 0.3), ("n", 0.3, 0.4), ("b", 0.6, 0.6)]
    assert list(bilabial_midpoints(phones, 10.0)) == [0, 2, 2]  # round() as the rig: 0.5 -> 0, 2.5 -> 2
    cmu = [("P", 0.0, 0.1), ("AA1", 0.1, 0.2), ("M", 0.3, 0.4), ("p", 0.4, 0.5), ("N", 0.5, 0.6)]
    assert list(bilabial_midpoints(cmu, 10.0, alphabet="cmu")) == [0, 4, 4]
    with pytest.raises(FacegenError, match="unknown phone alphabet 'ipa'"):
        bilabial_midpoints(cmu, 10.0, alphabet="ipa")


def test_the_reference_reads_cmu_phones_and_loudness(face, talking):
    v, _, mid = talking
    cmu = [("SIL", 0.0, 0.2), ("P", 0.2, 0.28), ("AE1", 0.28, 0.45), ("B", 0.45, 0.52), ("IY0", 0.52, 0.7),
           ("M", 0.7, 0.78), ("AA2", 0.78, 1.0), ("SIL", 1.0, 1.4)]
    assert list(bilabial_midpoints(cmu, FPS, alphabet="cmu")) == list(mid)
    ref = rig_reference(cmu, [], T, FPS, alphabet="cmu")
    m = lipsync_metrics(ref, v, face, FPS, speech=speech_mask(cmu, T, FPS), bilabials=mid)
    assert m["bilabial_closure_rate"] == 1.0 and m["aperture_r"] > 0.9  # the same motion, near enough
    # louder second half: the rig opens the mouth wider there (prosody)
    loud = np.where(np.arange(140) < 60, -30.0, -10.0).astype(np.float32)  # dB at 100 Hz
    louder = aperture(rig_reference(PHONES, [], T, FPS, loudness=loud), face) - aperture(v, face)
    assert louder[22:25].min() > 0.05 and louder[8:11].max() < 0  # AA (cm) wider, the first a narrower


def test_out_of_range_bilabials_are_dropped(face, talking):
    v, speech, _ = talking
    m = lipsync_metrics(v, v, face, FPS, speech=speech, bilabials=[6, T, T + 4, -1])
    assert m["bilabials"] == 1
    m = lipsync_metrics(v, v, face, FPS, speech=speech)
    assert m["bilabials"] == 0 and m["bilabial_closure_rate"] is None


def test_refusals(face, grid_mesh, talking):
    with pytest.raises(FacegenError, match="lacks the lip-sync regions mouth_upper_margin, "
                                           "mouth_lower_margin, left_eyeball, right_eyeball:") as err:
        aperture(grid_mesh.vertices[None], grid_mesh)
    assert "\n" not in str(err.value)
    v, speech, _ = talking
    with pytest.raises(FacegenError, match="34 frames but the reference 35"):
        lipsync_metrics(v[:-1], v, face, FPS)
    with pytest.raises(FacegenError, match="shape"):
        aperture(v[0], face)
    with pytest.raises(FacegenError, match="35 entries"):
        lipsync_metrics(v, v, face, FPS, speech=speech[:-1])


def test_format(face, talking):
    v, speech, mid = talking
    text = format_lipsync(lipsync_metrics(v, v, face, FPS, speech=speech, bilabials=mid))
    lines = {line.split("  ")[0]: line for line in text.splitlines()}
    assert "1.000" in lines["aperture r, lag 0"] and ">= 0.7" in lines["aperture r, lag 0"]
    assert "100%" in lines["bilabial closure (p/b/m midpoints)"]
    assert lines["upper face, emotional / neutral words"].split()[-3] == "-"  # not measured
    assert text.splitlines()[-1].startswith(f"{T} frames")
