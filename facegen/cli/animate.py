"""`facegen animate`: one audio clip to one animation file (and a preview video)."""

from __future__ import annotations

import click

from facegen.cli.command import Command
from facegen.cli.options import (
    DEVICE,
    FiniteRange,
    morph_targets_option,
    one_of,
    protect_inputs,
    read_text,
    usd_clips_option,
)
from facegen.exchange import extensions
from facegen.runtime import Reporter, say_stderr


@click.command(cls=Command, given_by={"path": ("output",)})  # the written file
@click.argument("audio", type=click.Path(dir_okay=False))
@click.option("--text", "-t", help="The transcript (words spoken).")
@click.option("--text-file", type=click.Path(dir_okay=False), help="A UTF-8 file with the transcript.")
@click.option("--alignment", type=click.Path(dir_okay=False),
              help="Word timings you already have: Gentle/WhisperX JSON, TextGrid, JSON or CSV word list.")
@click.option("--no-text", is_flag=True, help="Use no words at all (zero text features).")
@click.option("--speaker", "-s",
              help="Speaking style: a speaker name or index of the model (default: the first).")
@click.option("--model", "-m", type=click.Path(dir_okay=False),
              help="Model bundle (default: the built-in model).")
@click.option("--template", type=click.Path(dir_okay=False),
              help="A face mesh (PLY/OBJ) with the model's topology to animate instead of its template.")
@click.option("--text-model",
              help="Local folder (or cached id) of the text model, if not where the bundle says.")
@click.option("--output", "-o", required=True, type=click.Path(dir_okay=False),
              help=f"Output file: {' '.join(extensions())}.")
@click.option("--usd-mode", type=click.Choice(["points", "blendshapes"]),
              help="USD: time-sampled points (default) or UsdSkel blend shapes (compact, for game engines).")
@click.option("--usd-clips", metavar="auto|never|N", callback=usd_clips_option,
              help="USD points: auto (default) writes clips over 2 minutes as value clips in OUTPUT.clips/ "
                   "(bounded memory), never keeps one file, N writes value clips of N frames.")
@click.option("--rig", type=click.Choice(["pca", "arkit"]),
              help="glTF / USD: the morph targets: pca (default: a PCA of the clip, the fewest targets) or "
                   "arkit (Apple's 52 ARKit blend shapes, named as ARKit names them, with their fitted "
                   "weights; USD: UsdSkel blend shapes).")
@click.option("--morph-targets", metavar="K|all", callback=morph_targets_option,
              help="glTF / USD blendshapes: number of PCA morph targets (default: as many as the tolerance "
                   "needs), or 'all' for one per frame (short clips).")
@click.option("--tolerance", type=FiniteRange(0, 1, min_open=True),
              help="glTF / USD blendshapes: largest vertex error allowed, as a fraction of the face size "
                   "(default 1e-3).")
@click.option("--fps", type=FiniteRange(0, 240, min_open=True),
              help="Frames per second of the output (default: the model's, 25): e.g. 24 for film, 30 or 60 "
                   "for games; the network's frames are resampled, lips and closures intact.")
@click.option("--on-mismatch", type=click.Choice(["error", "warn"]), default="error", show_default=True,
              help="A transcript that does not match the speech: refuse it, or animate with a warning (the "
                   "metadata's transcript_match holds the score either way).")
@click.option("--blink-rate", type=FiniteRange(0, 120), default=17.0, show_default=True, metavar="PER_MIN",
              help="Blinks per minute, timed by the speech (more at pauses and phrase ends); 0 = none.")
@click.option("--seed", type=click.IntRange(0, 2**32 - 1), default=0, show_default=True,
              help="Seed of the random layers (blinks): the same inputs and seed give the same files.")
@click.option("--head-motion", type=FiniteRange(0, 3), default=1.0, show_default=True, metavar="AMOUNT",
              help="How much the head moves with the voice (nods, tilts, drift; written as a transform where "
                   "the format has one): 0 = still, 1 = as people do.")
@click.option("--lip-seal/--no-lip-seal", default=True, show_default=True,
              help="Shut the lips on p, b and m where the model leaves them apart (--no-lip-seal: the "
                   "model's lips as they are).")
@click.option("--emotion", metavar="LABEL[:INTENSITY]",
              help="An emotion over the whole clip, on top of what the words do: neutral, happy, sad, angry, "
                   "surprised, afraid or disgusted, intensity 0-1 (default 1), e.g. happy:0.6.")
@click.option("--language", "-l", default="en", show_default=True, metavar="CODE",
              help="The transcript's language (`facegen languages` lists them): its words are aligned with "
                   "their pronunciation there.")
@click.option("--strength", metavar="REGION=SCALE,...",
              help="Scale the model's motion by region: lips, jaw (the rest of the lower face), upper "
                   "(brows, lids, forehead), 0-3 each (1 = as it is), e.g. lips=1.2,jaw=0.8,upper=1.5.")
@click.option("--preview", type=click.Path(dir_okay=False),
              help="Also render a preview video (.mp4) with sound.")
@click.option("--device", type=DEVICE, default="auto", show_default=True,
              help="Where the network runs: auto = a CUDA GPU when there is one, else the CPU.")
@click.option("--quiet", "-q", is_flag=True, help="No progress messages.")
def animate(audio, text, text_file, alignment, no_text, speaker, model, template, text_model, output,
            usd_mode, usd_clips, rig, morph_targets, tolerance, fps, on_mismatch, blink_rate, seed,
            head_motion, lip_seal, emotion, language, strength, preview, device, quiet):
    """Animate the face for AUDIO and write OUTPUT."""
    from facegen.atomic import output_folders

    one_of(text=text, text_file=text_file, alignment=alignment, no_text=no_text)
    with output_folders(output, preview):  # made as needed, removed again when nothing is written
        _animate(audio, text, text_file, alignment, no_text, speaker, model, template, text_model, output,
                 usd_mode, usd_clips, rig, morph_targets, tolerance, fps, on_mismatch, preview, device, quiet,
                 blink_rate=blink_rate, seed=seed, emotion=emotion, head_motion=head_motion,
                 strength=strength, language=language, lip_seal=lip_seal)


def _animate(audio, text, text_file, alignment, no_text, speaker, model, template, text_model, output,
             usd_mode, usd_clips, rig, morph_targets, tolerance, fps, on_mismatch, preview, device, quiet, *,
             blink_rate, seed, emotion, head_motion, strength, language, lip_seal):
    from facegen.animator import Animator
    from facegen.atomic import Transaction
    from facegen.exchange.plan import plan_write
    from facegen.expression import parse_emotion

    emotion = parse_emotion(emotion)  # a bad label or intensity: before any work
    from facegen.strength import parse_strength

    strength = parse_strength(strength)
    from facegen.languages import check_language, check_script

    language = check_language(language).code

    options = {k: v for k, v in (("mode", usd_mode), ("clips", usd_clips), ("rig", rig),
                                 ("morph_targets", morph_targets), ("tolerance", tolerance)) if v is not None}
    # everything the path and options decide fails before any work: extension, folders, sidecar, options
    plan = plan_write(output, options=options, audio_source=audio, preview=preview)
    protect_inputs(plan.outputs, transcript=text_file, alignment=alignment, model=model, template=template)
    if alignment:  # a FIFO, a device, a folder or an oversized file: refused before the model loads
        from facegen.alignment_files import check_alignment_file

        check_alignment_file(alignment)
    if preview:
        from facegen.render import check_output

        check_output(preview)
    transcript = read_text(text, text_file)
    if transcript:
        check_script(transcript, check_language(language))
    from facegen.expression import emotion_spans

    emotion_spans(transcript)  # bad markup: before any work
    animator = Animator(model, text_model=text_model, device=device)
    if plan.rig == "arkit":  # ARKit weights need the rig's regions: checked before work
        # the model loads for the check: its transcript's alignment starts first, so the two overlap
        animator.align_ahead(audio, text=transcript, alignment=alignment, no_text=no_text, language=language)
        plan.check_template(animator.mesh(template))
    # notes are "facegen: ..." lines (not "warning:"), said also with --quiet
    reporter = Reporter.stderr(quiet).noting(say_stderr)
    # plan.streams: the writer reads frames block by block, no [T, V, 3] array in memory
    anim = animator.animate(audio, text=transcript, alignment=alignment, no_text=no_text, speaker=speaker,
                            template=template, fps=fps, stream=plan.streams, reporter=reporter,
                            meanwhile=plan.import_writer, on_mismatch=on_mismatch, blink_rate=blink_rate,
                            seed=seed, emotion=emotion, head_motion=head_motion, strength=strength,
                            language=language, lip_seal=lip_seal)
    from facegen.word_timing import RECOGNISED

    if anim.metadata.get("word_timing") == RECOGNISED:  # what drives the face without a transcript: say it
        from facegen.recognition import SURE

        words = anim.metadata["words"]
        unsure = sum(w.get("confidence", 1.0) < SURE for w in words)
        heard = " ".join(w["word"] + ("?" if w.get("confidence", 1.0) < SURE else "") for w in words)
        unsure_note = f" ({unsure} unsure words, marked ?, leave the brows neutral)" if unsure else ""
        reporter.note(f"heard: {heard or '(no words)'}{unsure_note}")
    from facegen.exchange.controls import dropped
    from facegen.runtime import warn_stderr

    # a control asked for that the format cannot carry: one warning line each (no head made: none to carry)
    asked = {"fps": fps, "head_motion": head_motion if anim.head is not None else 0.0,
             "blink_rate": blink_rate, "seed": seed, "emotion": emotion, "strength": strength}
    for line in dropped(output, asked):
        warn_stderr(line)
    with Transaction():  # all or nothing: no animation without the preview asked for
        written = plan.write(anim)
        from facegen.exchange.wav import is_same_file

        kept = [p for p in written if is_same_file(audio, p)]  # clip.wav -> clip.usda: referenced
        uses = f"; its audio: the input {kept[0]}, referenced" if kept else ""
        reporter.progress(f"wrote {', '.join(str(p) for p in written if p not in kept)} ({anim.num_frames} "
                          f"frames at {anim.fps:g} fps{uses})")
        if preview:
            from facegen.render import render_animation

            result = render_animation(anim, preview, reporter=reporter)
            for note in result.notes:
                reporter.progress(note)
            reporter.progress(f"wrote {result.path} ({result.width}x{result.height}, "
                              f"{result.seconds:.1f} s to render)")
