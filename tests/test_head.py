"""Head motion (issue 24): prosody-driven nods, tilts and drift within the targets, written as a transform
in USD (reopened with pxr), glTF (reopened with pygltflib), the Live Link CSV, the ARKit JSON and beside a
.npy; the points stay face-local, and --head-motion 0 leaves them bit-identical."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

import facegen
from facegen.head import angles_of, head_motion, quaternions, rotations


@pytest.fixture(scope="module")
def speech(tmp_path_factory):
    """About 30 s of espeak phrases with pauses, its pauses and transcript."""
    import soundfile as sf

    from facegen.blinks import quiet_spans
    from facegen.espeak import synthesize
    from facegen.synth.sentences import generated_sentences

    rng = np.random.default_rng(2)
    parts, words = [], []
    for i, text in enumerate(list(generated_sentences(12).values())):
        parts += [synthesize(text, variant=("m1", "f3")[i % 2], sample_rate=16000).audio,
                  np.full(int(rng.uniform(0.3, 0.9) * 16000), 1e-4, np.float32)]
        words.append(text)
    audio = np.concatenate(parts)
    wav = tmp_path_factory.mktemp("head") / "speech.wav"
    sf.write(wav, audio, 16000)
    return wav, audio, quiet_spans(audio, 16000), " ".join(words)


def test_head_motion_meets_the_targets(speech):
    _, audio, pauses, _ = speech
    frames = int(len(audio) / 16000 * 25)
    angles = head_motion(audio, 16000, pauses, frames, 25.0)
    assert angles.shape == (frames, 3) and angles.dtype == np.float32
    assert np.array_equal(angles, head_motion(audio, 16000, pauses, frames, 25.0))
    assert not np.array_equal(angles, head_motion(audio, 16000, pauses, frames, 25.0, seed=4))
    assert not head_motion(audio, 16000, pauses, frames, 25.0, amount=0).any()
    t = np.arange(frames) / 25
    speaking = np.ones(frames, bool)
    for a, b in pauses:
        speaking[(t >= a) & (t < b)] = False
    rms = np.sqrt((angles[speaking] ** 2).sum(1).mean())
    assert 1.0 <= rms <= 4.0, rms
    assert np.abs(angles).max() <= 10 and np.abs(np.diff(angles, axis=0)).max() <= 1.5
    speed = np.linalg.norm(np.diff(angles, axis=0), axis=1)
    assert speed[speaking[1:]].mean() >= 2 * speed[~speaking[1:]].mean()


def test_rotations_and_quaternions_agree():
    from scipy.spatial.transform import Rotation

    angles = np.array([[10.0, 0, 0], [0, 10.0, 0], [0, 0, 10.0], [3.0, -2.0, 1.5]])
    r = rotations(angles)
    assert r[0] @ [0, 0, 1] == pytest.approx([np.sin(np.radians(10)), 0, np.cos(np.radians(10))])  # to +x
    assert (r[1] @ [0, 0, 1])[1] < 0  # a nod: the face looks down
    assert (r[2] @ [1, 0, 0])[1] > 0  # roll: the face's left side rises
    assert np.allclose(Rotation.from_quat(quaternions(angles)).as_matrix(), r, atol=1e-6)


def test_angles_of_inverts_rotations():
    angles = np.random.default_rng(5).uniform([-60, -80, -60], [60, 80, 60], (200, 3)).astype(np.float32)
    np.testing.assert_allclose(angles_of(rotations(angles)), angles, atol=1e-4)
    assert angles_of(np.eye(3)[None]).tolist() == [[0.0, 0.0, 0.0]]


@pytest.fixture(scope="module")
def animated(speech):
    wav, _, _, text = speech
    return facegen.animate(wav, text=text), facegen.animate(wav, text=text, head_motion=0)


def test_the_points_stay_face_local(animated):
    moving, still = animated
    assert still.head is None and moving.head.shape == (moving.num_frames, 3)
    assert np.array_equal(moving.vertices, still.vertices)
    assert moving.metadata["head_motion"]["amount"] == 1.0
    assert still.metadata["head_motion"] == {"amount": 0.0}


def _expected(anim, frame: int, vertex: int) -> np.ndarray:
    p, pivot = anim.vertices[frame, vertex].astype(np.float64), anim.head_pivot.astype(np.float64)
    return pivot + rotations(anim.head[frame:frame + 1])[0] @ (p - pivot)


def test_usd_and_gltf_carry_the_transform(animated, tmp_path):
    import pygltflib
    from pxr import Gf, Usd, UsdGeom
    from scipy.spatial.transform import Rotation

    from facegen.exchange import write_animation

    anim, _ = animated
    frame, vertex = int(np.argmax(np.abs(anim.head).sum(1))), 1234
    for ext in (".usda", ".usdc"):
        write_animation(anim, tmp_path / f"a{ext}")
        stage = Usd.Stage.Open(str(tmp_path / f"a{ext}"))
        face = UsdGeom.Xformable(stage.GetPrimAtPath("/Face"))
        ops = [op.GetOpName() for op in face.GetOrderedXformOps()]
        assert ops == ["xformOp:translate:pivot", "xformOp:rotateZXY:head", "!invert!xformOp:translate:pivot"]
        assert len(face.GetOrderedXformOps()[1].GetTimeSamples()) == anim.num_frames
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Face/Mesh"))
        local = np.asarray(mesh.GetPointsAttr().Get(frame))[vertex]
        assert np.allclose(local, anim.vertices[frame, vertex], atol=1e-6)  # face-local points
        world = face.ComputeLocalToWorldTransform(frame).Transform(Gf.Vec3d(*local.astype(float)))
        assert np.allclose(list(world), _expected(anim, frame, vertex), atol=1e-5)
    write_animation(anim, tmp_path / "a.glb")
    doc = pygltflib.GLTF2().load(str(tmp_path / "a.glb"))
    head = next(i for i, n in enumerate(doc.nodes) if n.name == "Head")
    assert doc.scenes[0].nodes == [head] and doc.nodes[head].children == [0]
    channel = next(c for c in doc.animations[0].channels if c.target.path == "rotation")
    assert channel.target.node == head
    accessor = doc.accessors[doc.animations[0].samplers[channel.sampler].output]
    assert accessor.count == anim.num_frames and accessor.type == "VEC4"
    view = doc.bufferViews[accessor.bufferView]
    data = doc.binary_blob()[view.byteOffset + (accessor.byteOffset or 0):][:accessor.count * 16]
    quats = np.frombuffer(data, np.float32).reshape(-1, 4)
    assert np.allclose(np.linalg.norm(quats, axis=1), 1, atol=1e-5)
    scale = doc.nodes[0].scale[0]
    r = Rotation.from_quat(quats[frame]).as_matrix()
    world = np.asarray(doc.nodes[head].translation) + r @ (np.asarray(doc.nodes[0].translation)
                                                           + scale * anim.vertices[frame, vertex])
    assert np.allclose(world, scale * _expected(anim, frame, vertex), atol=1e-5)


@pytest.mark.parametrize("ext", [".usdc", ".glb"])
def test_usd_and_gltf_read_back_the_head(animated, tmp_path, ext):
    """`facegen render x.glb`, a read and a rewrite keep the head's turn: the readers give it back."""
    from facegen.exchange import read_animation, write_animation

    anim, still = animated
    write_animation(anim, tmp_path / f"a{ext}")
    back = read_animation(tmp_path / f"a{ext}")
    assert back.head.shape == (anim.num_frames, 3)
    np.testing.assert_allclose(back.head, anim.head, atol=1e-4)  # degrees (glTF: through quaternions)
    np.testing.assert_allclose(back.head_pivot, anim.head_pivot, atol=1e-6)
    write_animation(back, tmp_path / f"b{ext}")  # and again: the same turn
    np.testing.assert_allclose(read_animation(tmp_path / f"b{ext}").head, anim.head, atol=2e-4)
    write_animation(still, tmp_path / f"s{ext}")
    assert read_animation(tmp_path / f"s{ext}").head is None


def test_csv_json_and_npy_carry_the_angles(animated, tmp_path):
    from facegen.exchange import write_animation

    anim, _ = animated
    write_animation(anim, tmp_path / "a.csv")
    rows = list(csv.DictReader((tmp_path / "a.csv").open()))
    got = np.array([[float(r["HeadYaw"]), float(r["HeadPitch"]), float(r["HeadRoll"])] for r in rows])
    assert np.allclose(got, np.radians(anim.head), atol=1e-5)
    write_animation(anim, tmp_path / "a.json")
    head = json.loads((tmp_path / "a.json").read_text())["facegenHead"]
    assert head["units"] == "degrees" and np.allclose(head["values"], anim.head, atol=1e-3)
    files = write_animation(anim, tmp_path / "a.npy")
    assert tmp_path / "a.head.npy" in files
    assert np.array_equal(np.load(tmp_path / "a.head.npy"), anim.head)
    assert np.load(tmp_path / "a.npy").shape == (anim.num_frames, 3 * anim.num_vertices)


def test_the_preview_turns_the_head(animated):
    from facegen.render import _posed

    anim, still = animated
    frame = int(np.argmax(np.abs(anim.head).sum(1)))
    assert np.allclose(_posed(anim, frame)[1234], _expected(anim, frame, 1234), atol=1e-5)
    assert np.array_equal(_posed(still, frame), still.vertices[frame])
