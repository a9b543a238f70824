"""`facegen batch`: manifests read with their line numbers, plans refused before any work, worker processes,
several formats from one inference, validation per item, skipping unchanged items, JSON and JUnit reports."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from helpers import grid_face, make_bundle

from facegen.batch import Job, read_manifest
from facegen.batch_plan import STATE_NAME, check_plan
from facegen.batch_run import run_manifest
from facegen.errors import FacegenError

REPO = Path(__file__).resolve().parents[1]
SENTENCES = ("What an excellent room you have, sir.", "Such expensive furnishings!",
             "We were amazed to find the old bakery still open.")


def cli(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "facegen", *args], capture_output=True, text=True,
                          timeout=600,
                          cwd=REPO, check=False, env=env)


@pytest.fixture(scope="module")
def speech(tmp_path_factory):
    """Three espeak sentences as 16 kHz WAVs (an audio-only model needs no transcript)."""
    from facegen.espeak import synthesize

    folder = tmp_path_factory.mktemp("speech")
    for i, sentence in enumerate(SENTENCES):
        sf.write(folder / f"s{i}.wav", synthesize(sentence, pitch=40 + 10 * i, sample_rate=16000).audio,
                 16000,
                 subtype="PCM_16")
    return folder


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    """A small audio-only bundle on a 120-vertex grid face, saved (workers load it from the file)."""
    path = tmp_path_factory.mktemp("model") / "small.safetensors"
    make_bundle(grid_face(12, 10, height=0.8, bend=2.0), path, modalities="audio", speakers=("F2", "M3"))
    return path


def write_manifest(folder: Path, rows: list[str], name: str = "lines.csv") -> Path:
    path = folder / name
    path.write_text("audio,speaker,output\n" + "\n".join(rows) + "\n")
    return path


# ---------------------------------------------------------------------------------------------------------
# manifests and plans: refused before any work, with the line


def test_manifest_errors_name_their_line(tmp_path):
    bad = {
        "audio,output\na.wav,a.npy\nb.wav,b.npy,extra\n": "line 3: 3 fields where the header has 2",
        "audio,words\na.wav,hi\n": "line 1: unknown column(s) words",
        "audio,output\na.wav,a.npy\n\nb.wav,b.fbx\n": "line 4: cannot handle 'b.fbx'",
        "audio,text,alignment\na.wav,hi,a.json\n": "line 2: give one of text, text_file or alignment",
        "audio,output\n,a.npy\n": "line 2: no audio file given",
        '[\n {"audio": "a.wav"},\n\n {"audio": "b.wav", "output": "b.xyz"}\n]':
            "line 4: cannot handle 'b.xyz'",
        '{"name": "x",\n "jobs": [{"audio": "a.wav"},\n  {"output": "b.npy"}]}':
            "line 3: no audio file given",
        '{"audio": "a.wav"}\n{"audio": "b.wav", "output": "b.npy"}\n{"audio": \n': "line 3: not valid JSON",
        '[{"audio": "a.wav"},\n {"audio": "b.wav",}]': "line 2: not valid JSON",
        '[{"audio": "a.wav"},\n ["b.wav"]]': "line 2: expected an object",
        '{"jobs": 3}': "must be a list of objects",
    }
    for n, (text, message) in enumerate(bad.items()):
        (tmp_path / f"m{n}.csv").write_text(text)
        with pytest.raises(FacegenError, match=message.replace("(", r"\(").replace(")", r"\)")):
            read_manifest(tmp_path / f"m{n}.csv")


def test_manifest_formats_lines_and_json_lines(tmp_path):
    (tmp_path / "t.txt").write_text("Hello there.")
    path = tmp_path / "m.jsonl"
    path.write_text('{"audio": "a.wav", "text_file": "t.txt", "output": "x/a.usdc"}\n\n'
                    '{"audio": "b.wav", "speaker": 1, "text_file": "missing.txt"}\n')
    a, b = read_manifest(path, outdir=tmp_path / "o", formats=[".usdc", ".glb", ".json"])
    assert (a.line, b.line) == (1, 3)
    assert a.targets == tuple(tmp_path / "o" / "x" / f"a{e}" for e in (".usdc", ".glb", ".json"))
    assert a.output == a.targets[0] and a.text == "Hello there." and a.problem is None
    assert b.speaker == "1" and b.targets[1] == tmp_path / "o" / "b.glb"
    assert b.problem.startswith("cannot read transcript file missing.txt")  # only its row fails


def job(out: Path, name: str, line: int, audio: str = "in.wav", formats=()) -> Job:
    target = out / name
    return Job(audio=out.parent / audio, output=target, line=line,
               outputs=tuple(target.with_suffix(e) for e in formats))


def test_plans_that_lose_or_misplace_a_clip_are_refused(tmp_path):
    out = tmp_path / "out"
    check_plan([job(out, "a.usdc", 2, formats=(".usdc", ".glb", ".json")), job(out, "sub/a.usdc", 3)], out)
    refused = {
        "also the output of line 2": [job(out, "a.usdc", 2), job(out, "x/../a.usdc", 3)],
        "shares its audio sidecar a.wav with line 2": [job(out, "a.usdc", 2), job(out, "a.glb", 3)],
        "outside the output folder": [job(out, "../a.usdc", 2)],
        "is outside": [job(out, "/tmp/elsewhere/a.usdc", 2)],
        "would overwrite the audio of line 3": [job(out, "a.usdc", 2), job(out, "b.usdc", 3,
                                                                           audio="out/a.wav")],
        "is an input of line 3": [job(out, "a.json", 2),
                                  Job(audio=tmp_path / "b.wav", output=out / "b.npy", line=3,
                                      alignment=out / "a.json")],
        "the batch's own report.json": [job(out, "report.json", 2)],
    }
    for message, jobs in refused.items():
        with pytest.raises(FacegenError, match=message):
            check_plan(jobs, out)


def test_cli_refuses_bad_plans_and_options_before_any_work(speech, tmp_path):
    cases = {
        "jobs 0": (["audio,output", "s0.wav,a.npy"], ["--jobs", "0"], "--jobs"),
        "malformed": (["audio,output", "s0.wav,a.npy", "s1.wav,b.npy,x"], [], "line 3: 3 fields"),
        "escape": (["audio,output", "s0.wav,../a.npy"], [], "line 2: output"),
        "duplicate": (["audio,output", "s0.wav,a.npy", "s1.wav,a.npy"], [], "line 3: output"),
        "shared sidecar": (["audio,output", "s0.wav,a.npy", "s1.wav,a.usdc"], [], "shares its audio sidecar"),
        "formats": (["audio,output", "s0.wav,a.npy"], ["--formats", "usdc,fbx"], "unknown extension '.fbx'"),
        "no ray": (["audio,output", "s0.wav,a.npy"], ["--engine", "ray"], "needs Ray"),
    }
    blocked = tmp_path / "blocked"  # a `ray` that cannot be imported, as when the extra is not installed
    blocked.mkdir()
    (blocked / "ray.py").write_text("raise ImportError('no ray here')\n")
    for name, (rows, options, message) in cases.items():
        manifest = speech / f"{name.replace(' ', '_')}.csv"
        manifest.write_text("\n".join(rows) + "\n")
        out = tmp_path / name.replace(" ", "_")
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(blocked), str(REPO)]))
        proc = cli("batch", str(manifest), "-o", str(out), *options, env=env)
        assert proc.returncode == 2, (name, proc.stderr)
        assert len(proc.stderr.strip().splitlines()) == 1 and message in proc.stderr, (name, proc.stderr)
        assert not out.exists() or not any(out.iterdir()), name  # nothing written


# ---------------------------------------------------------------------------------------------------------
# runs: worker processes, formats, validation, reports, skipping


def test_batch_in_worker_processes_writes_validates_reports_and_skips(speech, model, tmp_path):
    from facegen import animate
    from facegen.bundle import load_bundle

    manifest = write_manifest(speech, ["s0.wav,F2,a/s0.npy", "s1.wav,M3,s1.npy", "nothere.wav,,gone.npy",
                                       "s2.wav,Z9,bad.npy", "s2.wav,1,s2.npy"])
    out = tmp_path / "out"
    seen = []
    outcome = run_manifest(manifest, out, jobs=2, formats="npy,glb", model=model, device="cpu",
                           on_result=seen.append)
    statuses = [r.status for r in outcome.results]
    assert statuses == ["passed", "passed", "error", "error", "passed"] and not outcome.ok
    assert sorted(r.job.line for r in seen) == [2, 3, 4, 5, 6]
    assert "nothere.wav" in outcome.results[2].error and "unknown speaker 'Z9'" in outcome.results[3].error
    bundle = load_bundle(model)
    for r, (wav, speaker) in zip(outcome.results[::4], [("s0.wav", "F2"), ("s2.wav", "1")], strict=True):
        # the worker's file equals a run of the library in this process
        alone = animate(speech / wav, bundle=bundle, speaker=speaker, device="cpu")
        frames = np.load(r.job.targets[0]).reshape(alone.vertices.shape)
        assert np.abs(frames - alone.vertices).max() < 1e-5
        assert [Path(v["file"]).suffix for v in r.validation] == [".npy", ".glb"]
        assert all(v["ok"] for v in r.validation) and r.frames == len(frames)
    assert {p.name for p in (out / "a").iterdir()} == {"s0.npy", "s0.glb", "s0.wav"}

    report = json.loads((out / "report.json").read_text())
    assert report["summary"] == {"passed": 3, "failed": 0, "error": 2, "skipped": 0, "flagged": 0}
    assert [(i["line"], i["output"], i["status"]) for i in report["items"]][:3] == [
        (2, "a/s0.npy", "passed"), (3, "s1.npy", "passed"), (4, "gone.npy", "error")]
    suite = ET.parse(out / "report.xml").getroot().find("testsuite")
    assert (suite.get("tests"), suite.get("errors"), suite.get("failures")) == ("5", "2", "0")
    cases = suite.findall("testcase")
    assert [c.get("line") for c in cases] == ["2", "3", "4", "5", "6"]
    assert cases[3].find("error").get("message").startswith("unknown speaker 'Z9'")
    assert cases[0].find("error") is None and "a/s0.glb: ok" in cases[0].find("system-out").text

    # a second run skips what is unchanged; a changed input, a touched output and --force run again
    mtime = (out / "s1.npy").stat().st_mtime_ns
    again = run_manifest(manifest, out, jobs=1, formats="npy,glb", model=model, device="cpu")
    assert [r.status for r in again.results] == ["skipped", "skipped", "error", "error", "skipped"]
    assert (out / "s1.npy").stat().st_mtime_ns == mtime
    assert ET.parse(out / "report.xml").getroot().find("testsuite").get("skipped") == "3"
    (out / "s2.glb").unlink()
    manifest.write_text(manifest.read_text().replace("s1.wav,M3", "s1.wav,F2"))
    third = run_manifest(manifest, out, jobs=1, formats="npy,glb", model=model, device="cpu")
    assert [r.status for r in third.results] == ["skipped", "passed", "error", "error", "passed"]
    assert (out / "s2.glb").is_file()
    forced = run_manifest(manifest, out, jobs=1, formats="npy,glb", model=model, device="cpu", force=True)
    assert [r.status for r in forced.results] == ["passed", "passed", "error", "error", "passed"]
    state = json.loads((out / STATE_NAME).read_text())
    assert sorted(state["items"]) == ["a/s0.npy", "s1.npy", "s2.npy"]


def _live_forkservers() -> list[int]:
    """The ids of this process's children that run multiprocessing's forkserver and have not exited."""
    live = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()  # state, parent, ...
            command = (stat.parent / "cmdline").read_bytes()
        except (OSError, IndexError):  # gone meanwhile
            continue
        if int(fields[1]) == os.getpid() and fields[0] not in "ZX" and b"forkserver" in command:
            live.append(int(stat.parent.name))
    return live


def test_the_main_process_aligns_waiting_items_as_a_worker_would(speech, tmp_path):
    """With transcripts, the main process force-aligns the last waiting items while the workers start: their
    files equal the library's run in this process, and a wrong transcript is that item's error, the same
    line."""
    from facegen import animate
    from facegen.batch import one_line

    wrong = "Seven purple elephants were dancing slowly across the frozen river."
    rows = [(f"s{i}.wav", SENTENCES[i]) for i in (0, 1, 2, 0)] + [("s2.wav", wrong)]
    manifest = speech / "texts.csv"
    with open(manifest, "w", newline="") as f:
        csv.writer(f).writerows([("audio", "text", "output")] + [(a, t, f"{n}-{a[:2]}.npy")
                                                                  for n, (a, t) in enumerate(rows)])
    # the default model: words and phones
    outcome = run_manifest(manifest, tmp_path / "out", jobs=2, device="cpu")
    assert [r.status for r in outcome.results] == ["passed"] * 4 + ["error"]
    if Path("/proc").is_dir():  # the forkserver is stopped at the end: its teardown would hold our pipes
        assert _live_forkservers() == []
    last = outcome.results[-1]
    # the last chunk waits until a worker is free: the main process aligned it
    assert last.job.aligned is not None
    assert last.seconds >= last.job.aligned.seconds > 0
    with pytest.raises(FacegenError) as here:
        animate(speech / "s2.wav", text=wrong, device="cpu")
    assert last.error == one_line(here.value)
    for r in outcome.results[:4]:
        alone = animate(r.job.audio, text=r.job.text, device="cpu")
        assert np.abs(np.load(r.job.output).reshape(alone.vertices.shape) - alone.vertices).max() < 1e-5


def test_failed_validation_is_a_junit_failure_and_exit_1(speech, tmp_path):
    """A model that throws the face far beyond the rest pose: written, but `validate` fails it."""
    wild = tmp_path / "wild.safetensors"
    make_bundle(grid_face(12, 10, height=0.8, bend=2.0), wild, modalities="audio", scale=5.0)
    manifest = write_manifest(speech, ["s0.wav,,s0.npy", "s9.wav,,s9.npy"], name="wild.csv")
    out = tmp_path / "out"
    proc = cli("batch", str(manifest), "-o", str(out), "-m", str(wild), "--device", "cpu", "-j", "1")
    assert proc.returncode == 1, proc.stderr
    assert proc.stdout.strip().splitlines()[-1].startswith("2 items in ")
    assert "0 passed, 1 failed, 1 error" in proc.stdout
    assert "line 2:" in proc.stderr and "line 3:" in proc.stderr
    case = ET.parse(out / "report.xml").getroot().find("testsuite").findall("testcase")[0]
    failure = case.find("failure")
    assert failure is not None and failure.get("type") == "validation" and "s0.npy" in failure.get("message")
    assert (out / "s0.npy").is_file()  # the file is kept for inspection; the state does not count it as done
    assert "s0.npy" not in json.loads((out / STATE_NAME).read_text())["items"]


def test_a_worker_limits_every_thread_pool_it_computes_with():
    import torch
    from pxr import Work
    from threadpoolctl import threadpool_info, threadpool_limits

    from facegen.engines import limit_threads

    before = torch.get_num_threads(), Work.GetConcurrencyLimit()
    try:
        with threadpool_limits():  # restores the BLAS and OpenMP pools afterwards
            limit_threads(1)
            assert torch.get_num_threads() == 1 and Work.GetConcurrencyLimit() == 1
            assert {pool["num_threads"] for pool in threadpool_info()} == {1}
    finally:
        torch.set_num_threads(before[0])
        Work.SetConcurrencyLimit(before[1])


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="counts threads through /proc")
def test_the_forkserver_preload_starts_no_thread_and_builds_the_decoders():
    """Workers are forked from a process that imported engines.PRELOAD: it may start no thread (Python's or
    native: an OpenMP or TBB pool does not survive a fork; OpenBLAS's, started with numpy, has fork handlers),
    and the aligner's decoders are built there, once."""
    code = ("import importlib, os, numpy; threads = len(os.listdir('/proc/self/task'))\n"
            "from facegen.engines import PRELOAD\n"
            "[importlib.import_module(m) for m in PRELOAD]\n"
            "from facegen import sphinx\n"
            "print(len(os.listdir('/proc/self/task')) - threads, sorted(sphinx.DECODERS))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=300,
                          check=False)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split(maxsplit=1) == ["0", "['align', 'cmn', 'phone-loop']\n"]
