"""ARKit tongueOut from the tongue (facegen.tongue's tipForward, th): in every ARKit output — Audio2Face JSON,
Live Link Face CSV, `--rig arkit` glTF and USD, the Blender helper's reading — on real espeak-ng speech; the
other 51 weights are the fit's own, unchanged."""

from __future__ import annotations

import csv
import json
from dataclasses import replace

import numpy as np
import pytest

from facegen.arkit.names import ARKIT_NAMES, LIVE_LINK_COLUMNS, arkit_name
from facegen.arkit.solve import TONGUE_OUT, fit_arkit
from facegen.exchange import write_animation

TEXT = "I think the three of them came with Beth. Maybe Bob bought a map."
PAD_S = 0.5  # silence before and after the speech
TONGUE = ARKIT_NAMES.index("tongueOut")
OTHERS = [k for k in range(len(ARKIT_NAMES)) if k != TONGUE]


@pytest.fixture(scope="module")
def spoken(tmp_path_factory):
    """The animation of espeak-ng speaking TEXT between two silences, its fit, and espeak's phones (times in
    the clip)."""
    import soundfile as sf

    import facegen
    from facegen.espeak import synthesize

    speech = synthesize(TEXT, sample_rate=16000)
    pad = np.full(int(PAD_S * 16000), 1e-4, np.float32)
    wav = tmp_path_factory.mktemp("tongue") / "th.wav"
    sf.write(wav, np.concatenate([pad, speech.audio, pad]), 16000)
    anim = facegen.animate(wav, text=TEXT, seed=1)
    phones = [(p.text.strip("',%=_:"), p.start + PAD_S, p.end + PAD_S) for p in speech.phones]
    return anim, fit_arkit(anim), phones


def frames_of(anim, phones, names: set[str]) -> list[list[int]]:
    """The frames within each phone named in `names` (espeak's mnemonics), one list per phone."""
    t = np.arange(anim.num_frames) / anim.fps
    return [list(np.flatnonzero((t >= start) & (t < end))) or [round((start + end) / 2 * anim.fps)]
            for name, start, end in phones if name in names]


def test_tongue_out_shows_for_th_only(spoken):
    anim, fit, phones = spoken
    tongue = fit.weights[:, TONGUE]
    th = frames_of(anim, phones, {"T", "D"})  # espeak: T = θ (think, three, Beth), D = ð (the, them, with)
    assert len(th) == 6
    assert all(tongue[frames].max() > 0.3 for frames in th), [tongue[f].max() for f in th]
    assert tongue.max() == pytest.approx(TONGUE_OUT)
    bilabial = frames_of(anim, phones, {"b", "m", "p"})[-6:]  # "Maybe Bob bought a map": far from any th
    assert len(bilabial) == 6 and max(tongue[f].max() for f in bilabial) <= 0.05
    pad = int(PAD_S * anim.fps) - 3  # the silent frames at either end (3 frames from the speech)
    silence = np.r_[:pad, anim.num_frames - pad : anim.num_frames]
    assert tongue[silence].max() <= 0.05


def test_the_other_weights_are_the_fit_of_the_face(spoken):
    """Without the parts (main's fit: it never read the tongue) the 51 other weights are bit-identical; the
    solver's own tongueOut (the lower lip a tongue pushes out) stays near 0: under 0.08 (0.05 at most seen
    since mouthPucker closes the lips and the pursed rounding's forward lower lip is left to the fit), far
    under the tongue's own."""
    anim, fit, _ = spoken
    before = fit_arkit(replace(anim, parts=None))
    assert np.array_equal(before.weights[:, OTHERS], fit.weights[:, OTHERS])
    assert before.weights[:, TONGUE].max() < 0.08 and fit.weights[:, TONGUE].max() > 0.3


def test_every_arkit_output_carries_it(spoken, tmp_path):
    from pxr import Usd, UsdSkel

    from facegen.blender.facegen_arkit import read_weights
    from facegen.exchange import gltf

    anim, fit, _ = spoken
    expected = fit.weights[:, TONGUE]
    doc = json.loads(write_animation(anim, tmp_path / "a.json")[0].read_text())
    assert np.allclose(np.asarray(doc["weightMat"])[:, TONGUE], expected, atol=1e-5)
    helper = read_weights(tmp_path / "a.json")  # the Blender helper keys what it reads
    assert np.allclose(helper["weights"][:, helper["names"].index("tongueOut")], expected, atol=1e-5)
    with open(write_animation(anim, tmp_path / "a.csv")[0], newline="") as f:
        header, *rows = list(csv.reader(f))
    column = [arkit_name(c) for c in header].index("tongueOut")
    assert header == list(LIVE_LINK_COLUMNS) and header[column] == "TongueOut"
    assert np.allclose([float(r[column]) for r in rows], expected, atol=1e-5)
    write_animation(anim, tmp_path / "a.glb", rig="arkit")
    assert np.allclose(gltf.decode(tmp_path / "a.glb")["weights"][:, TONGUE], expected)
    write_animation(anim, tmp_path / "a.usdc", rig="arkit")
    stage = Usd.Stage.Open(str(tmp_path / "a.usdc"))
    skel = UsdSkel.Animation(stage.GetPrimAtPath("/Face/Skeleton/Animation"))
    usd = [skel.GetBlendShapeWeightsAttr().Get(t)[TONGUE] for t in range(anim.num_frames)]
    assert np.allclose(usd, expected)
