"""The ARKit solver: bounded least squares with temporal smoothness, against scipy and on the real shapes."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import grid_face, make_animation, procedural_rig, rig_clip
from scipy.optimize import lsq_linear

from facegen.animation import Animation
from facegen.arkit.names import ARKIT_NAMES
from facegen.arkit.shapes import arkit_shapes
from facegen.arkit.solve import fit_arkit, solve_weights
from facegen.errors import FacegenError
from facegen.inference import FrameStream


def test_solver_matches_lsq_linear_frame_by_frame():
    rng = np.random.default_rng(3)
    basis = rng.standard_normal((900, 52))
    truth = rng.uniform(-0.4, 1.4, (52, 12))  # many weights beyond the bounds: the box is active
    targets = (basis @ truth).T + 0.5 * rng.standard_normal((12, 900))
    weights = solve_weights(basis.T @ basis, targets @ basis, 0.0)
    reference = np.stack([lsq_linear(basis, d, bounds=(0, 1), method="bvls").x for d in targets])
    assert weights.shape == (12, 52) and weights.min() >= 0 and weights.max() <= 1
    assert ((reference == 0) | (reference == 1)).mean() > 0.2
    assert np.abs(weights - reference).max() < 1e-3


def test_smoothness_trades_jitter_for_fit():
    rng = np.random.default_rng(4)
    basis = rng.standard_normal((300, 8))
    targets = (basis @ rng.uniform(0, 1, (8, 60))).T  # weights jumping frame to frame
    rough = solve_weights(basis.T @ basis, targets @ basis, 0.0)
    smooth = solve_weights(basis.T @ basis, targets @ basis, 500.0)
    jitter = [np.abs(np.diff(w, axis=0)).mean() for w in (rough, smooth)]
    assert jitter[1] < 0.3 * jitter[0]
    assert np.abs(smooth.mean(0) - rough.mean(0)).max() < 0.05  # the level stays, the wiggle goes


@pytest.fixture(scope="module")
def face():
    mesh, _ = procedural_rig()
    return mesh, arkit_shapes(mesh)


def test_recovers_weights_posed_through_the_shapes(face):
    mesh, shapes = face
    rng = np.random.default_rng(5)
    frames = 40
    t = np.linspace(0, 1, frames)[:, None]
    truth = 0.5 + 0.5 * np.sin(2 * np.pi * (rng.uniform(0.3, 1.5, 52) * t + rng.uniform(0, 1, 52)))
    truth *= rng.uniform(0, 1, 52) < 0.5  # a sparse set of active shapes, as in speech
    for a, b in (("jawLeft", "jawRight"), ("mouthLeft", "mouthRight")):  # opposite shapes: one side at a time
        truth[:, ARKIT_NAMES.index(b)] = 0
    vertices = mesh.vertices + np.einsum("tk,kvc->tvc", truth, shapes.offsets)
    anim = Animation.from_mesh(mesh, vertices.astype(np.float32), 25.0)
    fit = fit_arkit(anim, smoothness=0.0)
    assert fit.names == ARKIT_NAMES and fit.weights.shape == (frames, 52) and fit.weights.dtype == np.float32
    assert fit.lip_error_mm < 0.01 and fit.face_error_mm < 0.005
    worst = np.sort(np.abs(fit.weights - truth).max(0))
    # all but two within 0.02: mouthShrugUpper and mouthRollUpper differ by < 0.01 mm on this face, so
    # no fit can tell them apart
    assert worst[-3] < 0.02 and worst[-1] < 0.3
    assert np.abs(fit.weights - truth).mean() < 0.005


def test_speech_fit_follows_the_jaw():
    anim = rig_clip(125)
    fit = fit_arkit(anim)
    jaw = anim.regions["jaw"]
    drop = -(anim.vertices[:, jaw, 1] - anim.template[jaw, 1]).mean(1)
    assert np.corrcoef(fit.weights[:, ARKIT_NAMES.index("jawOpen")], drop)[0, 1] >= 0.9
    assert fit.lip_error_mm < 0.5 and 0 < fit.face_error_mm < 0.5
    assert 0 <= fit.weights.min() and fit.weights.max() <= 1
    left, right = (fit.weights[:, ARKIT_NAMES.index(n)] for n in ("jawLeft", "jawRight"))
    assert np.minimum(left, right).max() < 0.01  # shapes that cancel are not both on


def test_a_stream_fits_like_its_array(face):
    mesh, _ = face
    rng = np.random.default_rng(6)
    states = rng.standard_normal((300, 4)).astype(np.float32)  # more frames than one block
    weight = (0.0004 * rng.standard_normal((3 * mesh.num_vertices, 4))).astype(np.float32)
    stream = FrameStream(states, weight, mesh.vertices, block_frames=70)
    streamed = fit_arkit(Animation.from_mesh(mesh, stream, 25.0))
    whole = fit_arkit(Animation.from_mesh(mesh, np.asarray(stream), 25.0))
    assert np.abs(streamed.weights - whole.weights).max() < 1e-4
    assert streamed.lip_error_mm == pytest.approx(whole.lip_error_mm, rel=1e-4)


def test_a_face_without_the_rig_regions_is_one_line():
    anim = make_animation(grid_face(), frames=5)
    with pytest.raises(FacegenError) as err:
        fit_arkit(anim)
    assert "\n" not in str(err.value) and "jaw" in str(err.value)
    with pytest.raises(FacegenError, match="smoothness"):
        fit_arkit(anim, smoothness=-1)


def test_a_half_open_jaw_reads_as_jaw_open_and_the_lip_alone():
    """The rig's jaw turns on an arc and jawOpen moves on a line: at jaw_open j the jaw lies up to 1 mm off
    it. The fit solves for that bulge (Shapes.hidden) and drops it, so a half-open jaw reads as j times the
    full opening's jawOpen and mouthLowerDown and nothing else. Without it, jaw_open 1/2 read as jawForward
    0.19, mouthShrugLower 0.18 and mouthRollLower 0.14 (an ARKit rig would push the chin out and roll the
    lower lip in at every half-open vowel)."""
    from facegen.face.rig import CHANNELS

    rig_mesh, rig = procedural_rig()
    openings = np.array([0.0, 0.25, 0.5, 0.75, 1.0], np.float32)
    weights = np.zeros((len(openings), len(CHANNELS)), np.float32)
    weights[:, CHANNELS.index("jaw_open")] = openings
    anim = Animation.from_mesh(rig_mesh, rig.pose(weights), 25.0)
    fit = fit_arkit(anim, 0.0)
    w = {n: fit.weights[:, i] for i, n in enumerate(fit.names)}
    assert np.allclose(w["jawOpen"], openings * w["jawOpen"][-1], atol=0.01), w["jawOpen"]
    assert np.allclose(w["mouthLowerDownLeft"], openings * w["mouthLowerDownLeft"][-1], atol=0.01)
    assert 0.3 < w["jawOpen"][-1] < 0.5
    moved = {"jawOpen", "mouthLowerDownLeft", "mouthLowerDownRight"}
    others = {n: float(v.max()) for n, v in w.items() if n not in moved and v.max() >= 0.02}
    assert not others, others
    # the weights pose the frames to within the bulge dropped (~1 mm at the chin, 0.13 mm on average: as
    # close as the fit that made it up out of other shapes came)
    assert fit.face_error_mm < 0.2 and fit.lip_error_mm < 0.3
