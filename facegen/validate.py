"""Checks on written animation assets (USD, USDZ and .npy): `validate(path) -> Report`.

Each check has a name, ok, a one-line detail and a severity. An "error" check that fails makes the report
fail; a "warning" is shown but never fails it (pxr validators' warnings are warnings, their errors are
errors; facegen's own checks are errors). The checks:

  file            the file opens (USD: as a stage; .npy: a [T, 3V] float array, no pickles)
  mesh            USD: a UsdGeom.Mesh exists (under the defaultPrim)
  vertex count    every frame has the template's vertex count (23,370 for BIWI topology); without a
                  template, the file's own rest pose / first frame sets it
  faces           the face list equals the template's (USD; .npy stores no faces); without a template,
                  triangles whose indices are in range
  frame rate      USD: timeCodesPerSecond authored, equal to framesPerSecond and to `fps` when given
  time samples    USD: points sampled exactly at 0, 1, ..., T-1, stage start/end 0 and T-1, an extent
                  sample per frame that contains the frame's points (blendshapes: blendShapeWeights
                  sampled at 0, 1, ..., T-1, one weight per blend shape in each sample)
  blendshapes     USD blendshapes files (a mesh bound to UsdSkel blend shapes, no points samples): the
                  frames are blended from the BlendShape offsets and weights, every other check runs on
                  them; the skel binding is complete and UsdSkel's own evaluation at the middle frame
                  equals the blend
  reconstruction  USD blendshapes: the error facegen stated in customLayerData is within its tolerance
  package         USDZ: the package's files (the root layer first, its WAV), the audio resolves inside it
  finite          no NaN or infinite coordinate
  displacement    no vertex moves further than `max_displacement` x the rest pose's bounding-box
                  diagonal from its rest position (rest = template, else the file's rest pose, else frame 0)
  audio           the audio is attached and readable (USD: the SpatialAudio prim's file resolves relative
                  to the layer, or inside the .usdz; .npy: the WAV sidecar beside it); `audio_path`
                  replaces it when given
  audio duration  the frame count matches the audio's duration x fps within one frame
  usd:<validator> pxr's UsdValidation validators (all registered), one check per error or warning
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from facegen.audio import load_audio
from facegen.errors import FacegenError
from facegen.exchange import npy as npy_format
from facegen.exchange import usd as usd_format
from facegen.exchange import usd_skel
from facegen.exchange import usdz as usdz_format
from facegen.exchange.wav import sidecar_path
from facegen.mesh import Mesh

DEFAULT_MAX_DISPLACEMENT = 0.25
DEFAULT_FPS = 25.0
SKEL_AGREEMENT = 1e-5  # UsdSkel's evaluation vs facegen's blend (float32 sums), as a share of the face size


@dataclass
class Check:
    name: str
    ok: bool
    detail: str
    severity: str = "error"  # "error": failing it fails the report; "warning": shown only

    @property
    def label(self) -> str:
        if self.ok:
            return "PASS"
        return "FAIL" if self.severity == "error" else "WARN"


@dataclass
class Report:
    path: str
    checks: list[Check] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return all(c.ok for c in self.checks if c.severity == "error")

    @property
    def failures(self) -> list[Check]:
        return [c for c in self.checks if not c.ok and c.severity == "error"]

    @property
    def warnings(self) -> list[Check]:
        return [c for c in self.checks if not c.ok and c.severity != "error"]

    def check(self, name: str) -> Check | None:
        """The first check called `name` (None when it did not run)."""
        return next((c for c in self.checks if c.name == name), None)

    def add(self, name: str, ok: bool, detail: str, severity: str = "error") -> bool:
        self.checks.append(Check(name, bool(ok), detail, severity))
        return bool(ok)

    def to_text(self) -> str:
        head = "OK" if self.ok else "FAILED"
        counts = f"{len(self.checks)} checks, {len(self.failures)} failed, {len(self.warnings)} warnings"
        lines = [f"{self.path}: {head} ({counts})"]
        width = min(max((len(c.name) for c in self.checks), default=0), 14)
        lines += [f"  {c.label}  {c.name:<{width}}  {c.detail}" for c in self.checks]
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {"path": self.path, "ok": self.ok, "checks": [asdict(c) for c in self.checks]}

    def to_json(self, indent: int | None = 2) -> str:
        return json.dumps(self.to_dict(), indent=indent)


def validate(
    path: str | os.PathLike,
    template: Mesh | None = None,
    fps: float | None = None,
    audio_path: str | os.PathLike | None = None,
    *,
    require_audio: bool = True,
    max_displacement: float = DEFAULT_MAX_DISPLACEMENT,
    reference: str | os.PathLike | None = None,
) -> Report:
    """Check an animation file written by facegen (or any file of the same layout); never raises for
    a bad file: every problem is a failed check in the returned Report. `reference` (glTF only): the
    source animation the file's morph targets must reproduce within its stated tolerance."""
    path = Path(path)
    report = Report(str(path))
    suffix = path.suffix.lower()
    if suffix in usd_format.EXTENSIONS + usdz_format.EXTENSIONS:
        _validate_usd(report, path, template, fps, audio_path, require_audio, max_displacement)
    elif suffix in npy_format.EXTENSIONS:
        _validate_npy(report, path, template, fps, audio_path, require_audio, max_displacement)
    elif suffix in (".glb", ".gltf"):  # glTF checks live in validate_gltf.py
        from facegen.validate_gltf import validate_gltf

        validate_gltf(report, path, template, fps, audio_path, require_audio, max_displacement, reference)
    else:
        exts = ", ".join(usd_format.EXTENSIONS + usdz_format.EXTENSIONS + npy_format.EXTENSIONS + (".glb", ".gltf"))
        report.add("file", False, f"cannot validate {suffix or 'files without extension'}: use one of {exts}")
    return report


# ---- USD ---------------------------------------------------------------------------------------------


def _validate_usd(report, path, template, fps, audio_path, require_audio, max_displacement) -> None:
    try:
        stage = usd_format.open_stage(path)
    except FacegenError as exc:
        report.add("file", False, str(exc))
        return
    report.add("file", True, f"opened as a USD stage ({stage.GetRootLayer().GetFileFormat().formatId})")
    mesh = usd_format.find_mesh(stage)
    if not report.add(
        "mesh", mesh is not None, f"{mesh.GetPath()}" if mesh else "no UsdGeom.Mesh in the stage"
    ):
        _usd_validators(report, stage)
        return

    if path.suffix.lower() in usdz_format.EXTENSIONS:
        _check_package(report, path, stage)
    rest = usd_format.rest_points(mesh)
    blended = not mesh.GetPointsAttr().GetNumTimeSamples() and usd_skel.has_blendshapes(mesh)
    if blended:
        times, frames = _blendshape_frames(report, stage, mesh, rest)
    else:
        times, frames = usd_format.points_samples(mesh)
    own = rest if rest is not None else (frames[0] if len(frames) else None)
    expected = template.num_vertices if template is not None else (len(own) if own is not None else None)
    source = (
        "the template" if template is not None else "the file's rest pose" if rest is not None else "frame 0"
    )
    counts = sorted({len(f) for f in frames})
    if len(frames) == 0:
        what = "blend shape frames" if blended else "points time samples"
        report.add("vertex count", False, f"the mesh has no {what}")
    else:
        wrong = [i for i, f in enumerate(frames) if len(f) != expected]
        report.add(
            "vertex count",
            not wrong,
            f"{expected} vertices per frame ({source})"
            if not wrong
            else f"{len(wrong)} of {len(frames)} frames have {counts} vertices, {source} has {expected}",
        )

    try:
        faces = usd_format.mesh_faces(mesh)
    except FacegenError as exc:
        faces = None
        report.add("faces", False, str(exc))
    if faces is not None:
        _check_faces(report, faces, template, expected)

    file_fps = usd_format.stage_fps(stage)
    layer = stage.GetRootLayer()
    if file_fps is None:
        report.add("frame rate", False, "timeCodesPerSecond is not authored: the frame rate is unknown")
    else:
        problems = []
        if layer.HasFramesPerSecond() and abs(layer.framesPerSecond - file_fps) > 1e-9:
            problems.append(f"framesPerSecond {layer.framesPerSecond:g} differs from timeCodesPerSecond")
        if fps is not None and abs(file_fps - fps) > 1e-9:
            problems.append(f"expected {fps:g} fps")
        report.add(
            "frame rate",
            not problems,
            f"{file_fps:g} fps" + (": " + "; ".join(problems) if problems else ""),
        )
    rate = file_fps if file_fps is not None else fps if fps is not None else DEFAULT_FPS

    _check_time_samples(report, stage, mesh, times, "blendShapeWeights" if blended else "points")
    _check_values(report, frames if counts == [expected] else [], own, template, max_displacement)

    audio = None
    sound = usd_format.find_audio(stage)
    if sound is None:
        report.add(
            "audio", not require_audio, "no SpatialAudio prim" + ("" if require_audio else " (not required)")
        )
    else:
        asset, resolved = usd_format.audio_file(sound)
        if not resolved:
            report.add("audio", False, f"{sound.GetPath()} refers to {asset!r}, which does not resolve")
        else:
            audio = _read_audio(
                report, "audio", resolved, f"{sound.GetPath()} -> {asset}", usd_format.read_audio_asset
            )
    if audio_path is not None:
        audio = _read_audio(report, "audio file", audio_path, str(audio_path))
    _check_duration(report, len(frames), rate, audio, require_audio)
    _usd_validators(report, stage)


def _blendshape_frames(report: Report, stage, mesh, rest) -> tuple[list[float], np.ndarray | list]:
    """The frames of a blendshapes file (the "blendshapes" check), then the "reconstruction" check."""
    try:
        if rest is None:
            raise FacegenError(f"mesh {mesh.GetPath()} has blend shapes but no points to apply them to")
        times, frames = usd_skel.blendshape_frames(stage, mesh, rest)
        middle = len(times) // 2
        evaluated = usd_skel.skel_points(stage, mesh, times[middle])
    except FacegenError as exc:
        report.add("blendshapes", False, str(exc))
        return [], []
    size = float(np.linalg.norm(rest.max(0) - rest.min(0)))
    finite = np.isfinite(evaluated).all(1)
    same = np.array_equal(finite, np.isfinite(frames[middle]).all(1))  # NaN is the "finite" check's failure
    gap = np.sqrt(((evaluated[finite].astype(np.float64) - frames[middle][finite]) ** 2).sum(1))
    diff = float(gap.max(initial=0.0))
    agree = same and diff <= SKEL_AGREEMENT * size
    report.add(
        "blendshapes",
        agree,
        f"{usd_skel.describe(usd_skel.shape_names(mesh))} x {len(times)} frames; UsdSkel's evaluation at "
        f"time {times[middle]:g} is {diff:.2g} from the blend" + ("" if agree else " (they disagree)"),
    )
    info = stage.GetRootLayer().customLayerData.get("facegen", {})
    stated = info.get("reconstruction") if isinstance(info, dict) else None
    if isinstance(stated, dict) and "relative_error" in stated:
        error, tolerance = float(stated["relative_error"]), stated.get("tolerance")
        ok = tolerance is None or error <= float(tolerance)
        units = float(stated.get("max_error", float("nan")))
        report.add(
            "reconstruction",
            ok,
            f"largest vertex error {units:.3g} = {error:.3g} of the face size"
            + ("" if tolerance is None else f"; tolerance {float(tolerance):g}")
            + ("" if ok else " (over the tolerance)"),
        )
    return times, frames


def _check_package(report: Report, path: Path, stage) -> None:
    """A .usdz: its files (root layer first), and its audio resolving inside it rather than beside it."""
    from pxr import Ar

    try:
        names = usdz_format.contents(path)
    except FacegenError as exc:
        report.add("package", False, str(exc))
        return
    problems = []
    if not names or Path(names[0]).suffix.lower() not in usd_format.EXTENSIONS:
        problems.append("the first file is not a USD layer")
    sound = usd_format.find_audio(stage)
    if sound is not None:
        asset, resolved = usd_format.audio_file(sound)
        outer = Ar.SplitPackageRelativePathOuter(resolved)[0] if Ar.IsPackageRelativePath(resolved) else ""
        if not outer or Path(outer).resolve() != path.resolve():
            problems.append(f"the audio {asset!r} does not resolve inside the package")
    detail = f"holds {', '.join(names)}" + ("; " + "; ".join(problems) if problems else "")
    report.add("package", not problems, detail)


def _check_faces(report: Report, faces: np.ndarray, template: Mesh | None, num_vertices: int | None) -> None:
    if template is not None:
        same = faces.shape == template.faces.shape and np.array_equal(faces, template.faces)
        if same:
            detail = f"{len(faces)} triangles, identical to the template's"
        elif faces.shape != template.faces.shape:
            detail = f"{len(faces)} triangles, the template has {len(template.faces)}"
        else:
            first = int(np.nonzero((faces != template.faces).any(axis=1))[0][0])
            detail = f"{len(faces)} triangles, but they differ from the template's from triangle {first} on"
        report.add("faces", same, detail)
    else:
        ok = num_vertices is not None and faces.min() >= 0 and faces.max() < num_vertices
        report.add(
            "faces", ok, f"{len(faces)} triangles" + ("" if ok else f", indices outside 0..{num_vertices}")
        )


def _check_time_samples(report: Report, stage, mesh, times: list[float], what: str = "points") -> None:
    """Samples at 0..T-1 and the stage's range; for `points`, an extent sample bounding each frame."""
    from pxr import UsdGeom

    count = len(times)
    problems = []
    if times != [float(i) for i in range(count)]:
        shown = ", ".join(f"{t:g}" for t in times[:4]) + (", ..." if count > 4 else "")
        problems.append(f"{what} sampled at {shown} instead of 0, 1, ..., {count - 1}")
    if count and (stage.GetStartTimeCode() != 0 or stage.GetEndTimeCode() != count - 1):
        problems.append(
            f"stage time range {stage.GetStartTimeCode():g}..{stage.GetEndTimeCode():g}, expected 0..{count - 1}"
        )
    extent = mesh.GetExtentAttr()
    if what != "points":  # blend shapes deform the rest pose, whose extent is not sampled
        pass
    elif list(extent.GetTimeSamples()) != times:
        problems.append("extent is not sampled at the same times as points")
    else:
        points = mesh.GetPointsAttr()
        for t in times:
            want = np.asarray(UsdGeom.PointBased.ComputeExtent(points.Get(t)), dtype=np.float64)
            have = np.asarray(extent.Get(t), dtype=np.float64)
            if have.shape != (2, 3) or not np.allclose(have, want, rtol=1e-5, atol=1e-6):
                problems.append(f"extent at time {t:g} does not bound the points")
                break
    report.add(
        "time samples", not problems, "; ".join(problems) or f"{count} frames, one at each of 0..{count - 1}"
    )


def _check_values(
    report: Report,
    frames: list[np.ndarray] | np.ndarray,
    own_rest: np.ndarray | None,
    template: Mesh | None,
    max_displacement: float,
) -> None:
    """finite + displacement, over [T, V, 3] frames of the right vertex count (skipped when empty)."""
    if len(frames) == 0:
        report.add("finite", False, "no frames with the expected vertex count to check")
        return
    bad_frames = [i for i, f in enumerate(frames) if not np.isfinite(f).all()]
    report.add(
        "finite",
        not bad_frames,
        "no NaN or infinite coordinates"
        if not bad_frames
        else f"{len(bad_frames)} frames have NaN/inf coordinates (first: frame {bad_frames[0]})",
    )
    rest = template.vertices if template is not None else own_rest if own_rest is not None else frames[0]
    rest = np.asarray(rest, dtype=np.float32)
    if not np.isfinite(rest).all():
        report.add("displacement", False, "the rest pose has NaN/inf coordinates")
        return
    size = float(np.linalg.norm(rest.max(0) - rest.min(0)))
    bound = max_displacement * size
    worst, worst_frame = 0.0, 0
    for i, f in enumerate(frames):
        with np.errstate(invalid="ignore", over="ignore"):
            d = np.sqrt(((np.asarray(f, dtype=np.float32) - rest) ** 2).sum(axis=1))
        d = float(d[np.isfinite(d)].max(initial=0.0))  # NaN/inf vertices are the "finite" check's failure
        if d > worst:
            worst, worst_frame = d, i
    share = f"{worst / size:.1%}" if size > 0 else "n/a"
    report.add(
        "displacement",
        worst <= bound,
        f"largest vertex offset {worst:.4g} (frame {worst_frame}) = {share} of the face size "
        f"{size:.4g}; bound {max_displacement:.0%}",
    )


def _read_audio(
    report: Report, name: str, path, shown: str, reader=load_audio
) -> tuple[np.ndarray, int] | None:
    try:
        samples, rate = reader(path)
    except FacegenError as exc:
        report.add(name, False, f"{shown}: {exc}")
        return None
    if len(samples) == 0:
        report.add(name, False, f"{shown}: no audio samples")
        return None
    report.add(name, True, f"{shown}: {len(samples) / rate:.3f} s at {rate} Hz")
    return samples, rate


def _check_duration(report: Report, frames: int, fps: float, audio, require_audio: bool) -> None:
    if audio is None:
        if require_audio:
            report.add("audio duration", False, "no readable audio to compare the frame count with")
        return
    seconds = len(audio[0]) / audio[1]
    expected = seconds * fps
    ok = abs(frames - expected) <= 1.0
    report.add(
        "audio duration",
        ok,
        f"{frames} frames at {fps:g} fps = {frames / fps:.3f} s; audio {seconds:.3f} s = {expected:.1f} frames"
        + ("" if ok else " (more than one frame apart)"),
    )


def _usd_validators(report: Report, stage) -> None:
    from pxr import UsdValidation

    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    with _quiet_native_stderr():  # pxr also prints its findings (and noise) as warnings on stderr
        errors = context.Validate(stage)
    found = 0
    for error in errors:
        kind = error.GetType()
        if kind not in (UsdValidation.ValidationErrorType.Error, UsdValidation.ValidationErrorType.Warn):
            continue
        found += 1
        validator = error.GetValidator()
        name = validator.GetMetadata().name if validator else error.GetName()
        severity = "error" if kind == UsdValidation.ValidationErrorType.Error else "warning"
        report.add(f"usd:{name}", False, error.GetMessage(), severity)
    if not found:
        report.add(
            "usd validators", True, f"{len(registry.GetOrLoadAllValidators())} pxr validators, no findings"
        )


@contextlib.contextmanager
def _quiet_native_stderr() -> Iterator[None]:
    """Send file descriptor 2 (where pxr's C++ diagnostics go) to /dev/null for the block."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


# ---- .npy --------------------------------------------------------------------------------------------


def _validate_npy(report, path, template, fps, audio_path, require_audio, max_displacement) -> None:
    try:
        data = npy_format.load_frames(path)
    except FacegenError as exc:
        report.add("file", False, str(exc))
        return
    report.add("file", True, f"[{data.shape[0]}, {data.shape[1]}] {data.dtype} array")
    if template is None:
        report.add(
            "template", False, ".npy files store no faces or rest pose: pass the template mesh (--template)"
        )
        return
    num_vertices = data.shape[1] // 3
    same = num_vertices == template.num_vertices
    report.add(
        "vertex count",
        same,
        f"{num_vertices} vertices per frame"
        + (" (the template's)" if same else f", the template has {template.num_vertices}"),
    )
    frames = data.reshape(len(data), num_vertices, 3) if same else []
    _check_values(report, frames, None, template, max_displacement)
    audio = None
    wav = Path(audio_path) if audio_path is not None else sidecar_path(path)
    if wav.is_file():
        audio = _read_audio(report, "audio", wav, str(wav))
    else:
        report.add(
            "audio", not require_audio, f"no audio file {wav}" + ("" if require_audio else " (not required)")
        )
    _check_duration(report, len(data), float(fps if fps is not None else DEFAULT_FPS), audio, require_audio)
