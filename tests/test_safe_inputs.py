"""Memory-safe, path-safe inputs and outputs (issue 22): templates.pkl memory bombs refused in bounded memory;
FIFOs, devices and folders refused at once as every text input (transcript, alignment, manifest, a row's
transcript or audio); batch outputs that leave OUT through a symbolic link or land on one of the run's inputs
(also case-folded or in another Unicode form) refused before any work; malformed manifests (NUL bytes, huge
numbers, deep nesting, a key given twice) refused naming the line; batch workers that die with their parent.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
import soundfile as sf
from helpers import grid_face, make_bundle
from hostile import BOMBS, REFUSALS, REPO, alive, descendants, run_measured

from facegen.alignment_files import read_alignment, read_phones
from facegen.audio import load_audio
from facegen.batch import read_manifest
from facegen.batch_plan import check_plan, item_key
from facegen.cli.options import read_text
from facegen.errors import FacegenError

POSIX = pytest.mark.skipif(not hasattr(os, "mkfifo") or not Path("/dev/zero").exists(),
                           reason="FIFOs and /dev/zero")


@pytest.fixture
def deadline():
    """Fail (instead of hanging for ever) when a test's reads block for 20 s, e.g. opening a FIFO."""
    def expired(_signum, _frame):
        raise TimeoutError("blocked for 20 s")

    old = signal.signal(signal.SIGALRM, expired)
    signal.alarm(20)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, old)


def one_line(exc: pytest.ExceptionInfo) -> str:
    text = str(exc.value)
    assert "\n" not in text and text.strip() == text, text
    return text


# ---------------------------------------------------------------------------------------------------------
# templates.pkl: no array allocated before its shape is checked against the file's size

_BOMB_RUN = textwrap.dedent("""
    import json, resource, sys, time
    resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))  # a regression fails here, not the machine
    from facegen.datasets.templates import read_templates_pkl
    from facegen.errors import FacegenError
    found = {}
    for path in sys.argv[2:]:
        t0 = time.perf_counter()
        try:
            read_templates_pkl(path)
            said = None
        except FacegenError as exc:
            said = str(exc)
        found[path] = [said, time.perf_counter() - t0]
    with open(sys.argv[1], "w") as f:
        json.dump(found, f)
""")


@pytest.mark.skipif(sys.platform != "linux", reason="peak memory from Linux's ru_maxrss")
def test_templates_pkl_bombs_are_refused_before_any_allocation(tmp_path):
    paths = {}
    for n, (name, data) in enumerate(BOMBS.items()):
        assert len(data) < 160
        paths[name] = tmp_path / f"bomb{n}.pkl"
        paths[name].write_bytes(data)
    found = tmp_path / "found.json"
    command = [sys.executable, "-c", _BOMB_RUN, str(found), *map(str, paths.values())]
    code, err, _, peak = run_measured(command, timeout=60)
    assert code == 0, err
    report = json.loads(found.read_text())
    for name, path in paths.items():
        said, seconds = report[str(path)]
        assert said is not None and REFUSALS[name] in said, (name, said)
        assert "\n" not in said and "MemoryError" not in said, (name, said)
        assert seconds < 5, (name, seconds)  # 15 s and 4.27 GB before (the target, < 1 s: benchmarks)
    assert peak < 300, peak


def test_templates_pkl_of_every_numpy_pickle_protocol_still_reads(tmp_path):
    import pickle

    import numpy as np

    from facegen.datasets.templates import read_templates_pkl

    data = {"F1": np.arange(12, dtype=np.float64).reshape(4, 3), "M2": np.ones((2, 3), ">f4"),
            "F3": np.asfortranarray(np.arange(9, dtype=np.int16).reshape(3, 3))}
    for protocol in range(pickle.HIGHEST_PROTOCOL + 1):
        path = tmp_path / f"p{protocol}.pkl"
        path.write_bytes(pickle.dumps(data, protocol=protocol))
        back = read_templates_pkl(path)
        assert set(back) == set(data), protocol
        for key, value in data.items():
            np.testing.assert_array_equal(back[key], value.astype(np.float32))


# ---------------------------------------------------------------------------------------------------------
# special files as every text input: refused at once, one line


@pytest.fixture
def specials(tmp_path):
    """A FIFO nobody writes to, endless devices, a folder."""
    fifo = tmp_path / "pipe.txt"
    os.mkfifo(fifo)
    (tmp_path / "folder.txt").mkdir()
    return {"fifo": fifo, "zero": Path("/dev/zero"), "urandom": Path("/dev/urandom"),
            "folder": tmp_path / "folder.txt"}


KIND = {"fifo": "a named pipe (FIFO), not a regular file", "zero": "a character device, not a regular file",
        "urandom": "a character device, not a regular file", "folder": "a folder, not a regular file"}


@POSIX
def test_special_files_are_refused_as_every_text_input(specials, tmp_path, deadline):
    from facegen.datasets.templates import read_templates_pkl

    for kind, path in specials.items():
        readers = {"transcript": lambda p: read_text(None, str(p)), "alignment": read_alignment,
                   "phones": read_phones, "manifest": read_manifest, "templates": read_templates_pkl}
        for what, reader in readers.items():
            t0 = time.perf_counter()
            with pytest.raises(FacegenError) as info:
                reader(path)
            assert KIND[kind] in one_line(info) and str(path) in str(info.value), (kind, what)
            assert time.perf_counter() - t0 < 2, (kind, what)
        # a row's transcript: that row's error; a row's audio: that row's error before any work
        manifest = tmp_path / f"{kind}.csv"
        manifest.write_text(f"audio,text_file,output\na.wav,{path},a.npy\n{path},,b.npy\n")
        text_row, audio_row = read_manifest(manifest)
        assert text_row.problem.startswith(f"cannot read transcript file {path} ({KIND[kind]})")
        with pytest.raises(FacegenError, match=r"not a regular file\): fix the path in the manifest"):
            item_key(audio_row, tmp_path, {})
        with pytest.raises(FacegenError, match=f"{path} is not a file: pass an audio file"):
            load_audio(path)


@POSIX
def test_text_inputs_larger_than_their_bound_are_refused_without_reading_them(tmp_path):
    from facegen.input_files import MANIFEST_BYTES, TRANSCRIPT_BYTES

    big = tmp_path / "big.txt"
    with open(big, "wb") as f:
        f.truncate(5 * TRANSCRIPT_BYTES)  # sparse: nothing to read
    with pytest.raises(FacegenError, match=r"transcript file .*big.txt is 5.2 MB, more than facegen reads "
                                           r"\(1.0 MB\): split the recording") as info:
        read_text(None, str(big))
    assert info.value.param == "text"
    with open(big, "wb") as f:
        f.truncate(2 * MANIFEST_BYTES)
    with pytest.raises(FacegenError, match="manifest .* more than facegen reads .*: split it into several"):
        read_manifest(big)
    big.write_bytes(b"caf\xe9\n")
    with pytest.raises(FacegenError, match=r"is not UTF-8 text \(invalid continuation byte at byte 3\)"):
        read_text(None, str(big))


@POSIX
@pytest.mark.skipif(sys.platform != "linux", reason="peak memory from Linux's ru_maxrss")
def test_cli_refuses_special_files_in_one_line(specials, tmp_path):
    """The commands, as new processes: a FIFO or /dev/zero as the transcript or the manifest, and a batch
    whose rows' transcript and audio are special files (their errors in the report, exit 1)."""
    wav = tmp_path / "a.wav"
    sf.write(wav, [0.1, -0.1] * 8000, 16000)
    manifest = tmp_path / "rows.csv"
    manifest.write_text(f"audio,text_file,output\n{wav},{specials['fifo']},a.npy\n"
                        f"{specials['fifo']},,b.npy\n{wav},/dev/urandom,c.npy\n")
    runs = {
        "--text-file FIFO": ["animate", str(wav), "--text-file", str(specials["fifo"]), "-o",
                             str(tmp_path / "t.npy")],
        "--text-file /dev/zero": ["animate", str(wav), "--text-file", "/dev/zero", "-o",
                                  str(tmp_path / "z.npy")],
        "manifest FIFO": ["batch", str(specials["fifo"]), "-o", str(tmp_path / "o1")],
        "manifest /dev/zero": ["batch", "/dev/zero", "-o", str(tmp_path / "o2")],
    }
    for name, args in runs.items():
        code, err, seconds, peak = run_measured([sys.executable, "-m", "facegen", *args])
        assert code == 2 and len(err.strip().splitlines()) == 1, (name, code, err)
        assert "not a regular file" in err, (name, err)
        assert peak < 300, (name, peak)
        print(f"{name}: exit {code} in {seconds:.2f} s, peak {peak:.0f} MB")
    assert not any(tmp_path.glob("*.npy")) and not (tmp_path / "o1").exists()
    code, err, seconds, peak = run_measured([sys.executable, "-m", "facegen", "batch", str(manifest), "-o",
                                              str(tmp_path / "o3")])
    assert code == 1, err
    items = json.loads((tmp_path / "o3" / "report.json").read_text())["items"]
    assert [i["status"] for i in items] == ["error"] * 3
    assert all("not a regular file" in i["error"] for i in items), items
    assert peak < 300, peak
    print(f"batch of special rows: exit {code} in {seconds:.2f} s, peak {peak:.0f} MB")


# ---------------------------------------------------------------------------------------------------------
# batch outputs: never outside OUT, never over an input


def _plan(folder: Path, rows: str, name: str = "lines.csv", out: Path | None = None) -> None:
    manifest = folder / name
    manifest.write_text(rows)
    out = folder if out is None else out
    check_plan(read_manifest(manifest, outdir=out), out)


def test_outputs_through_symbolic_links_out_of_the_output_folder_are_refused(tmp_path):
    out, outside = tmp_path / "out", tmp_path / "outside"
    out.mkdir()
    outside.mkdir()
    (out / "abs").symlink_to(outside)
    (out / "rel").symlink_to("../outside")
    (out / "inner").symlink_to(out / "sub", target_is_directory=True)  # a link that stays inside is fine
    for link in ("abs", "rel"):
        escape = rf"line 2: output .*{link}/a.usdc leads outside the output folder .*, to "
        with pytest.raises(FacegenError, match=rf"{escape}{os.path.realpath(outside)}/a.usdc, through a sym"):
            _plan(tmp_path, f"audio,output\nin.wav,{link}/a.usdc\n", out=out)
    with pytest.raises(FacegenError, match="line 3: output .* leads outside"):  # ".." after a link
        _plan(tmp_path, "audio,output\nin.wav,a.usdc\nin.wav,abs/../b.usdc\n", out=out)
    _plan(tmp_path, "audio,output\nin.wav,inner/a.usdc\nin.wav,sub/b.usdc\n", out=out)
    with pytest.raises(FacegenError, match="line 3: output .* is also the output of line 2"):
        _plan(tmp_path, "audio,output\nin.wav,inner/a.usdc\nin.wav,sub/a.usdc\n", out=out)
    # the output folder itself may be a link
    (tmp_path / "out-link").symlink_to(out)
    _plan(tmp_path, "audio,output\nin.wav,a.usdc\n", out=tmp_path / "out-link")


def test_outputs_over_the_runs_inputs_are_refused_case_folded_and_normalised(tmp_path):
    (tmp_path / "line.json").write_text("Hello.")
    nfc, nfd = "caf\u00e9", "cafe\u0301"
    (tmp_path / f"{nfc}.json").write_text("Hello.")
    refused = {
        "audio,output\nin.wav,lines.csv\n": "line 2: output .*lines.csv is the manifest: writing it",
        "audio,output\nin.wav,Lines.csv\n":
            r"is the manifest \(.*Lines.csv and .*lines.csv are one file where names are compared without",
        "audio,text_file,output\nin.wav,line.json,a.npy\nb.wav,,line.json\n":
            r"line 3: output .*line.json is an input of line 2 \(its transcript file\)",
        "audio,text_file,output\nin.wav,line.json,LINE.json\n":
            "line 2: output .*LINE.json is an input of line 2",
        f"audio,text_file,output\nin.wav,{nfc}.json,a.npy\nb.wav,,{nfd}.json\n":
            "line 3: output .* is an input of line 2 .* one file where names are compared without case",
        "audio,output\nin.wav,A.npy\nb.wav,a.npy\n":
            "line 3: output .*a.npy is also the output of line 2 .*one file",
        "audio,output\nin.wav,x.npy\nb.wav,REPORT.json\n": "line 3: output .* is the batch's own report.json",
        "audio,output\nin.wav,IN.usdc\nb.wav,in.glb\n": "line 3: output .* shares its audio sidecar",
        "audio,output\nin.wav,x.npy\nb.wav,IN.usdc\n":
            "line 3: the audio sidecar of .*IN.usdc would overwrite the audio of line 2",
    }
    for rows, message in refused.items():
        with pytest.raises(FacegenError, match=message):
            _plan(tmp_path, rows)
    _plan(tmp_path, "audio,output\nin.wav,in.usdc\n")  # its own audio is no sidecar to write


def test_an_input_that_links_into_the_output_folder_is_protected(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "take.wav").write_bytes(b"RIFF")
    (tmp_path / "in.wav").symlink_to(out / "take.wav")  # a row's audio is a link to a file in OUT
    with pytest.raises(FacegenError, match="line 3: the audio sidecar of .*take.usdc would overwrite the "
                                           "audio of line 2"):
        _plan(tmp_path, "audio,output\nin.wav,x.npy\nother.wav,take.usdc\n", out=out)


def test_cli_refuses_an_escaping_plan_before_any_work(tmp_path):
    out, outside = tmp_path / "out", tmp_path / "outside"
    out.mkdir()
    outside.mkdir()
    (out / "link").symlink_to(outside)
    manifest = tmp_path / "lines.csv"
    manifest.write_text("audio,output\nin.wav,a.npy\nin.wav,link/b.npy\n")
    proc = subprocess.run([sys.executable, "-m", "facegen", "batch", str(manifest), "-o", str(out)],
                          capture_output=True, text=True, cwd=REPO, timeout=300, check=False)
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert "line 3: output" in proc.stderr and "leads outside the output folder" in proc.stderr
    assert list(outside.iterdir()) == [] and sorted(p.name for p in out.iterdir()) == ["link"]


# ---------------------------------------------------------------------------------------------------------
# malformed manifests: one line naming the line


def test_malformed_manifests_are_one_line_naming_the_line(tmp_path):
    huge = "9" * 5000
    bad = {
        "m.csv": ("audio,output\na.wav,a.npy\nb\0.wav,b.npy\n", "line 3: the audio path contains a NUL byte"),
        "m.json": ('[{"audio": "a.wav"},\n {"audio": "b.wav", "text_file": "t\\u0000.txt"}]',
                   "line 2: the text_file path contains a NUL byte"),
        "n.json": (f'[{{"audio": "a.wav"}},\n {{"audio": "b.wav", "speaker": {huge}}}]',
                   "line 2: the speaker 999999999999... is a 5000-digit number: give a speaker's name"),
        "n.jsonl": (f'{{"audio": "a.wav"}}\n{{"audio": "b.wav", "speaker": {huge}}}\n',
                    "line 2: the speaker 999999999999... is a 5000-digit number"),
        "d.json": ('[{"audio": "a.wav"},\n {"audio": ' + "[" * 100_000 + "]" * 100_000 + "}]",
                   "line 2: objects or lists nested too deeply"),
        "d.jsonl": ('{"audio": "a.wav"}\n\n{"audio": "b.wav", "x": ' + "[" * 100_000 + "\n",
                    "line 3: objects or lists nested too deeply"),
        "k.json": ('[{"audio": "a.wav",\n  "Audio": "b.wav"}]', "line 1: column audio given twice: keep one"),
        "k.jsonl": ('{"audio": "a.wav"}\n{"audio": "b.wav", "audio": "c.wav"}\n',
                    "line 2: column audio given twice"),
        "s.csv": ("audio\n/\n", "line 2: the audio path / names no file"),
    }
    for name, (text, message) in bad.items():
        path = tmp_path / name
        path.write_text(text)
        with pytest.raises(FacegenError, match=message.replace("(", r"\(").replace(")", r"\)")) as info:
            read_manifest(path)
        assert str(path) in one_line(info), name
    # numbers still read as before: an index as speaker
    path = tmp_path / "ok.json"
    path.write_text('[{"audio": "a.wav", "speaker": 1}, {"audio": "b.wav", "speaker": -2.5}]')
    assert [j.speaker for j in read_manifest(path)] == ["1", "-2.5"]


# ---------------------------------------------------------------------------------------------------------
# workers die with the batch


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")
def test_sigkill_of_the_batch_leaves_no_process_behind(tmp_path):
    from facegen.espeak import synthesize

    model = tmp_path / "small.safetensors"
    make_bundle(grid_face(12, 10, height=0.8, bend=2.0), model, modalities="audio", speakers=("F2", "M3"))
    speech = synthesize("We were amazed to find the old bakery still open.", sample_rate=16000).audio
    sf.write(tmp_path / "s.wav", speech, 16000)
    manifest = tmp_path / "lines.csv"
    manifest.write_text("audio,output\n" + "".join(f"s.wav,{n}.usdc\n" for n in range(3000)))  # minutes
    proc = subprocess.Popen([sys.executable, "-m", "facegen", "batch", str(manifest), "-o",
                             str(tmp_path / "out"), "--jobs", "2", "-m", str(model), "--device", "cpu", "-q"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=REPO)
    try:
        deadline = time.monotonic() + 300
        while True:  # the workers run once the forkserver has children
            family = descendants(proc.pid)
            if sum(len(descendants(child)) for child in family) >= 2 or proc.poll() is not None:
                break
            assert time.monotonic() < deadline, "no workers started"
            time.sleep(0.1)
        assert proc.poll() is None, "the batch finished before it was killed: give it more rows"
        time.sleep(1.0)  # at work
        family = descendants(proc.pid)
        assert proc.poll() is None, "the batch finished before it was killed: give it more rows"
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        proc.kill()
        proc.wait()
    assert len(family) >= 3  # the forkserver and two workers (and multiprocessing's resource tracker)
    deadline = time.monotonic() + 5
    while any(alive(pid, start) for pid, start in family.items()) and time.monotonic() < deadline:
        time.sleep(0.1)
    left = [pid for pid, start in family.items() if alive(pid, start)]
    for pid in left:  # not for the next test
        os.kill(pid, signal.SIGKILL)
    assert left == [], f"{len(left)} of {len(family)} processes outlived the batch by 5 s"
