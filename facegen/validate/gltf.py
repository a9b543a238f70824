"""Checks on glTF/GLB animations (exchange/gltf.py), added to a Report, and the Khronos validator's driver.

  file              the file parses as glTF with one animated morph-target mesh (exchange/gltf.py layout)
  rig               the targets' names (mesh.extras.targetNames): ARKit shapes or not (validate/rig.py)
  gltf-validator    the Khronos glTF-Validator (npm `gltf-validator`, run by facegen/assets/gltf_validate.js
                    with Node): zero errors; each warning is a `gltf:<CODE>` warning, infos are counted.
                    Without Node or the package this one check fails and says how to install it
                    (`make node-deps`); every other check still runs
  vertex count, faces, finite, displacement   as for USD (checks.py), on the reconstructed frames
  frame rate        asset.extras.facegen.fps is stated (and equals `fps` when given)
  time samples      a LINEAR weights sampler keyed at exactly i / fps, i = 0..T-1, T = the stated frame
                    count; min/max on the sampler input and on every POSITION accessor (base and targets)
  reconstruction    with a `reference` (the source .npy/USD/...): every reconstructed vertex within the
                    stated tolerance x face size of the source (and within the stated error); without one,
                    the stated error is reported
  audio, audio duration               the WAV sidecar (or `audio_path`): readable, within one frame
  embedded audio, embedded audio duration, audio sync   the KHR_audio_emitter MP3: decodes, lasts the
                    animation's duration within one frame (+ one MP3 frame of padding), and lines up with
                    the WAV sidecar within one frame
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np

from facegen.animation import DEFAULT_FPS, Animation
from facegen.audio import load_audio
from facegen.errors import FacegenError
from facegen.exchange import gltf as gltf_format
from facegen.exchange import mp3, read_animation
from facegen.exchange.wav import sidecar_path
from facegen.face.mesh import Mesh
from facegen.processes import run_tool, tool_path
from facegen.validate.checks import check_duration, check_faces, check_values, open_file, read_audio
from facegen.validate.report import Expected, Report
from facegen.validate.rig import check_rig

ASSETS = Path(__file__).resolve().parents[1] / "assets"
SCRIPT = ASSETS / "gltf_validate.js"
INSTALL_HINT = "run `make node-deps` in the facegen checkout (npm install in facegen/assets)"


def validator_version() -> str:
    """The gltf-validator version pinned in facegen/assets/package.json."""
    try:
        return json.loads((ASSETS / "package.json").read_text())["dependencies"]["gltf-validator"]
    except (OSError, KeyError, ValueError):
        return "?"


def run_gltf_validator(path: str | os.PathLike, *, script: str | os.PathLike | None = None,
                       timeout: float = 300.0) -> tuple[dict | None, str]:
    """(the validator's JSON report, "") or (None, why it could not run and how to fix that)."""
    script = Path(script) if script is not None else SCRIPT
    install = f"install Node.js >= 18, then {INSTALL_HINT}"
    try:
        tool_path("node", install)
        if not script.is_file():
            return None, f"the validator script {script} is missing: reinstall facegen"
        done = run_tool("node", [script, path, "200"], text=True, timeout=timeout, install=install)
    except FacegenError as exc:  # Node.js is missing
        return None, str(exc)
    except subprocess.TimeoutExpired as exc:
        return None, f"could not run the glTF-Validator ({exc})"
    lines = [line for line in done.stdout.splitlines() if line.strip()]
    try:
        report = json.loads(lines[-1]) if lines else None
    except ValueError:
        report = None
    if done.returncode == 3:
        return None, (f"the npm package gltf-validator@{validator_version()} is not installed: "
                      f"{INSTALL_HINT}")
    if report is None or "error" in report or done.returncode != 0:
        why = report.get("error") if isinstance(report, dict) else (done.stderr.strip().splitlines()
                                                                    or ["?"])[-1]
        return None, f"the glTF-Validator failed: {why}"
    return report, ""


def check(report: Report, path: Path, expected: Expected) -> None:
    """Add the glTF checks for `path` to `report`; never raises for a bad file."""
    template, fps, require_audio = expected.template, expected.fps, expected.require_audio
    decoded = open_file(report, gltf_format.decode, path)
    if decoded is None:
        _khronos(report, path)
        return
    info = decoded["info"]
    K, T = len(decoded["targets"]), len(decoded["times"])
    report.add("file", True, f"glTF {'binary' if path.suffix.lower() == '.glb' else 'JSON'}: one mesh, "
               f"{K} morph targets, {T} keys (written by "
               f"{info.get('version') and 'facegen ' + info['version'] or '?'})")
    _khronos(report, path)
    check_rig(report, decoded["names"], info.get("lipErrorMm"), info.get("faceErrorMm"))

    frames = gltf_format.reconstruct(decoded)
    base = decoded["base"]
    count = template.num_vertices if template is not None else len(base)
    source = "the template" if template is not None else "the file's rest pose"
    report.add("vertex count", len(base) == count,
               f"{len(base)} vertices" + ("" if len(base) == count else f", {source} has {count}"))
    check_faces(report, decoded["faces"], template, len(base))

    stated = info.get("fps")
    rate = float(stated) if isinstance(stated, int | float) and stated > 0 else None
    if rate is None:
        report.add("frame rate", False, "asset.extras.facegen.fps is not stated: the frame rate is unknown")
    else:
        off = fps is not None and abs(rate - fps) > 1e-9
        report.add("frame rate", not off, f"{rate:g} fps" + (f": expected {fps:g} fps" if off else ""))
    rate = rate or decoded["fps"] or fps or DEFAULT_FPS
    _check_keys(report, decoded, rate)
    check_values(report, frames if len(base) == count else [], base, template, expected.max_displacement)
    own = template if template is not None else Mesh(np.asarray(base, np.float32), decoded["faces"])
    _check_reconstruction(report, frames, info, own, rate, expected.reference)  # a .npy reference: this face

    audio = None
    wav = Path(expected.audio_path) if expected.audio_path is not None else sidecar_path(path)
    if wav.is_file():
        audio = read_audio(report, "audio", wav, str(wav))
    data = decoded["file"].mp3_audio()
    embedded = None
    if data is None:
        report.add("embedded audio", not require_audio or audio is not None,
                   "no KHR_audio_emitter audio/mpeg in the file" + ("" if require_audio
                                                                    else " (not required)"))
    else:
        try:
            embedded = mp3.decode(data)
            report.add("embedded audio", True, f"KHR_audio_emitter audio/mpeg, {len(data)} bytes, "
                       f"{len(embedded[0]) / embedded[1]:.3f} s at {embedded[1]} Hz")
        except FacegenError as exc:
            report.add("embedded audio", False, str(exc))
    if audio is None and embedded is None and require_audio:
        report.add("audio", False, f"no WAV sidecar {wav} and no embedded audio")
    if audio is not None or embedded is None:
        check_duration(report, T, rate, audio, require_audio and embedded is None)
    if embedded is not None:
        seconds = len(embedded[0]) / embedded[1]
        slack = 1.0 / rate + 1152.0 / embedded[1]  # one frame, plus one MP3 frame of encoder padding
        ok = abs(seconds - T / rate) <= slack
        report.add("embedded audio duration", ok, f"{seconds:.3f} s for {T} frames = {T / rate:.3f} s "
                   f"(allowed {slack * 1000:.0f} ms: one frame + one MP3 frame)")
        if audio is not None:  # the samples now (read_audio only measured them): both tracks are compared
            try:
                _check_sync(report, embedded, load_audio(wav), rate)
            except FacegenError as exc:
                report.add("audio sync", False, str(exc))


def _khronos(report: Report, path: Path) -> None:
    result, why = run_gltf_validator(path)
    if result is None:
        report.add("gltf-validator", False, why)
        return
    issues = result.get("issues", {})
    messages = issues.get("messages", [])
    errors, warnings = issues.get("numErrors", 0), issues.get("numWarnings", 0)
    infos = sorted({m["code"] for m in messages if m.get("severity") in (2, 3)})
    report.add("gltf-validator", errors == 0,
               f"glTF-Validator {result.get('validatorVersion', validator_version())}: {errors} errors, "
               f"{warnings} warnings, {issues.get('numInfos', 0)} infos"
               + (f" ({', '.join(infos)})" if infos else ""))
    for m in messages:
        if m.get("severity") in (0, 1):
            report.add(f"gltf:{m.get('code')}", False, f"{m.get('pointer', '')}: "
                                                       f"{m.get('message', '')}".strip(": "),
                       "error" if m["severity"] == 0 else "warning")


def _check_keys(report: Report, decoded: dict, rate: float) -> None:
    doc = decoded["file"].doc
    times, info = decoded["times"], decoded["info"]
    T = len(times)
    problems = []
    if decoded["interpolation"] != "LINEAR":
        problems.append(f"{decoded['interpolation']} sampler (expected LINEAR)")
    want = np.arange(T) / rate
    if T and np.abs(times - want).max() > 0.5e-4 + 1e-6 * want[-1]:
        worst = int(np.argmax(np.abs(times - want)))
        problems.append(f"key {worst} at {times[worst]:.6f} s, expected {want[worst]:.6f} s (frame / fps)")
    if isinstance(info.get("frames"), int) and info["frames"] != T:
        problems.append(f"{T} keys but {info['frames']} frames stated")
    node = decoded["node"]
    track = gltf_format.weight_track(doc, node)
    accessors = doc.accessors
    unbounded = []
    if track is not None and not (accessors[track[0]].min and accessors[track[0]].max):
        unbounded.append("sampler input")
    prim = doc.meshes[decoded["mesh"]].primitives[0]
    positions = [prim.attributes.POSITION] + [t["POSITION"] for t in prim.targets or []]
    unbounded += [f"accessor {i}" for i in positions if not (accessors[i].min and accessors[i].max)]
    if unbounded:
        problems.append("no min/max on " + ", ".join(unbounded[:5]) + (" ..." if len(unbounded) > 5 else ""))
    report.add("time samples", not problems, "; ".join(problems) or
               f"{T} keys at frame / fps (0 .. {(T - 1) / rate:.3f} s), LINEAR; min/max on the sampler input "
               f"and on {len(positions)} POSITION accessors")


def _check_reconstruction(report: Report, frames: np.ndarray, info: dict, template: Mesh | None, rate: float,
                          reference) -> None:
    tolerance = info.get("tolerance")
    claimed = info.get("reconstructionError")
    if reference is None:
        stated = (f"stated largest vertex error {claimed:.3g} of the face size" if isinstance(claimed, float)
                  else "no stated reconstruction error")
        report.add("reconstruction", isinstance(claimed, int | float),
                   stated + (f" (tolerance {tolerance:g})" if isinstance(tolerance, int | float) else "")
                   + "; pass the source animation as reference to verify it")
        return
    try:
        source = reference if isinstance(reference, Animation) else read_animation(reference, template, rate)
    except FacegenError as exc:
        report.add("reconstruction", False, f"cannot read the reference: {exc}")
        return
    if source.vertices.shape != frames.shape:
        report.add("reconstruction", False, f"the reference has {list(source.vertices.shape)} vertices, "
                   f"the file {list(frames.shape)}")
        return
    size = float(source.size)
    error = float(np.sqrt(((frames - source.vertices) ** 2).sum(axis=2)).max()) / size
    limit = tolerance if isinstance(tolerance, int | float) else claimed if isinstance(claimed,
                                                                                       int | float) else 0.0
    slack = 1e-6  # float32 rounding of the stored arrays
    ok = error <= limit + slack and (not isinstance(claimed, int | float) or error <= claimed + slack)
    report.add("reconstruction", ok, f"largest vertex error {error:.3g} of the face size against the "
               f"reference (stated {claimed if claimed is None else f'{claimed:.3g}'}, tolerance "
               f"{tolerance if tolerance is None else f'{tolerance:g}'})")


def _check_sync(report: Report, embedded: tuple[np.ndarray, int], audio: tuple[np.ndarray, int],
                rate: float) -> None:
    samples, sample_rate = embedded
    wav, wav_rate = audio
    if wav_rate != sample_rate:
        from math import gcd

        from scipy.signal import resample_poly

        g = gcd(wav_rate, sample_rate)
        wav = resample_poly(wav, sample_rate // g, wav_rate // g).astype(np.float32)
    if not (np.abs(wav).max() > 0 and np.abs(samples).max() > 0):
        report.add("audio sync", True, "silent audio: nothing to line up")
        return
    lag = mp3.lag(samples, wav)
    seconds = lag / sample_rate
    report.add("audio sync", abs(seconds) <= 1.0 / rate,
               f"the embedded MP3 is {seconds * 1000:+.1f} ms from the WAV sidecar (one frame: "
               f"{1000 / rate:.0f} ms)")
