"""Checks on USD and USDZ animations (exchange/usd.py, usdz.py; UsdSkel blend shapes: usd_skel.py), added
to a Report. pxr's validators' warnings are warnings, their errors are errors; facegen's own checks are
errors.

  file            the file opens as a USD stage
  mesh            a UsdGeom.Mesh exists (under the defaultPrim)
  vertex count    every frame has the template's vertex count (23,370 for BIWI topology); without a
                  template, the file's own rest pose / first frame sets it
  faces           as in checks.py
  frame rate      timeCodesPerSecond authored, equal to framesPerSecond and to `fps` when given
  time samples    points sampled exactly at 0, 1, ..., T-1, stage start/end 0 and T-1, an extent sample per
                  frame that contains the frame's points (blendshapes: blendShapeWeights sampled at
                  0, 1, ..., T-1, one weight per blend shape in each sample, and the mesh's extent at each
                  frame, sampled or not, contains the blended points)
  blendshapes     blendshapes files (a mesh bound to UsdSkel blend shapes, no points samples): the frames
                  are blended from the BlendShape offsets and weights, every other check runs on them; the
                  skel binding is complete and UsdSkel's own evaluation at the middle frame equals the blend
  reconstruction  blendshapes: the error facegen stated in customLayerData is within its tolerance
  rig             blendshapes: the shapes' names, ARKit's or not (validate/rig.py)
  package         USDZ: the package's files (the root layer first, its WAV), the audio resolves inside it
  clips           value clips (a long points clip, exchange/usd_clips.py): every clip layer and the manifest
                  resolve and open, the clips are active in time order from frame 0, each clip layer's own
                  points samples lie within its active range; the frames are then read through the stage, one
                  at a time (never all held), so every other check sees the composed animation
  finite, displacement   as in checks.py
  audio           the SpatialAudio prim's file resolves relative to the layer, or inside the .usdz, and
                  reads; `audio_path` replaces it when given ("audio file")
  audio duration  as in checks.py
  usd:<validator> pxr's UsdValidation validators (all registered), one check per error or warning
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from facegen.animation import DEFAULT_FPS
from facegen.errors import FacegenError
from facegen.exchange import usd as usd_format
from facegen.exchange import usd_skel
from facegen.exchange import usdz as usdz_format
from facegen.validate.checks import (
    ValueScan,
    audio_length,
    check_duration,
    check_faces,
    check_values,
    open_file,
    read_audio,
)
from facegen.validate.report import Expected, Report
from facegen.validate.rig import check_rig

SKEL_AGREEMENT = 1e-5  # UsdSkel's evaluation vs facegen's blend (float32 sums), as a share of the face size


def check(report: Report, path: Path, expected: Expected) -> None:
    """Add the USD (or USDZ) checks for `path` to `report`; never raises for a bad file."""
    template, fps = expected.template, expected.fps
    stage = open_file(report, usd_format.open_stage, path)
    if stage is None:
        return
    report.add("file", True, f"opened as a USD stage ({stage.GetRootLayer().GetFileFormat().formatId})")
    mesh = usd_format.find_mesh(stage)
    if not report.add(
        "mesh", mesh is not None, f"{mesh.GetPath()}" if mesh else "no UsdGeom.Mesh in the stage"
    ):
        _usd_validators(report, stage)
        return

    if path.suffix.lower() in usdz_format.FORMAT.extensions:
        _check_package(report, path, stage)
    if usd_format.clip_sets(mesh):
        _check_clips(report, mesh)
    rest = usd_format.rest_points(mesh)
    blended = not mesh.GetPointsAttr().GetNumTimeSamples() and usd_skel.has_blendshapes(mesh)
    if blended:
        times, frames = _blendshape_frames(report, stage, mesh, rest)
    else:
        times, frames = usd_format.points_samples(mesh)
    own = rest if rest is not None else (frames[0] if len(frames) else None)
    count = template.num_vertices if template is not None else (len(own) if own is not None else None)
    source = (
        "the template" if template is not None else "the file's rest pose" if rest is not None else "frame 0"
    )
    scan = extent_problem = None
    if blended:
        lengths = [len(f) for f in frames]
    else:  # one pass reading each frame through the stage: its length, its extent, its values
        base = template.vertices if template is not None else own
        lengths, scan, extent_problem = _scan_points(mesh, frames, base, count)
    counts = sorted(set(lengths))
    if len(frames) == 0:
        what = "blend shape frames" if blended else "points time samples"
        report.add("vertex count", False, f"the mesh has no {what}")
    else:
        wrong = [i for i, n in enumerate(lengths) if n != count]
        report.add(
            "vertex count",
            not wrong,
            f"{count} vertices per frame ({source})"
            if not wrong
            else f"{len(wrong)} of {len(frames)} frames have {counts} vertices, {source} has {count}",
        )

    try:
        faces = usd_format.mesh_faces(mesh)
    except FacegenError as exc:
        faces = None
        report.add("faces", False, str(exc))
    if faces is not None:
        check_faces(report, faces, template, count)

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

    _check_time_samples(report, stage, mesh, times, "blendShapeWeights" if blended else "points", frames,
                        extent_problem)
    if scan is not None and len(times) and counts == [count]:
        scan.report(report, expected.max_displacement)
    else:
        check_values(report, frames if counts == [count] else [], own, template, expected.max_displacement)

    audio = None
    sound = usd_format.find_audio(stage)
    if sound is None:
        report.add(
            "audio", not expected.require_audio,
            "no SpatialAudio prim" + ("" if expected.require_audio else " (not required)"),
        )
    else:
        asset, resolved = usd_format.audio_file(sound)
        if not resolved:
            report.add("audio", False, f"{sound.GetPath()} refers to {asset!r}, which does not resolve")
        else:
            audio = read_audio(report, "audio", resolved, f"{sound.GetPath()} -> {asset}", _audio_asset)
    if expected.audio_path is not None:
        audio = read_audio(report, "audio file", expected.audio_path, str(expected.audio_path))
    check_duration(report, len(frames), rate, audio, expected.require_audio)
    _usd_validators(report, stage)


def _audio_asset(resolved: str) -> tuple[np.ndarray | int, int]:
    """The audio a SpatialAudio prim resolves to: a file measured in bounded memory (audio_length), one
    inside a .usdz package read through USD's resolver."""
    return (audio_length if os.path.isfile(resolved) else usd_format.read_audio_asset)(resolved)


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
    stated = stated if isinstance(stated, dict) else {}
    check_rig(report, usd_skel.shape_names(mesh), stated.get("lip_error_mm"), stated.get("face_error_mm"))
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
    if not names or Path(names[0]).suffix.lower() not in usd_format.FORMAT.extensions:
        problems.append("the first file is not a USD layer")
    sound = usd_format.find_audio(stage)
    if sound is not None:
        asset, resolved = usd_format.audio_file(sound)
        outer = Ar.SplitPackageRelativePathOuter(resolved)[0] if Ar.IsPackageRelativePath(resolved) else ""
        if not outer or Path(outer).resolve() != path.resolve():
            problems.append(f"the audio {asset!r} does not resolve inside the package")
    detail = f"holds {', '.join(names)}" + ("; " + "; ".join(problems) if problems else "")
    report.add("package", not problems, detail)


def _check_clips(report: Report, mesh) -> None:
    """Value clips: each clip set's layers and manifest open, active in time order from 0, and each clip
    layer's own points samples within the stage times where it is active."""
    from pxr import Sdf

    problems, described = [], []
    for name, clip_set in usd_format.clip_sets(mesh).items():
        assets = list(clip_set.get("assetPaths", []))
        active = [tuple(a) for a in clip_set.get("active", [])]
        starts = [a[0] for a in active]
        if [int(a[1])
            for a in active] != list(range(len(assets))) or starts != sorted(starts) or starts[:1] != [0]:
            problems.append(f"clip set {name!r}: active {active[:4]} does not play its {len(assets)} clips "
                            "in order from time 0")
        manifest = clip_set.get("manifestAssetPath")
        identity = all(a == b for a, b in clip_set.get("times", []))  # clip time = stage time (facegen's)
        for k, asset in enumerate(assets):
            layer = Sdf.Layer.FindOrOpen(asset.resolvedPath) if asset.resolvedPath else None
            if layer is None:
                problems.append(f"clip layer {asset.path} does not resolve or open")
                continue
            spec = layer.GetAttributeAtPath(Sdf.Path(str(clip_set.get("primPath",
                                                                      mesh.GetPath()))).AppendProperty(
                "points"))
            times = list(layer.ListTimeSamplesForPath(spec.path)) if spec else []
            end = starts[k + 1] if k + 1 < len(starts) else float("inf")
            outside = identity and k < len(starts) and times and (times[0] < starts[k] or times[-1] >= end)
            if not times or outside:
                problems.append(f"clip layer {asset.path} has no points samples within its active times")
            del layer
        if manifest is not None and manifest.path and not manifest.resolvedPath:
            problems.append(f"clip manifest {manifest.path} does not resolve")
        described.append(f"{name}: {len(assets)} clip layers" + (f" ({assets[0].path} ...)" if assets
                                                                 else ""))
    report.add("clips", not problems, "; ".join(problems[:3]) or "; ".join(described) + ", all resolve")


def _scan_points(mesh, frames: usd_format.PointsFrames, rest: np.ndarray | None,
                 count: int | None) -> tuple[list[int], ValueScan | None, str | None]:
    """Each `points` sample read once: the vertex counts, finite + displacement against `rest` of the frames
    with `count` vertices (a ValueScan, None without a rest pose), and the first problem of the extent samples
    (an extent sample per frame bounding its points), or None."""
    from pxr import UsdGeom

    extent = mesh.GetExtentAttr()
    check_extent = list(extent.GetTimeSamples()) == frames.times
    problem = None if check_extent else "extent is not sampled at the same times as points"
    scan = ValueScan(rest) if rest is not None else None
    lengths = []
    for i, t in enumerate(frames.times):
        value = frames.value(i)
        if value is None:  # a value clip that does not open
            lengths.append(0)
            problem = problem or f"no points at time {t:g}"
            continue
        lengths.append(len(value))
        if problem is None:
            want = np.asarray(UsdGeom.PointBased.ComputeExtent(value), dtype=np.float64)
            have = np.asarray(extent.Get(t), dtype=np.float64)
            # np.allclose's test (equal infinities are close, NaN is not) without its overhead, 2 x 3 values a
            # frame
            with np.errstate(invalid="ignore"):
                close = have.shape == want.shape == (2, 3) and bool(
                    ((have == want) | (np.abs(have - want) <= 1e-6 + 1e-5 * np.abs(want))).all())
            if not close:
                problem = f"extent at time {t:g} does not bound the points"
        if scan is not None and len(value) == count:
            scan.add(i, np.asarray(value, dtype=np.float32))
    return lengths, scan, problem


def _check_time_samples(report: Report, stage, mesh, times: list[float], what: str = "points",
                        frames=(), extent_problem: str | None = None) -> None:
    """Samples at 0..T-1 and the stage's range; for `points`, an extent sample bounding each frame (its first
    problem found by _scan_points: `extent_problem`); for blend shapes, the extent at each time (sampled or
    not) bounding the blended `frames`."""
    count = len(times)
    problems = []
    if times != [float(i) for i in range(count)]:
        shown = ", ".join(f"{t:g}" for t in times[:4]) + (", ..." if count > 4 else "")
        problems.append(f"{what} sampled at {shown} instead of 0, 1, ..., {count - 1}")
    if count and (stage.GetStartTimeCode() != 0 or stage.GetEndTimeCode() != count - 1):
        problems.append(
            f"stage time range {stage.GetStartTimeCode():g}..{stage.GetEndTimeCode():g}, expected "
            f"0..{count - 1}"
        )
    extent = mesh.GetExtentAttr()
    if what != "points" and len(frames):  # blend shapes deform the rest pose: the extent holds every frame
        bounds = usd_skel.point_extents(frames).astype(np.float64)
        for t, (low, high) in zip(times, bounds, strict=False):
            box = np.asarray(extent.Get(t) or [], dtype=np.float64)
            slack = 1e-6 * max(float(np.abs(low).max()), float(np.abs(high).max()), 1.0)
            if box.shape != (2, 3) or (low < box[0] - slack).any() or (high > box[1] + slack).any():
                problems.append(f"extent at time {t:g} does not bound the blended points")
                break
    elif extent_problem is not None:
        problems.append(extent_problem)
    report.add(
        "time samples", not problems, "; ".join(problems) or f"{count} frames, one at each of 0..{count - 1}"
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
