"""Property tests for every reader: whatever bytes a file holds, a reader returns a value or raises
FacegenError — never another exception — and stays within bounded memory; writers round-trip what they
write."""

from __future__ import annotations

import json
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from facegen.errors import FacegenError

SETTINGS = settings(max_examples=60, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
MEMORY_LIMIT = 200e6  # bytes any one read may allocate on inputs of a few kB


def _noise(prefix: bytes = b"") -> st.SearchStrategy[bytes]:
    return st.binary(max_size=2048).map(lambda b: prefix + b)


def _read(tmp_path: Path, name: str, data: bytes, reader) -> None:
    path = tmp_path / name
    path.write_bytes(data)
    tracemalloc.start()
    try:
        reader(path)
    except FacegenError as exc:
        assert "\n" not in str(exc)
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert peak < MEMORY_LIMIT


def _animation(path: Path):
    from facegen.exchange import read_animation
    from facegen.face.mesh import Mesh

    template = Mesh(np.zeros((4, 3), np.float32), np.array([[0, 1, 2], [1, 2, 3]], np.int32))
    return read_animation(path, template=template)


NPY_HEADER = (b"\x93NUMPY\x01\x00v\x00{'descr': '<f4', 'fortran_order': False, 'shape': (3, 4, 3), }"
              + b" " * 50 + b"\n")
ANIMATIONS = {
    ".npy": st.one_of(_noise(), _noise(NPY_HEADER[:128])),
    ".glb": st.one_of(_noise(), _noise(b"glTF\x02\x00\x00\x00")),
    ".gltf": st.one_of(_noise(), st.recursive(st.none() | st.booleans() | st.floats() | st.text(max_size=8),
                                              lambda c: st.lists(c, max_size=4) | st.dictionaries(
                                                  st.sampled_from(["asset", "meshes", "buffers", "accessors",
                                                                   "version", "uri", "count"]), c,
                                                  max_size=4),
                                              max_leaves=20).map(lambda v: json.dumps(v).encode())),
    ".usda": st.one_of(_noise(b"#usda 1.0\n"), st.text(max_size=400).map(lambda t: ("#usda 1.0\n"
                                                                                    + t).encode())),
    ".usdc": st.one_of(_noise(), _noise(b"PXR-USDC")),
    ".usdz": st.one_of(_noise(), _noise(b"PK\x03\x04")),
}


@pytest.mark.parametrize("suffix", sorted(ANIMATIONS))
def test_animation_readers_on_arbitrary_bytes(suffix, tmp_path):
    @SETTINGS
    @given(ANIMATIONS[suffix])
    def check(data):
        _read(tmp_path, f"anim{suffix}", data, _animation)

    check()


ALIGNMENT_JSON = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
    lambda c: st.lists(c, max_size=5) | st.dictionaries(
        st.sampled_from(["word", "start", "end", "words", "segments", "text", "case", "alignedWord"]), c,
        max_size=5),
    max_leaves=30).map(lambda v: json.dumps(v).encode())


@pytest.mark.parametrize("suffix", [".json", ".TextGrid", ".csv"])
def test_alignment_reader_on_arbitrary_bytes(suffix, tmp_path):
    from facegen.alignment_files import read_alignment, read_phones

    strategy = {".json": st.one_of(_noise(), ALIGNMENT_JSON),
                ".TextGrid": st.one_of(_noise(b'File type = "ooTextFile"\nObject class = "TextGrid"\n'),
                                       st.text(max_size=300).map(
                                           lambda t: ('File type = "ooTextFile"\n' + t).encode())),
                ".csv": st.one_of(_noise(b"word,start,end\n"), st.text(max_size=300).map(str.encode))}[suffix]

    @SETTINGS
    @given(strategy)
    def check(data):
        _read(tmp_path, f"words{suffix}", data, lambda p: read_alignment(p, duration=5.0))
        _read(tmp_path, f"words{suffix}", data, read_phones)

    check()


@SETTINGS
@given(st.one_of(_noise(), _noise(b"\x80\x02}q\x00"), _noise(b"\x80\x04\x95")))
def test_templates_pkl_on_arbitrary_bytes(tmp_path_factory, data):
    from facegen.datasets.templates import read_templates_pkl

    _read(tmp_path_factory.mktemp("pkl"), "templates.pkl", data, read_templates_pkl)


@pytest.mark.parametrize("suffix", [".ply", ".obj"])
def test_mesh_reader_on_arbitrary_bytes(suffix, tmp_path):
    from facegen.face.mesh import read_mesh

    prefix = b"ply\nformat ascii 1.0\n" if suffix == ".ply" else b"v 0 0 0\n"

    @SETTINGS
    @given(st.one_of(_noise(), _noise(prefix), st.text(max_size=300).map(lambda t: prefix + t.encode())))
    def check(data):
        _read(tmp_path, f"mesh{suffix}", data, read_mesh)

    check()


@SETTINGS
@given(st.one_of(_noise(), _noise(b"RIFF\x24\x08\x00\x00WAVEfmt "), _noise(b"ID3"), _noise(b"fLaC")))
def test_audio_reader_on_arbitrary_bytes(tmp_path_factory, data):
    from facegen.audio import load_audio

    _read(tmp_path_factory.mktemp("wav"), "clip.wav", data, load_audio)


@SETTINGS
@given(st.one_of(_noise(), st.integers(0, 4096).flatmap(
    lambda n: _noise(n.to_bytes(8, "little") + b'{"__metadata__":{"facegen":'))))
def test_bundle_reader_on_arbitrary_bytes(tmp_path_factory, data):
    from facegen.bundle import load_bundle

    _read(tmp_path_factory.mktemp("bundle"), "m.safetensors", data, load_bundle)


@SETTINGS
@given(_noise())
def test_vl_reader_on_arbitrary_bytes(data):
    from facegen.datasets.raw import read_vl

    try:
        read_vl(data, "frame.vl")
    except FacegenError:
        pass


WORDS = st.lists(st.tuples(st.from_regex(r"[A-Za-z]([A-Za-z']{0,10}[A-Za-z])?", fullmatch=True),
                           st.floats(0.01, 0.5),
                           st.floats(0.0, 0.3)), min_size=1, max_size=30)


@SETTINGS
@given(WORDS, st.sampled_from([".json", ".TextGrid"]))
def test_alignment_round_trip(tmp_path_factory, spec, suffix):
    from facegen.alignment_files import read_alignment, write_alignment
    from facegen.words import Word

    t, words = 0.0, []
    for text, length, pause in spec:
        start = round(t + pause, 3)
        words.append(Word(text, start, round(start + length, 3)))
        t = start + length
    path = tmp_path_factory.mktemp("align") / f"words{suffix}"
    write_alignment(words, path, duration=t + 1)
    back = read_alignment(path, duration=t + 1)
    assert [w.text for w in back] == [w.text for w in words]
    np.testing.assert_allclose([(w.start, w.end) for w in back], [(w.start, w.end) for w in words], atol=1e-3)


@SETTINGS
@given(st.dictionaries(st.from_regex(r"[A-Z][0-9]{1,2}", fullmatch=True),
                       st.integers(1, 50).map(lambda v: np.random.default_rng(v).normal(size=(v, 3))),
                       min_size=1,
                       max_size=4))
def test_templates_pkl_round_trip(tmp_path_factory, templates):
    from facegen.datasets.templates import read_templates_pkl, write_templates_pkl

    path = tmp_path_factory.mktemp("pkl") / "templates.pkl"
    write_templates_pkl(templates, path)
    back = read_templates_pkl(path)
    assert set(back) == set(templates)
    for k, v in templates.items():
        np.testing.assert_array_equal(back[k], v.astype(np.float32))
