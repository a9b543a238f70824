"""`facegen align`: when each word (and phone) of a transcript is spoken."""

from __future__ import annotations

import json

import click

from facegen.cli.command import Command
from facegen.cli.options import one_of, protect_inputs, read_text
from facegen.errors import FacegenError


@click.command(cls=Command)
@click.argument("audio", type=click.Path(dir_okay=False))
@click.option("--text", "-t", help="The transcript.")
@click.option("--text-file", type=click.Path(dir_okay=False), help="A UTF-8 file with the transcript.")
@click.option("--output", "-o", type=click.Path(dir_okay=False),
              help="words.json, words.TextGrid or words.csv (default: JSON on stdout).")
@click.option("--phones", is_flag=True,
              help="Also write each word's phones (CMU, pocketsphinx phone alignment): a `phones` list / "
                   "tier.")
@click.option("--language", "-l", default="en", show_default=True, metavar="CODE",
              help="The transcript's language (`facegen languages` lists them): its words are aligned with "
                   "their pronunciation there.")
def align(audio, text, text_file, output, phones, language):
    """Find when each word (and with --phones each phone) of the transcript is spoken in AUDIO."""
    from facegen.alignment_files import alignment_format, alignment_json, write_alignment
    from facegen.audio import check_speech, load_audio
    from facegen.languages import check_language, check_script
    from facegen.runtime import Reporter, say_stderr
    from facegen.word_timing import clip_words

    language = check_language(language).code
    one_of(text=text, text_file=text_file)
    protect_inputs([output], audio=audio, transcript=text_file)
    if output:
        alignment_format(output, phones)  # a name facegen writes (with phones: one that holds them)
    samples, sr = load_audio(audio)
    check_speech(samples, sr, 25.0, name=f"audio file {audio}")
    transcript = read_text(text, text_file)
    if transcript:
        check_script(transcript, check_language(language))
    if phones:
        if transcript is None:
            raise FacegenError("--phones needs the transcript: pass --text or --text-file")
        from facegen.align import align_phones

        words, found = align_phones(samples, sr, transcript, language)
    else:
        words = clip_words(samples, sr, text=transcript, reporter=Reporter(note=say_stderr),
                           language=language).words
        found = None
    if output:
        from facegen.atomic import output_folders

        with output_folders(output):  # made as needed, as animate and batch do
            write_alignment(words, output, duration=len(samples) / sr, phones=found)
    else:
        click.echo(json.dumps(alignment_json(words, found), indent=1))
