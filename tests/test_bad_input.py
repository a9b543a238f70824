"""The bad-input matrix: every subcommand, fed what users and broken pipelines feed it, answers with one line
and exit 2 — no traceback, no "internal error", nothing written."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from helpers import grid_face, make_bundle

from facegen.cli import main

ROOT = Path(__file__).resolve().parents[1]
WAV = ROOT / "examples" / "excellent_room.wav"
TXT = ROOT / "examples" / "excellent_room.txt"


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("inputs")
    shutil.copy(WAV, d / "clip.wav")
    shutil.copy(TXT, d / "clip.txt")
    (d / "garbage.wav").write_bytes(b"this is not audio at all" * 10)
    (d / "garbage.safetensors").write_bytes(b"\x00" * 64)
    (d / "nested.json").write_text("[" * 50_000 + "]" * 50_000)
    (d / "too_many.json").write_text(json.dumps([{"word": "la", "start": i * 0.001, "end": i * 0.001 + 0.0005}
                                                 for i in range(3000)]))
    (d / "x.usda").write_text("#usda 1.0\n")
    np.save(d / "anim.npy", np.zeros((5, 7, 3), np.float32))
    (d / "manifest.csv").write_text("audio,output\nclip.wav,clip.usda\n")
    (d / "data").mkdir()
    bundle = make_bundle(grid_face())
    with torch.no_grad():
        bundle.model.fc_out.weight.fill_(float("nan"))
    from facegen.bundle import save_bundle

    save_bundle(bundle, d / "nan.safetensors")
    return d


LONG = "a" * 300
CASES = {
    "animate: missing audio": "animate {i}/missing.wav --no-text -o {o}/out.usda",
    "animate: audio is not audio": "animate {i}/garbage.wav --no-text -o {o}/out.usda",
    "animate: unknown extension": "animate {i}/clip.wav --no-text -o {o}/out.xyz",
    "animate: output folder is a file": "animate {i}/clip.wav --no-text -o {i}/clip.wav/out.usda",
    "animate: speaker of 5,000 digits": ("animate {i}/clip.wav --no-text -o {o}/out.npy --speaker "
                                         + "9" * 5000),
    "animate: tolerance nan": "animate {i}/clip.wav --no-text -o {o}/out.glb --tolerance nan",
    "animate: tolerance inf": "animate {i}/clip.wav --no-text -o {o}/out.glb --tolerance inf",
    "animate: tolerance 1e300": "animate {i}/clip.wav --no-text -o {o}/out.glb --tolerance 1e300",
    "animate: morph targets 0": "animate {i}/clip.wav --no-text -o {o}/out.glb --morph-targets 0",
    "animate: morph targets word": "animate {i}/clip.wav --no-text -o {o}/out.glb --morph-targets many",
    "animate: option of another format": "animate {i}/clip.wav --no-text -o {o}/out.npy --tolerance 0.01",
    "animate: name too long": "animate {i}/clip.wav --no-text -o {o}/" + LONG + ".usda",
    "animate: output is the transcript": "animate {i}/clip.wav --text-file {i}/x.usda -o {i}/x.usda",
    "animate: nested alignment": "animate {i}/clip.wav --alignment {i}/nested.json -o {o}/out.npy",
    "animate: impossible word rate": "animate {i}/clip.wav --alignment {i}/too_many.json -o {o}/out.npy",
    "animate: empty transcript": "animate {i}/clip.wav --text ' ' -o {o}/out.npy",
    "animate: missing model": "animate {i}/clip.wav --no-text --model {i}/missing.safetensors -o {o}/out.npy",
    "animate: corrupt model": "animate {i}/clip.wav --no-text --model {i}/garbage.safetensors -o {o}/out.npy",
    "animate: NaN model": "animate {i}/clip.wav --no-text --model {i}/nan.safetensors -o {o}/out.npy",
    "animate: unknown speaker": "animate {i}/clip.wav --no-text --speaker Q9 -o {o}/out.npy",
    "animate: two transcripts": "animate {i}/clip.wav --no-text --text hi -o {o}/out.npy",
    "align: missing audio": "align {i}/missing.wav --text hello -o {o}/words.json",
    "align: output is the transcript": "align {i}/clip.wav --text-file {i}/clip.txt -o {i}/clip.txt",
    "align: unknown extension": "align {i}/clip.wav --text hello -o {o}/words.xyz",
    "align: impossible word rate": "align {i}/clip.wav --text '" + "la " * 400 + "' -o {o}/words.json",
    "train: bundle named .usda": "train {i}/data -o {o}/m.usda",
    "train: threads -1": "train {i}/data -o {o}/m.safetensors --threads -1",
    "train: batch size 0": "train {i}/data -o {o}/m.safetensors --batch-size 0",
    "train: lr nan": "train {i}/data -o {o}/m.safetensors --lr nan",
    "train: epochs 0": "train {i}/data -o {o}/m.safetensors --epochs 0",
    "train: no dataset": "train {i}/missing -o {o}/m.safetensors",
    "train: empty dataset": "train {i}/data -o {o}/m.safetensors",
    "batch: batch size 0": "batch {i}/manifest.csv -o {o} --batch-size 0",
    "batch: missing manifest": "batch {i}/missing.csv -o {o}",
    "validate: missing file": "validate {i}/missing.usda",
    "validate: fps nan": "validate {i}/x.usda --fps nan",
    "render: missing input": "render {i}/missing.npy -o {o}/v.mp4",
    "render: size 0": "render {i}/anim.npy -o {o}/v.mp4 --size 0",
    "render: video extension": "render {i}/anim.npy -o {o}/v.avi",
    "data synth: fps nan": "data synth {o}/corpus --fps nan",
    "data synth: workers 0": "data synth {o}/corpus --workers 0",
    "data import-biwi: not a release": "data import-biwi {i}/data {o}/dataset",
    "evaluate: missing bundle": "evaluate {i}/missing.safetensors {i}/data",
    "info: missing bundle": "info {i}/missing.safetensors",
    "info: corrupt bundle": "info {i}/garbage.safetensors",
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_input_is_one_line_exit_2_and_writes_nothing(case, inputs, tmp_path, capsys):
    import shlex

    out = tmp_path / "out"
    out.mkdir()
    before = sorted(p.name for p in inputs.iterdir())
    argv = shlex.split(CASES[case].format(i=inputs, o=out))
    with pytest.raises(SystemExit) as info:
        main(argv)
    err = capsys.readouterr().err.strip()
    assert info.value.code == 2, err
    lines = err.splitlines()
    assert lines and lines[-1].startswith("facegen: error: "), err
    problems = [ln for ln in lines if ln.startswith("facegen: error: ") or "Traceback" in ln]
    assert len(problems) == 1 and "internal error" not in err, err
    assert list(out.iterdir()) == [], "something was written"
    assert sorted(p.name for p in inputs.iterdir()) == before
    assert ((inputs / "x.usda").read_text() == "#usda 1.0\n"
            and (inputs / "clip.txt").read_bytes() == TXT.read_bytes())
