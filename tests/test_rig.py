"""The motion rig on the procedural face, the viseme / expression / blink curves and the lexicon."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from facegen.errors import FacegenError
from facegen.face.mesh import Mesh
from facegen.face.procedural import make_face, speaker_face
from facegen.face.rig import CHANNELS, EXPRESSIONS, LOWER_CHANNELS, UPPER_CHANNELS, Rig
from facegen.phonetics import phone_visemes
from facegen.synth.curves import (
    BILABIAL_JAW,
    SpeakerStyle,
    blink_curves,
    expression_curves,
    motion_curves,
    viseme_curves,
)
from facegen.synth.lexicon import (
    HELD_OUT_LEXICON,
    LEXICON,
    TRAIN_LEXICON,
    emotional_words,
    lookup,
    normalise_word,
)

FPS = 25.0


@dataclass
class Ph:
    text: str
    start: float
    end: float
    word: int = 0


@dataclass
class Wd:
    text: str
    start: float
    end: float


@pytest.fixture(scope="module")
def face():
    return make_face()


@pytest.fixture(scope="module")
def rig(face):
    return Rig(face)


def _weights(**channels: float) -> np.ndarray:
    w = np.zeros((1, len(CHANNELS)), np.float32)
    for name, value in channels.items():
        w[0, CHANNELS.index(name)] = value
    return w


def _pose(rig: Rig, **channels: float) -> np.ndarray:
    return rig.pose(_weights(**channels))[0]


def _centre(idx: np.ndarray) -> int:
    return int(idx[len(idx) // 2])


# --------------------------------------------------------------------------------------------- the rig
def test_rest_pose_is_the_template(rig, face):
    assert rig.channels == CHANNELS and len(CHANNELS) == len(set(CHANNELS))
    rest = rig.pose(np.zeros((3, len(CHANNELS)), np.float32))
    assert rest.shape == (3, face.num_vertices, 3) and rest.dtype == np.float32
    assert np.abs(rest - face.vertices[None]).max() < 1e-6
    weights = np.random.default_rng(0).random((125, len(CHANNELS))).astype(np.float32)
    out = rig.pose(weights)
    assert out.shape == (125, face.num_vertices, 3) and np.isfinite(out).all()


def test_jaw_open_lowers_the_chin_and_parts_the_lips(rig, face):
    r, v = face.regions, face.vertices
    up, lo = _centre(r["mouth_upper_margin"]), _centre(r["mouth_lower_margin"])
    cm = rig.cm
    jaw = r["jaw"][(np.abs(v[r["jaw"], 0]) < 1e-4) & (v[r["jaw"], 1] < v[lo, 1] - 2.5 * cm)]
    chin = int(jaw[np.argmax(v[jaw, 2])])  # the most prominent point of the chin
    opened = _pose(rig, jaw_open=0.6)
    rest_gap = v[up, 1] - v[lo, 1]
    gap = opened[up, 1] - opened[lo, 1]
    assert opened[chin, 1] < v[chin, 1] - 0.8 * cm  # chin down by more than 8 mm
    assert gap > rest_gap + 0.8 * cm  # lips apart
    assert abs(opened[up, 1] - v[up, 1]) < 0.1 * abs(opened[lo, 1] - v[lo, 1])  # the upper lip stays
    forehead = r["forehead"]
    assert np.abs(opened[forehead] - v[forehead]).max() < 1e-7


def test_lip_close_seals_the_lips_even_with_the_jaw_open(rig, face):
    up, lo = face.regions["mouth_upper_margin"], face.regions["mouth_lower_margin"]
    open_only = _pose(rig, jaw_open=0.3)
    sealed = _pose(rig, jaw_open=0.3, lip_close=1.0)
    assert np.linalg.norm(open_only[up] - open_only[lo], axis=1).max() > 0.5 * rig.cm
    assert np.linalg.norm(sealed[up] - sealed[lo], axis=1).max() < 1e-5
    half = _pose(rig, jaw_open=0.3, lip_close=0.5)
    g_half = np.linalg.norm(half[up] - half[lo], axis=1).max()
    assert 0.3 * rig.cm < g_half < np.linalg.norm(open_only[up] - open_only[lo], axis=1).max()


def test_blink_closes_both_eyes_and_widen_opens_them(rig, face):
    v, r = face.vertices, face.regions
    blink = _pose(rig, blink=1.0)
    wide = _pose(rig, lid_widen=1.0)
    for side in ("left", "right"):
        up, lo = r[f"{side}_upper_lid_margin"], r[f"{side}_lower_lid_margin"]
        rest_gap = np.linalg.norm(v[up] - v[lo], axis=1)
        closed_gap = np.linalg.norm(blink[up] - blink[lo], axis=1)
        assert rest_gap.max() > 0.6 * rig.cm
        assert closed_gap.max() < 0.05 * rest_gap.max()
        c = len(up) // 2
        assert blink[up[c], 1] < v[up[c], 1] - 0.4 * rig.cm  # the upper lid comes down
        assert wide[up[c], 1] - wide[lo[c], 1] > v[up[c], 1] - v[lo[c], 1] + 0.15 * rig.cm
    # the lids stay outside the eyeballs
    for side in ("left", "right"):
        eye = r[f"{side}_eyeball"]
        centre = v[eye].mean(0)
        assert np.linalg.norm(blink[r["upper_lids"]] - centre, axis=1).min() > 0.3 * rig.cm


def test_brow_raise_moves_brows_up_and_leaves_the_lips(rig, face):
    v, r = face.vertices, face.regions
    raised = _pose(rig, brow_raise=1.0)
    dy = raised[r["brows"], 1] - v[r["brows"], 1]
    assert dy.min() > 0.3 * rig.cm and dy.mean() > 0.5 * rig.cm
    assert np.abs(raised[r["lips"]] - v[r["lips"]]).max() < 1e-7
    assert np.abs(raised[r["jaw"]] - v[r["jaw"]]).max() < 1e-7
    assert np.abs(raised[r["forehead"], 2] - v[r["forehead"], 2]).max() > 0.02 * rig.cm  # wrinkles


def test_frown_and_smile(rig, face):
    v, r = face.vertices, face.regions
    frown = _pose(rig, brow_frown=1.0)
    brows = r["brows"]
    assert (frown[brows, 1] - v[brows, 1]).mean() < -0.2 * rig.cm
    assert (np.abs(frown[brows, 0]) - np.abs(v[brows, 0])).mean() < -0.1 * rig.cm  # drawn together
    smile = _pose(rig, cheek_raise=1.0)
    corners = [r["mouth_upper_margin"][0], r["mouth_upper_margin"][-1]]
    assert (smile[corners, 1] - v[corners, 1]).min() > 0.3 * rig.cm
    assert np.abs(smile[corners, 0]).min() > np.abs(v[corners, 0]).min()


def test_mouth_channels_leave_the_upper_face(rig, face):
    r = face.regions
    for name in LOWER_CHANNELS:
        posed = _pose(rig, **{name: 1.0})
        assert np.abs(posed[r["upper_face"]] - face.vertices[r["upper_face"]]).max() < 1e-7, name
        assert np.abs(posed[r["lips"]] - face.vertices[r["lips"]]).max() > 0.1 * rig.cm, name


def test_rig_works_on_speaker_faces():
    face = speaker_face(5)
    rig = Rig(face)
    posed = rig.pose(np.concatenate([_weights(blink=1.0), _weights(jaw_open=0.5)]))
    r = face.regions
    up, lo = r["left_upper_lid_margin"], r["left_lower_lid_margin"]
    assert np.linalg.norm(posed[0, up] - posed[0, lo], axis=1).max() < 0.05 * rig.cm
    mu, ml = _centre(r["mouth_upper_margin"]), _centre(r["mouth_lower_margin"])
    assert posed[1, mu, 1] - posed[1, ml, 1] > 0.7 * rig.cm
    assert 0.8 < rig.cm / Rig(make_face()).cm < 1.25


def test_rig_refuses_meshes_without_its_regions(grid_mesh, rig):
    with pytest.raises(FacegenError, match="rig regions"):
        Rig(Mesh(grid_mesh.vertices, grid_mesh.faces, {}))
    with pytest.raises(FacegenError, match="shape"):
        rig.pose(np.zeros((4, 3), np.float32))


# ------------------------------------------------------------------------------------------- visemes
def test_phoneme_to_viseme_mapping():
    assert phone_visemes("p") == phone_visemes("b") == phone_visemes("m") == ("PBM",)
    assert phone_visemes("f") == ("FV",) and phone_visemes("v") == ("FV",)
    assert phone_visemes("tS") == phone_visemes("dZ") == phone_visemes("S") == ("SH",)
    assert phone_visemes("'aI") == ("AA", "IH") and phone_visemes(",oU") == ("OW",)
    assert phone_visemes("'u:") == ("UW",) and phone_visemes("@L") == ("AH", "L")
    assert phone_visemes("3:") == ("ER",)
    # an espeak phoneme looks like its CMU phones (one table: facegen.phonetics), e.g. "a" in "cat" like AE
    assert phone_visemes("'a") == phone_visemes("AE1", "cmu") == ("AE",) and phone_visemes("V") == ("AH",)
    assert (phone_visemes("_:") == ("rest",) and phone_visemes("qq") == ("rest",)
            and phone_visemes("") == ("rest",))
    english = ["p", "b", "m", "f", "v", "T", "D", "s", "z", "S", "Z", "tS", "dZ", "t", "d", "n", "l", "r",
               "k", "g", "N", "h", "w", "j", "a", "A:", "e", "E", "@", "3:", "i:", "I", "O:", "U", "u:", "aI",
               "aU", "eI", "oU", "OI", "0", "V", "@2", "@L", "t#", "a#", "i@3", "O2", "aI@", "e@", "i@", "U@",
               "I2", "i"]
    assert all(phone_visemes(p) != ("rest",) for p in english)


def _phones(*items: tuple[str, float, float]) -> list[Ph]:
    return [Ph(t, s, e) for t, s, e in items]


def test_lips_close_on_bilabials_and_the_jaw_opens_for_vowels():
    phones = _phones(("h", 0.20, 0.28), ("'a", 0.28, 0.48), ("p", 0.48, 0.60), ("'a", 0.60, 0.84))
    curves = viseme_curves(phones, 30, FPS)
    assert curves.shape == (30, len(LOWER_CHANNELS)) and curves.dtype == np.float32
    jaw, close = curves[:, 0], curves[:, LOWER_CHANNELS.index("lip_close")]
    t = np.arange(30) / FPS
    in_p = (t >= 0.48) & (t <= 0.60)
    assert in_p.sum() >= 2
    mid_vowels = [int(0.38 * FPS), int(0.72 * FPS)]
    assert jaw[mid_vowels].min() > 0.3 and close[mid_vowels].max() < 0.3
    # the lips shut, the jaw part open as the vowels around it hold it (real speakers: about half)
    assert close[in_p].min() > 0.99 and jaw[in_p].max() <= BILABIAL_JAW + 1e-6
    assert 0.2 * jaw[mid_vowels].mean() < jaw[in_p].min() and jaw[in_p].max() < 0.7 * jaw[mid_vowels].mean()
    # silence before speech: near rest, the lips parting ahead of it (coarticulation 0.117 s, calibrated on
    # real faces: people's lips lead their sound)
    assert np.abs(curves[:2]).max() < 0.15 and jaw[0] < jaw[1] < 0.5 * jaw[mid_vowels].min()
    assert np.abs(curves[-3:]).max() < 0.01  # and after it
    assert np.all(np.diff(jaw[:7]) > 0)  # the jaw starts opening before the vowel (anticipation)


def test_a_bilabial_shorter_than_a_frame_still_closes_the_lips():
    phones = _phones(("'a", 0.10, 0.305), ("m", 0.305, 0.33), ("'a", 0.33, 0.55))
    close = viseme_curves(phones, 16, FPS)[:, LOWER_CHANNELS.index("lip_close")]
    assert close.max() > 0.99 and int(np.argmax(close)) == round(0.3175 * FPS)


def test_rounding_and_spreading_and_coarticulation():
    k_round, k_wide = LOWER_CHANNELS.index("lip_round"), LOWER_CHANNELS.index("lip_wide")
    oo = viseme_curves(_phones(("w", 0.1, 0.2), ("'u:", 0.2, 0.45)), 15, FPS)
    ee = viseme_curves(_phones(("s", 0.1, 0.2), ("'i:", 0.2, 0.45)), 15, FPS)
    k = int(0.32 * FPS)
    assert oo[k, k_round] > 0.6 and oo[k, k_wide] < 0.2
    assert ee[k, k_wide] > 0.5 and ee[k, k_round] < 0.2
    # anticipation: the rounding of "oo" starts before the vowel (during the preceding "t")
    too = viseme_curves(_phones(("t", 0.10, 0.22), ("'u:", 0.22, 0.45)), 15, FPS)
    tee = viseme_curves(_phones(("t", 0.10, 0.22), ("'i:", 0.22, 0.45)), 15, FPS)
    assert too[int(0.16 * FPS), k_round] > tee[int(0.16 * FPS), k_round] + 0.15


def test_speaker_style_changes_amplitude():
    phones = _phones(("'a", 0.1, 0.5))
    small = viseme_curves(phones, 15, FPS, SpeakerStyle(jaw_gain=0.8, articulation=0.8))
    large = viseme_curves(phones, 15, FPS, SpeakerStyle(jaw_gain=1.2, articulation=1.2))
    assert large[7, 0] > small[7, 0] * 1.5
    assert SpeakerStyle.for_speaker(2) == SpeakerStyle.for_speaker(2) != SpeakerStyle.for_speaker(3)
    for i in range(14):
        s = SpeakerStyle.for_speaker(i)
        assert (0.1 <= s.onset <= 0.2 and 0.6 <= s.decay <= 1.0
                and 2.0 <= s.blink_interval[0] < s.blink_interval[1] <= 6.0)


def test_visemes_from_real_speech():
    speech = pytest.importorskip("facegen.espeak")
    spoken = speech.synthesize("Bob bought a map", voice="en-us")
    frames = int(np.ceil(spoken.duration * FPS))
    curves = viseme_curves(spoken.phones, frames, FPS)
    close = curves[:, LOWER_CHANNELS.index("lip_close")]
    t = np.arange(frames) / FPS
    bilabials = [p for p in spoken.phones if phone_visemes(p.text) == ("PBM",)]
    assert len(bilabials) >= 4  # b, b, m, p
    for p in bilabials:
        near = np.abs(t - (p.start + p.end) / 2) <= max((p.end - p.start) / 2, 0.5 / FPS) + 1e-9
        assert close[near].max() > 0.99, p
    vowels = [p for p in spoken.phones if phone_visemes(p.text)[0] in ("AA", "AO")]
    assert vowels and max(curves[int((p.start + p.end) / 2 * FPS), 0] for p in vowels) > 0.3


# ---------------------------------------------------------------------------------------- expressions
def test_upper_face_is_zero_without_emotional_words():
    words = [Wd("the", 0.1, 0.2), Wd("table", 0.2, 0.6), Wd("is", 0.6, 0.7), Wd("brown", 0.7, 1.1)]
    curves = expression_curves(words, 40, FPS)
    assert curves.shape == (40, len(UPPER_CHANNELS)) and not curves.any()


def test_expression_onset_hold_and_decay():
    style = SpeakerStyle(onset=0.16, decay=0.8, expressiveness=1.0)
    words = [Wd("what", 0.2, 0.4), Wd("an", 0.4, 0.5), Wd("Amazing!", 1.0, 1.4), Wd("day", 1.4, 1.7)]
    curves = expression_curves(words, 100, FPS, style=style)
    raise_ = curves[:, UPPER_CHANNELS.index("brow_raise")]
    peak = LEXICON["amazing"].intensity * EXPRESSIONS["surprise"]["brow_raise"]
    frame = (np.arange(100) / FPS)
    assert not raise_[frame < 1.0].any()  # nothing before the word
    assert raise_[27] == pytest.approx(0.5 * peak, abs=1e-5)  # half way up the onset ramp (1.08 s)
    assert raise_[(frame >= 1.2) & (frame <= 1.4)] == pytest.approx(peak, abs=1e-6)  # held through the word
    assert 0.2 * peak < raise_[round(1.8 * FPS)] < 0.8 * peak  # decaying
    assert not raise_[frame >= 2.2].any()  # gone after the decay
    assert curves[:, UPPER_CHANNELS.index("lid_widen")].max() > 0
    assert not curves[:, UPPER_CHANNELS.index("brow_frown")].any()


def test_expression_classes_and_lexicon_choice():
    angry = expression_curves([Wd("furious", 0.1, 0.5)], 20, FPS)
    assert angry[:, UPPER_CHANNELS.index("brow_frown")].max() > 0.5
    assert not angry[:, UPPER_CHANNELS.index("brow_raise")].any()
    happy = expression_curves([Wd("delighted", 0.1, 0.5)], 20, FPS)
    assert happy[:, UPPER_CHANNELS.index("cheek_raise")].max() > 0.5
    held_out = [Wd("flabbergasted", 0.1, 0.6)]
    assert expression_curves(held_out, 20, FPS).any()  # the ground truth knows every emotional word
    assert not expression_curves(held_out, 20, FPS, lexicon=TRAIN_LEXICON).any()
    calm = expression_curves([Wd("furious", 0.1, 0.5)], 20, FPS, style=SpeakerStyle(expressiveness=0.5))
    assert calm.max() == pytest.approx(0.5 * angry.max(), abs=1e-6)


def test_upper_face_ignores_the_phones():
    words = [Wd("wow", 0.1, 0.4), Wd("really", 0.4, 0.8)]
    a = motion_curves(_phones(("w", 0.1, 0.2), ("'aU", 0.2, 0.4)), words, 30, FPS,
                      rng=np.random.default_rng(1))
    b = motion_curves(_phones(("m", 0.1, 0.3), ("'i:", 0.3, 0.5)), words, 30, FPS,
                      rng=np.random.default_rng(1))
    assert a.shape == (30, len(CHANNELS))
    upper = [CHANNELS.index(c) for c in UPPER_CHANNELS + ("blink",)]
    assert np.array_equal(a[:, upper], b[:, upper])
    assert not np.array_equal(a[:, : len(LOWER_CHANNELS)], b[:, : len(LOWER_CHANNELS)])


# ---------------------------------------------------------------------------------------------- blinks
def test_blinks_every_two_to_six_seconds():
    frames = int(120 * FPS)
    curve = blink_curves(frames, FPS, np.random.default_rng(7))
    assert curve.shape == (frames, 1) and curve.min() >= 0 and curve.max() == pytest.approx(1.0, abs=0.05)
    closed = curve[:, 0] > 0.5
    starts = np.nonzero(closed[1:] & ~closed[:-1])[0]
    assert 120 / 6 - 2 <= len(starts) <= 120 / 2 + 1
    gaps = np.diff(starts) / FPS
    assert gaps.min() > 1.9 and gaps.max() < 6.5
    active = curve[:, 0] > 0.01
    runs = np.diff(np.flatnonzero(np.diff(np.concatenate([[0], active.astype(int), [0]]))))[::2] / FPS
    assert runs.max() <= 0.26
    assert np.array_equal(curve, blink_curves(frames, FPS, np.random.default_rng(7)))
    assert not np.array_equal(curve, blink_curves(frames, FPS, np.random.default_rng(8)))


# ---------------------------------------------------------------------------------------------- lexicon
def test_lexicon_sizes_classes_and_separation():
    assert len(TRAIN_LEXICON) >= 300 and len(HELD_OUT_LEXICON) >= 60
    assert not set(TRAIN_LEXICON) & set(HELD_OUT_LEXICON)
    assert set(LEXICON) == set(TRAIN_LEXICON) | set(HELD_OUT_LEXICON)
    for word, emotion in LEXICON.items():
        assert emotion.cls in EXPRESSIONS and 0 < emotion.intensity <= 1 and word == normalise_word(word)
    assert {e.cls for e in HELD_OUT_LEXICON.values()} == set(EXPRESSIONS)
    assert normalise_word("Wow!") == "wow" and normalise_word("fear's") == "fear"
    assert lookup("Furious,").cls == "anger" and lookup("table") is None
    assert emotional_words("Wow, the jubilant crowd was happy.") == ["wow", "jubilant", "happy"]
    assert emotional_words("Wow, the jubilant crowd", TRAIN_LEXICON) == ["wow"]
