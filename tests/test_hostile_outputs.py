"""Tampered ARKit weight files through `facegen validate` and the Blender helper (issue 22's hostile sweep).

Well-formed files with bad values are validation findings: exit 1 and a FAIL line naming the problem (a
weight written as text, a trackPath that is a number or names /dev/zero or a FIFO, a CSV timecode 1e400, a
2-hour track for a 4-second file). Files facegen cannot read are a failed "file" check (exit 1): nested
100,000 deep, 1,000,000 frames at 25 fps (11 hours, past the 4 hours facegen reads), larger than 512 MB;
a path that is no regular file is one line, exit 2. The Blender helper refuses all of these, and `--fps
inf|nan|0|-5`, `--save` into a missing folder or onto a folder, with one line, exit 2, no traceback, nothing
saved, before Blender starts. `build_cases` makes the cases; benchmarks/bench_hostile_outputs.py times them.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from facegen.arkit.names import ARKIT_NAMES, LIVE_LINK_COLUMNS
from facegen.audio import write_wav

REPO = Path(__file__).resolve().parents[1]
BLENDER_PYTHON = REPO / ".venv-blender" / "bin" / "python"
HELPER = REPO / "facegen" / "blender" / "facegen_import.py"
FPS = 25
FRAMES = 100  # 4 s
AUDIO = ("audio", "audio duration")  # a track that cannot be read, and so no duration to compare


@dataclass
class Case:
    name: str
    tool: str  # "validate" (python -m facegen validate ...) or "blender" (the helper in .venv-blender)
    args: list[str]
    exit: int
    says: str  # in the FAIL line (validate, exit 1) or the one error line
    checks: tuple[str, ...] = ()  # validate: the failed checks (exit 1), the first saying `says`

    def command(self) -> list[str]:
        if self.tool == "validate":
            return [sys.executable, "-m", "facegen", "validate", *self.args]
        return [str(BLENDER_PYTHON), str(HELPER), *self.args]


def audio2face(frames: int = FRAMES, **changes) -> dict:
    """An Audio2Face document of `frames` frames (weights 0.1 .. 0.6), with `changes` to its keys."""
    weights = np.linspace(0.1, 0.6, frames * 52).reshape(frames, 52).round(5)
    doc = {"exportFps": FPS, "trackPath": "", "numPoses": 52, "numFrames": frames,
           "facsNames": list(ARKIT_NAMES), "weightMat": weights.tolist()}
    doc.update(changes)
    return doc


def write_json(path: Path, doc: dict) -> Path:
    path.write_text(json.dumps(doc))
    return path


def write_rows(path: Path, frames: int, row: str = ",".join(["0"] * 52), head: str = "") -> Path:
    """An Audio2Face JSON of `frames` identical rows, written a piece at a time (10**6 rows: 105 MB)."""
    with open(path, "w") as f:
        f.write(f'{{"exportFps": {FPS}, {head}"numPoses": 52, "facsNames": {json.dumps(list(ARKIT_NAMES))}, '
                '"weightMat": [')
        f.writelines(("," if done else "") + ",".join([f"[{row}]"] * min(1000, frames - done))
                     for done in range(0, frames, 1000))
        f.write("]}\n")
    return path


def live_link(path: Path, frames: int = FRAMES, timecode: dict[int, str] | None = None) -> Path:
    """A Live Link Face CSV of `frames` rows at 25 fps; `timecode` replaces the Timecode of some rows."""
    lines = [",".join(LIVE_LINK_COLUMNS)]
    for i in range(frames):
        cell = (timecode or {}).get(i, f"00:00:{i // FPS:02d}:{i % FPS:02d}.000")
        lines.append(",".join([cell, "61", *["0.25"] * 52, *["0"] * 9]))
    path.write_text("\n".join(lines) + "\n")
    return path


def long_wav(path: Path, seconds: float = 7200, rate: int = 48000, channels: int = 2) -> Path:
    """A 16-bit WAV of `seconds` of silence (2 h, 48 kHz stereo: 1.4 GB) made in no time: its header from
    soundfile, its samples a sparse extension of the file (zeros)."""
    write_wav(np.zeros(0, np.float32), rate, path)  # the header of an empty WAV, then fix its sizes
    data = int(seconds * rate) * channels * 2
    header = bytearray(path.read_bytes()[:44])
    header[4:8] = (36 + data).to_bytes(4, "little")
    header[22:24] = channels.to_bytes(2, "little")
    header[28:32] = (rate * channels * 2).to_bytes(4, "little")
    header[32:34] = (channels * 2).to_bytes(2, "little")
    header[40:44] = data.to_bytes(4, "little")
    with open(path, "wb") as f:
        f.write(header)
        f.truncate(44 + data)
    return path


def build_cases(folder: Path) -> list[Case]:
    """The hostile sweep's ARKit cases as files in `folder`, and what each must give."""
    folder.mkdir(parents=True, exist_ok=True)
    fifo = folder / "pipe.wav"
    if not fifo.exists():
        os.mkfifo(fifo)
    doc = audio2face()
    doc["weightMat"][1][5] = "0.5"
    text_weight = write_json(folder / "text_weight.json", doc)
    write_wav(np.full(FRAMES * 16000 // FPS, 0.01, np.float32), 16000, folder / "speech.wav")
    deep = folder / "deep.json"
    deep.write_text('{"exportFps": 25, "weightMat": ' + "[" * 100_000 + "]" * 100_000 + "}")
    huge = write_rows(folder / "million.json", 10**6, head='"numFrames": 1000000, ')
    unstated = write_rows(folder / "unstated.json", 10_000).read_text().replace(
        '"exportFps": 25', '"exportFps": 0.25')  # 10,000 frames at 0.25 fps: 11 hours, no numFrames
    (folder / "unstated.json").write_text(unstated)
    big = folder / "big.json"
    big.write_text('{"exportFps": 25, "weightMat": [[0]]}' + " " * 1000)
    with open(big, "r+b") as f:
        f.truncate(600 << 20)  # 600 MB (sparse): white space after the object
    long_wav(folder / "long.wav")
    cases = [
        Case("weight as text", "validate", [str(text_weight), "--no-audio-required"], 1,
             "weightMat row 1, weight 5 is '0.5'", ("finite",)),
        Case("trackPath /dev/zero", "validate", [str(write_json(folder / "zero.json", audio2face(
            trackPath="/dev/zero")))], 1, "a character device, not a regular file", AUDIO),
        Case("trackPath FIFO", "validate", [str(write_json(folder / "fifo.json", audio2face(
            trackPath=fifo.name)))], 1, "a named pipe (FIFO), not a regular file", AUDIO),
        Case("trackPath number", "validate", [str(write_json(folder / "number.json", audio2face(
            trackPath=5)))], 1, "trackPath is 5, not the path of an audio file", AUDIO),
        Case("trackPath 1.4 GB WAV", "validate", [str(write_json(folder / "long.json", audio2face(
            trackPath="long.wav")))], 1, "audio 7200.000 s", ("audio duration",)),
        Case("CSV timecode 1e400", "validate", [str(live_link(folder / "e400.csv", timecode={5: "1e400"})),
                                                "--no-audio-required"], 1,
             "row 6: '1e400' is not HH:MM:SS:FF[.mmm]", ("timecode",)),
        Case("CSV frame 10^400", "validate", [str(live_link(folder / "f400.csv", timecode={
            FRAMES - 1: "00:00:03:1" + "0" * 400})), "--no-audio-required"], 1,
             "is not HH:MM:SS:FF[.mmm]", ("timecode",)),
        Case("JSON nested 100,000 deep", "validate", [str(deep)], 1, "nested too deeply", ("file",)),
        Case("JSON 1,000,000 frames", "validate", [str(huge)], 1,
             "1,000,000 frames, 11.1 hours at 25 fps; facegen reads ARKit weights of up to 4 hours",
             ("file",)),
        Case("JSON 11 h, numFrames unstated", "validate", [str(folder / "unstated.json")], 1,
             "more than 4,096 frames, 4.6 hours at 0.25 fps", ("file",)),
        Case("JSON 600 MB", "validate", [str(big)], 1,
             "is 629 MB, more than facegen reads as ARKit weights (512 MB", ("file",)),
        Case("validate a FIFO", "validate", [str(fifo)], 2, "pipe.wav"),
        Case("validate /dev/zero", "validate", ["/dev/zero"], 2, "/dev/zero"),
    ]
    good = write_json(folder / "good.json", audio2face())
    cases += [
        Case(f"--fps {fps}", "blender", [str(good), "--fps", fps], 2, "the frame rate must be a number")
        for fps in ("inf", "nan", "0", "-5")]
    cases += [
        Case("--save into a missing folder", "blender", [str(good), "--save", str(folder / "no" / "a.blend")],
             2, "does not exist: create it first"),
        Case("--save onto a folder", "blender", [str(good), "--save", str(folder)], 2, "it is a folder"),
        Case("helper: JSON 1,000,000 frames", "blender", [str(huge), "--save", str(folder / "a.blend")], 2,
             "million.json: it holds 1,000,000 frames, 11.1 hours at 25 fps"),
        Case("helper: JSON 600 MB", "blender", [str(big)], 2, "big.json: it is 629 MB"),
        Case("helper: JSON nested 100,000 deep", "blender", [str(deep)], 2, "nested too deeply"),
        Case("helper: weight as text", "blender", [str(text_weight)], 2, "weightMat row 1 holds '0.5'"),
        Case("helper: CSV timecode 1e400", "blender", [str(folder / "e400.csv")], 2,
             "a Timecode '1e400' that is not HH:MM:SS:FF.mmm"),
        Case("helper: a FIFO", "blender", [str(fifo)], 2, "not a regular file"),
        Case("helper: /dev/zero", "blender", ["/dev/zero"], 2, "not a regular file"),
    ]
    return cases


def run_case(case: Case, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run(case.command(), capture_output=True, text=True, timeout=timeout, cwd=REPO,
                          check=False)


def outcome(case: Case, done: subprocess.CompletedProcess) -> str | None:
    """What is wrong with how `case` ended (None: as it must): exit code; validate's findings (exit 1) a
    FAIL line of the one failed check naming the problem; every refusal (exit 2) one line on stderr; never
    a traceback."""
    if done.returncode != case.exit:
        return f"exit {done.returncode}, not {case.exit}: {done.stderr[-500:]}"
    if "Traceback" in done.stderr or "internal error" in done.stderr:
        return f"a traceback: {done.stderr[-500:]}"
    if case.exit == 1:
        lines = {line.strip()[6:].split("  ")[0]: line for line in done.stdout.splitlines()
                 if line.strip().startswith("FAIL")}
        if tuple(lines) != case.checks:
            return f"failed {list(lines.values())}, not {case.checks}"
        if case.says not in lines[case.checks[0]]:
            return f"{lines[case.checks[0]]!r} does not say {case.says!r}"
        return None
    lines = done.stderr.strip().splitlines()
    if len(lines) != 1 or case.says not in lines[0]:
        return f"not one line saying {case.says!r}: {done.stderr[-500:]}"
    return None


@pytest.fixture(scope="module")
def cases(tmp_path_factory):
    if not hasattr(os, "mkfifo") or not Path("/dev/zero").exists():
        pytest.skip("FIFOs and /dev/zero")
    folder = tmp_path_factory.mktemp("hostile_outputs")
    yield folder, build_cases(folder)
    for name in ("million.json", "big.json", "long.wav"):  # 105 MB, and two sparse files
        (folder / name).unlink()


def test_validate_finds_tampered_arkit_files(cases):
    _, found = cases
    wrong = {c.name: outcome(c, run_case(c)) for c in found if c.tool == "validate"}
    assert {name: problem for name, problem in wrong.items() if problem} == {}
    assert len(wrong) == 13


def test_blender_helper_refuses_in_one_line_before_blender(cases):
    if not BLENDER_PYTHON.is_file():
        pytest.skip(f"{BLENDER_PYTHON} is missing: run `make blender-venv`")
    folder, found = cases
    before = sorted(p.name for p in folder.rglob("*"))
    wrong = {c.name: outcome(c, run_case(c)) for c in found if c.tool == "blender"}
    assert {name: problem for name, problem in wrong.items() if problem} == {}
    assert len(wrong) == 13
    assert sorted(p.name for p in folder.rglob("*")) == before  # nothing saved, no folder made


# ---- the bounded reader itself -----------------------------------------------------------------------------


def _read(text: str, piece: int, monkeypatch) -> tuple[dict, list, int | None]:
    from facegen.exchange import arkit_read

    monkeypatch.setattr(arkit_read, "_PIECE", piece)
    rows: list = []
    path = Path(os.environ.get("TMPDIR", "/tmp")) / f"facegen_read_{os.getpid()}.json"
    path.write_text(text)
    try:
        with open(path, "rb") as f:
            doc, count = arkit_read.read_json(f, rows.extend)
    finally:
        path.unlink()
    return doc, rows, count


def test_read_json_equals_json_loads_at_every_cut(monkeypatch):
    """Pieces of 1, 2, 3, 7 characters cut every value somewhere (a number "1.5e|-07", a string, a key,
    "Infinity"): the document and the rows are json.loads's."""
    rows = [[0, 1, 0.5, 1e-05, -2.25e-07, 123456789012345678, "x]", True, None, [1, [2]], float("inf")],
            [], [{"a": 1}], 7]
    doc = {"exportFps": 30.5, "trackPath": 'a"]b,}', "numFrames": 4, "facsNames": ["jawOpen"],
           "weightMat": rows, "facegen": {"audio": None, "x": [1, {"y": "z"}]}, "é": "ü"}
    for text in (json.dumps(doc), json.dumps(doc, indent=2), json.dumps(doc, separators=(",", ":"))):
        for piece in (1, 2, 3, 7, 1 << 20):
            head, got, count = _read(text, piece, monkeypatch)
            assert head == {k: v for k, v in json.loads(text).items() if k != "weightMat"}
            assert json.dumps(got) == json.dumps(json.loads(text)["weightMat"]) and count == 4


@pytest.mark.parametrize("text, says", [
    ("[1, 2]", "not a JSON object"),
    ('{"a" 1}', "expected ':' after the key 'a'"),
    ('{"a": 1,}', "expected a key in double quotes at character 8"),
    ('{"a": 1} x', "more text after the object"),
    ('{"weightMat": [[1] [2]]}', "expected ',' or ']' after weightMat row 0"),
    ('{"weightMat": [], "weightMat": []}', "weightMat is given twice"),
    ('{"numFrames": ' + "9" * 5000 + "}", "a number of thousands of digits"),
    ('{"a": ' + "[" * 100_000 + "]" * 100_000 + "}", "nested too deeply"),
    ('{"weightMat": [' + "[" * 100_000 + "]" * 100_000 + "]}", "nested too deeply"),
    ('{"exportFps": 25, "numFrames": 360001}', "360,001 frames, 4.0 hours at 25 fps"),
    ('{"numFrames": 3456001}', "3,456,001 frames, 4.0 hours at 240 fps (it states no rate"),
    ('{"numFrames": 1e999999, "exportFps": 25}', None),  # inf frames: not a count, the rows are counted
])
def test_read_json_refuses_in_one_line(monkeypatch, text, says):
    from facegen.exchange import arkit_read

    for piece in (3, 1 << 20):
        if says is None:
            assert _read(text, piece, monkeypatch)[2] is None
            continue
        with pytest.raises((arkit_read.NotJson, arkit_read.TooLarge)) as info:
            _read(text, piece, monkeypatch)
        assert says in str(info.value) and "\n" not in str(info.value)


def test_same_bounds_everywhere(tmp_path):
    """The helper reads with the very file validate reads with (the add-on zip carries it), and its bounds
    are facegen's: the longest audio, the highest output rate."""
    import zipfile

    from facegen.animation import MAX_FPS
    from facegen.audio import MAX_SECONDS
    from facegen.blender import facegen_arkit
    from facegen.blender.package import ADDON_MODULE, write_addon
    from facegen.exchange import arkit_read

    assert (arkit_read.MAX_SECONDS, arkit_read.MAX_FPS) == (MAX_SECONDS, MAX_FPS)
    assert Path(facegen_arkit.READ.__file__).resolve() == Path(arkit_read.__file__).resolve()
    with zipfile.ZipFile(write_addon(tmp_path / "addon.zip")) as archive:
        assert archive.read(f"{ADDON_MODULE}/arkit_read.py") == Path(arkit_read.__file__).read_bytes()


def test_validate_says_each_tampered_value(tmp_path):
    """Findings name the value: a weight as text, true and null; a weight past float range; a bad trackPath in
    the facegen key; a track that is a folder. A good file stays OK, its findings' numbers exact."""
    from facegen.validate import validate

    good = validate(write_json(tmp_path / "good.json", audio2face()), require_audio=False)
    assert good.ok and good.check("finite").detail == "5200 weights are finite numbers"
    assert good.check("range").detail == "weights 0.1 .. 0.6, within [0, 1]"
    doc = audio2face()
    doc["weightMat"][3][7], doc["weightMat"][4][0], doc["weightMat"][9][51] = True, None, 10**400
    report = validate(write_json(tmp_path / "kinds.json", doc), require_audio=False)
    assert [c.name for c in report.failures] == ["finite"]
    assert report.check("finite").detail == ("3 of 5200 weights are not finite numbers (weightMat row 3, "
                                             "weight 7 is True)")
    (tmp_path / "folder.wav").mkdir()
    for track, says in (("folder.wav", "a folder, not a regular file"), ("a\0b.wav", "contains a NUL byte"),
                        (["x.wav"], "facegen.audio is ['x.wav'], not the path")):
        report = validate(write_json(tmp_path / "t.json", audio2face(facegen={"audio": track})))
        assert [c.name for c in report.failures] == ["audio", "audio duration"], report.to_text()
        assert says in report.check("audio").detail and "\n" not in report.check("audio").detail


def test_audio_length_is_load_audios_length_without_the_samples(tmp_path):
    from facegen.audio import load_audio
    from facegen.errors import FacegenError
    from facegen.validate.checks import audio_length

    example = REPO / "examples" / "excellent_room.wav"
    samples, rate = load_audio(example)
    assert audio_length(example) == (len(samples), rate)
    write_wav(np.array([0.1, np.nan, 0.2], np.float32), 16000, tmp_path / "nan.wav", subtype="FLOAT")
    with pytest.raises(FacegenError, match="NaN or infinite samples"):
        audio_length(tmp_path / "nan.wav")
    long_wav(tmp_path / "long.wav", seconds=4 * 3600 + 1, rate=8000, channels=1)
    with pytest.raises(FacegenError, match="4.0 hours long; facegen animates up to 4 hours"):
        audio_length(tmp_path / "long.wav")
    assert audio_length(long_wav(tmp_path / "long.wav", seconds=3600, rate=8000, channels=1)) == (
        3600 * 8000, 8000)


def test_csv_bounds_are_the_same_in_validate_and_the_helper(tmp_path):
    """Timecodes spanning 5 hours, a line of 2 MB: validate's "file" finding and the helper's one line say
    the same bound."""
    from facegen.blender import facegen_arkit
    from facegen.validate import validate

    span = live_link(tmp_path / "span.csv", timecode={FRAMES - 1: "05:00:00:00.000"})
    wide = live_link(tmp_path / "wide.csv")
    wide.write_text(wide.read_text().replace(",61,", "," + "6" * (2 << 20) + ",", 1))
    for path, says in ((span, "its Timecodes span 5.0 hours; facegen reads ARKit weights of up to 4 hours"),
                       (wide, "a line is longer than 1 MB")):
        report = validate(path, require_audio=False)
        assert [c.name for c in report.failures] == ["file"] and says in report.check("file").detail
        with pytest.raises(ValueError, match=says) as info:
            facegen_arkit.read_weights(path)
        assert "\n" not in str(info.value)
    clip = facegen_arkit.read_weights(live_link(tmp_path / "fine.csv"))  # the good one reads as before
    assert clip["weights"].shape == (FRAMES, 52) and clip["weights"].dtype == np.float32
    assert clip["fps"] == FPS
    np.testing.assert_array_equal(clip["frames"], np.arange(FRAMES))
    assert float(clip["weights"].min()) == float(clip["weights"].max()) == 0.25


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes")
def test_validate_says_what_a_special_file_is(tmp_path):
    fifo = tmp_path / "take.json"
    os.mkfifo(fifo)
    for path, kind in ((fifo, "a named pipe (FIFO)"), (Path("/dev/zero"), "a character device")):
        done = subprocess.run([sys.executable, "-m", "facegen", "validate", str(path)], capture_output=True,
                              text=True, timeout=120, check=False)
        assert done.returncode == 2 and done.stderr.count("\n") == 1 and kind in done.stderr, done.stderr
