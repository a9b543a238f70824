"""End-to-end: the facegen command through a real subprocess, on synthesised speech and the BIWI template."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from helpers import make_bundle

SENTENCE = "What an excellent room you have, sir. Such expensive furnishings!"


def run(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "facegen", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=300, check=False)


@pytest.fixture(scope="module")
def work(tmp_path_factory, biwi_template):
    from facegen.espeak import synthesize

    d = tmp_path_factory.mktemp("cli")
    speech = synthesize(SENTENCE, voice="en-us", pitch=40, rate=165)
    sf.write(d / "speech.wav", speech.audio, speech.sample_rate, subtype="PCM_16")
    (d / "line.txt").write_text(SENTENCE + "\n")
    (d / "words.json").write_text(json.dumps({"words": [{"word": w.text, "start": w.start, "end": w.end}
                                                         for w in speech.words]}))
    make_bundle(biwi_template, d / "model.safetensors", speakers=("F2", "F3", "F4", "M3"))
    return d, speech


def assert_user_error(proc: subprocess.CompletedProcess, fragment: str, folder: Path) -> None:
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert fragment.lower() in lines[0].lower(), lines[0]
    assert not list(folder.glob("out*")) and not list(folder.glob(".out*")), list(folder.iterdir())


@pytest.mark.parametrize("ext", ["usda", "usdc", "npy"])
def test_animate_writes_valid_assets(work, ext, biwi_template):
    d, speech = work
    out = d / f"anim_{ext}" / f"clip.{ext}"
    out.parent.mkdir()
    p = run("animate", d / "speech.wav", "--text", SENTENCE, "--speaker", "3", "--model",
            d / "model.safetensors",
            "-o", out)
    assert p.returncode == 0, p.stderr
    T = round(len(speech.audio) / speech.sample_rate * 25)
    assert (out.parent / "clip.wav").is_file()
    if ext == "npy":
        arr = np.load(out)
        assert arr.shape == (T, 23370 * 3) and arr.dtype == np.float32
        v = arr.reshape(T, -1, 3)
    else:
        from pxr import Usd, UsdGeom

        stage = Usd.Stage.Open(str(out))
        assert stage.GetTimeCodesPerSecond() == 25 and stage.GetEndTimeCode() == T - 1
        mesh = next(UsdGeom.Mesh(p) for p in stage.Traverse() if p.IsA(UsdGeom.Mesh))
        times = mesh.GetPointsAttr().GetTimeSamples()
        assert times == list(range(T))
        v = np.stack([np.asarray(mesh.GetPointsAttr().Get(t)) for t in (0, T // 2, T - 1)])
        assert np.array_equal(np.asarray(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3),
                              biwi_template.faces)
    moved = np.abs(v - biwi_template.vertices[None]).max()
    assert 1e-4 < moved < 0.25 * biwi_template.size
    val = run("validate", out, "--model", d / "model.safetensors", "--fps", "25", "--json")
    assert val.returncode == 0, val.stdout + val.stderr
    assert json.loads(val.stdout)["ok"] is True


def test_the_input_audio_as_sidecar_is_not_said_to_be_written(work):
    d, _ = work
    folder = d / "beside"
    folder.mkdir()
    source = folder / "clip.wav"
    source.write_bytes((d / "speech.wav").read_bytes())
    model = d / "model.safetensors"
    p = run("animate", source, "--text", SENTENCE, "--model", model, "-o", folder / "clip.usda")
    assert p.returncode == 0, p.stderr
    said = p.stderr.strip().splitlines()[-1]
    assert said.startswith(f"facegen: wrote {folder / 'clip.usda'} (") and f"{source}, referenced)" in said
    assert f"{folder / 'clip.usda'}, " not in said and source.read_bytes() == (d / "speech.wav").read_bytes()
    p = run("animate", source, "--text", SENTENCE, "--model", model, "-o", folder / "b.usda")
    assert f"wrote {folder / 'b.usda'}, {folder / 'b.wav'} (" in p.stderr and "referenced" not in p.stderr


def test_alignment_file_and_no_text_and_text_file(work):
    d, _ = work
    for i, extra in enumerate((["--alignment", d / "words.json"], ["--no-text"], ["--text-file",
                                                                                  d / "line.txt"])):
        out = d / f"variant{i}.npy"
        p = run("animate", d / "speech.wav", *extra, "--model", d / "model.safetensors", "-o", out, "-q")
        assert p.returncode == 0, p.stderr
        assert p.stderr == ""  # --quiet
        assert np.load(out).shape[1] == 70110


def test_speaker_changes_the_motion(work):
    d, _ = work
    outs = []
    for spk in ("F2", "M3"):
        out = d / f"spk_{spk}.npy"
        assert run("animate", d / "speech.wav", "--alignment", d / "words.json", "--speaker", spk,
                   "--model", d / "model.safetensors", "-o", out).returncode == 0
        outs.append(np.load(out))
    assert np.abs(outs[0] - outs[1]).max() > 1e-5


def test_align_command(work):
    d, speech = work
    p = run("align", d / "speech.wav", "--text", SENTENCE, "-o", d / "aligned.TextGrid")
    assert p.returncode == 0, p.stderr
    text = (d / "aligned.TextGrid").read_text()
    assert '"excellent"' in text and 'name = "words"' in text
    p = run("align", d / "speech.wav", "--text", SENTENCE)
    words = json.loads(p.stdout)["words"]
    assert [w["word"] for w in words][:3] == ["What", "an", "excellent"]
    truth = {w.text: w.start for w in speech.words}
    assert abs(words[2]["start"] - truth["excellent"]) < 0.1


def test_info(work):
    d, _ = work
    p = run("info", d / "model.safetensors")
    assert p.returncode == 0
    assert "23370 vertices, 46068 faces" in p.stdout and "0=F2, 1=F3, 2=F4, 3=M3" in p.stdout
    meta = json.loads(run("info", d / "model.safetensors", "--json").stdout)
    assert meta["topology"]["num_vertices"] == 23370


def _bad_inputs(d: Path) -> dict:
    (d / "bad").mkdir(exist_ok=True)
    b = d / "bad"
    (b / "notaudio.wav").write_text("hello, I am text")
    sf.write(b / "silent.wav", np.zeros(16000, np.float32), 16000)
    sf.write(b / "short.wav", 0.3 * np.sin(np.arange(300) / 5).astype(np.float32), 16000)
    (b / "malformed.json").write_text("{not json")
    (b / "late.json").write_text(json.dumps({"words": [{"word": "hello", "start": 0.1, "end": 99.0}]}))
    data = (d / "model.safetensors").read_bytes()
    (b / "trunc.safetensors").write_bytes(data[: len(data) // 3])
    from facegen.face.mesh import Mesh, read_mesh, write_mesh

    biwi = read_mesh(Path(__file__).resolve().parents[2] / "shared" / "biwi" / "BIWI.ply")
    write_mesh(Mesh(biwi.vertices[:-10], biwi.faces[biwi.faces.max(1) < 23360]), b / "small.ply")
    nan = biwi.vertices.copy()
    nan[5] = np.nan
    (b / "nan.obj").write_text("".join(f"v {x} {y} {z}\n" for x, y, z in nan)
                               + "".join(f"f {i + 1} {j + 1} {k + 1}\n" for i, j, k in biwi.faces))
    ro = b / "readonly"
    ro.mkdir(exist_ok=True)
    ro.chmod(0o555)
    return {
        "missing": (["animate", d / "nope.wav", "--text", "hi"], "does not exist"),
        "notaudio": (["animate", b / "notaudio.wav", "--text", "hi"], "cannot read"),
        "silent": (["animate", b / "silent.wav", "--text", "hi"], "silent"),
        "short": (["animate", b / "short.wav", "--text", "hi"], "shorter than one frame"),
        "empty": (["animate", d / "speech.wav", "--text", "  "], "empty"),
        "mismatch": (["animate", d / "speech.wav", "--text",
                      "the quick brown fox jumps over the lazy dog and then it sleeps for a very long time"],
                     "transcript"),
        "malformed": (["animate", d / "speech.wav", "--alignment", b / "malformed.json"], "malformed.json"),
        "late": (["animate", d / "speech.wav", "--alignment", b / "late.json"], "late.json"),
        "speaker": (["animate", d / "speech.wav", "--no-text", "--speaker", "Z9"], "0=F2, 1=F3, 2=F4, 3=M3"),
        "topology": (["animate", d / "speech.wav", "--no-text", "--template", b / "small.ply"], "vertices"),
        "nan": (["animate", d / "speech.wav", "--no-text", "--template", b / "nan.obj"], "nan"),
        "bundle": (["animate", d / "speech.wav", "--no-text", "--model", b / "trunc.safetensors"], "corrupt"),
        "extension": (["animate", d / "speech.wav", "--no-text"], ".usda"),
        "both": (["animate", d / "speech.wav", "--no-text", "--text", "hi"], "cannot be used together"),
    }


def test_user_errors_are_one_line_exit_2_and_leave_nothing(work):
    d, _ = work
    cases = _bad_inputs(d)
    for name, (args, fragment) in cases.items():
        out_dir = d / f"err_{name}"
        out_dir.mkdir(exist_ok=True)
        out = out_dir / ("out.fbx" if name == "extension" else "out.usda")
        if "--model" not in args:
            args = [*args, "--model", d / "model.safetensors"]
        proc = run(*args, "-o", out)
        assert_user_error(proc, fragment, out_dir)


def test_unwritable_output_and_debug_traceback(work):
    d, _ = work
    ro = d / "bad" / "readonly"
    if not list((d / "bad").glob("*")):
        _bad_inputs(d)
    import os

    if os.geteuid() == 0:  # root writes anywhere (and animate makes missing folders): a file as the folder
        target = d / "speech.wav" / "out.usda"
    else:
        target = ro / "out.usda"
    p = run("animate", d / "speech.wav", "--no-text", "--model", d / "model.safetensors", "-o", target)
    assert p.returncode == 2 and "output folder" in p.stderr and len(p.stderr.strip().splitlines()) == 1
    p = run("--debug", "animate", d / "nope.wav", "--no-text", "-o", d / "x.usda")
    assert p.returncode != 0 and "Traceback" in p.stderr


def test_help_is_fast_and_lists_commands():
    p = run("--help")
    assert p.returncode == 0
    for cmd in ("animate", "align", "validate", "info"):
        assert cmd in p.stdout


@pytest.mark.parametrize("args, fragment", [
    (["data", "synth", "{d}/out", "--preset", "voices", "--subjects", "F2"],
     "do not apply to --preset voices"),
    (["data", "synth", "{d}/out", "--limit", "3"], "--limit applies to --preset voices only"),
    (["data", "synth", "{d}/out", "--languages", "fr"], "--languages applies to --preset voices only"),
    (["data", "synth", "{d}/out", "--preset", "voices", "--languages", "fr,nl"], "no voices for 'nl'"),
    (["align", "{speech}", "--phones"], "--phones needs the transcript"),
    (["align", "{speech}", "--text", "hi", "--phones", "-o", "{d}/out.csv"],
     "use a .json or .TextGrid file name"),
])
def test_corpus_and_phone_errors_are_one_line(tmp_path, args, fragment):
    from facegen.audio import write_wav
    from facegen.espeak import synthesize

    speech = tmp_path / "speech.wav"
    write_wav(synthesize("hi there").audio, 22050, speech)
    proc = run(*[a.format(d=tmp_path, speech=speech) for a in args])
    assert_user_error(proc, fragment, tmp_path)
    assert not (tmp_path / "out").exists()


def test_align_phones_writes_words_and_phones(tmp_path):
    from facegen.audio import write_wav
    from facegen.espeak import synthesize

    speech = synthesize("Please bring my map.", voice="en-us", rate=150)
    write_wav(speech.audio, speech.sample_rate, tmp_path / "s.wav")
    proc = run("align", tmp_path / "s.wav", "--text", "Please bring my map.", "--phones", "-o",
               tmp_path / "a.json")
    assert proc.returncode == 0, proc.stderr
    data = json.loads((tmp_path / "a.json").read_text())
    assert [w["word"] for w in data["words"]] == ["Please", "bring", "my", "map"]
    phones = [p["phone"] for p in data["phones"]]
    assert phones[:3] == ["P", "L", "IY"] and phones.count("M") == 2 and "B" in phones
    assert all(data["words"][0]["start"] <= p["start"] < p["end"] <= data["words"][-1]["end"] + 1e-6
               for p in data["phones"])
