"""The layers over the network's frames of a clip: what the network cannot predict from the audio and the
words — the lips shut on p, b and m (facegen.lip_seal), blinks timed by the speech (facegen.blinks), gaze
(facegen.gaze: saccades, aversion; the eyeballs turned, the upper lids following; the parts' eyes too), the
tongue (facegen.tongue), the clip's emotion (facegen.expression) and the head's motion (facegen.head, beside
the frames: a transform). The times and settings go in the metadata (animator)."""

from __future__ import annotations

import numpy as np

from facegen.errors import FacegenError


def add_layers(clip, stream, fps: float):
    """`stream` (the network's frames of `clip`, a FrameStream at `fps`) with the layers; the clip's
    blinks, saccades, head angles and pivot set on it. A face without facegen's rig regions gets none."""
    from facegen.arkit.shapes import arkit_shapes
    from facegen.blinks import blink_curve, blink_times, quiet_spans
    from facegen.expression import emotion_offsets, span_curve
    from facegen.gaze import EyeTurns, gaze_curve, lid_curves, saccades

    clip.blinks, clip.saccades, clip.head, clip.parts = [], [], None, None
    try:
        shapes = arkit_shapes(clip.mesh)
    except FacegenError:
        return stream
    frames = len(stream)
    duration = len(clip.samples) / clip.sample_rate
    pauses = quiet_spans(clip.samples, clip.sample_rate)
    curves, offsets = [], []
    clip.blinks = blink_times(duration, pauses, clip.blink_rate, clip.seed)
    if clip.blinks:
        curves.append(blink_curve(clip.blinks, frames, fps))
        offsets.append(shapes.offset("eyeBlinkLeft") + shapes.offset("eyeBlinkRight"))
    clip.saccades = saccades(duration, pauses, clip.seed)
    gaze = gaze_curve(clip.saccades, frames, fps)
    if clip.saccades:
        eyes = np.concatenate([clip.mesh.regions["left_eyeball"], clip.mesh.regions["right_eyeball"]])
        follow = lid_curves(gaze)
        for k, name in enumerate(("eyeLookUp", "eyeLookDown")):  # their lids only: the eyes turn below
            lids = shapes.offset(name + "Left") + shapes.offset(name + "Right")
            lids[eyes] = 0.0
            curves.append(follow[:, k])
            offsets.append(lids)
    mood = emotion_offsets(clip.emotion, clip.mesh)
    if mood is not None:
        curves.append(np.ones(frames, np.float32))
        offsets.append(mood)
    for emotion, start, end in clip.emotion_spans or []:  # marked in the transcript
        mood = emotion_offsets(emotion, clip.mesh)
        if mood is not None:
            curves.append(span_curve(start, end, frames, fps))
            offsets.append(mood)
    if curves:
        stream = stream.with_layers(np.stack(curves, 1), np.stack([o.reshape(-1) for o in offsets]))
    if clip.lip_seal:  # after the layers above: the gap it shuts is the one they leave
        from facegen.lip_seal import seal_curve

        close = shapes.offset("mouthClose")
        seal = seal_curve(stream, clip.mesh, clip.phone_times, fps, close)
        if seal is not None:
            stream = stream.with_layers(seal[:, None], close.reshape(1, -1))
            clip.sealed = int(np.count_nonzero(seal))
    from facegen.face.parts import PartDrivers
    from facegen.tongue import tongue_curves

    clip.parts = PartDrivers(gaze, tongue_curves(clip.phones, frames, fps))  # eyes, teeth, tongue
    if clip.saccades:
        stream = stream.with_turns(EyeTurns(clip.mesh.vertices, clip.mesh.regions, gaze))
    from facegen.head import has_pivot, head_motion, pivot

    if clip.head_motion and has_pivot(clip.mesh.regions):
        clip.head = head_motion(clip.samples, clip.sample_rate, pauses, frames, fps, clip.head_motion,
                                clip.seed)
        clip.head_pivot = pivot(clip.mesh.vertices, clip.mesh.regions).astype(np.float32)
    return stream
