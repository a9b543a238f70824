"""Forced alignment started ahead, in a process of its own, while the caller loads the model and the text
model and computes the clip's features.

A new `facegen animate` spends a few tenths of a second loading the bundle and the text model and computing
the clip's mel and word features, and as long again or longer aligning the transcript (a minute of speech:
3-4 s): pocketsphinx holds the GIL, so a thread cannot overlap the two, but a forked process can, on the
second core. `start` forks only where that is safe (no other Python thread, torch not imported: its OpenMP
pool does not survive a fork; facegen's CPU inference never imports it) and returns an `AlignAhead` whose
`result()` gives what `align.align_checked` would have given in this process (the same code on the same
audio: the same words and phones), or raises their FacegenError. A child that dies without an answer
(killed, a bug) makes `result()` return None: the caller aligns in its own process, where any error shows as
usual.

`start` returns None, and the caller aligns in-process as before, where overlapping gains nothing or is not
safe: torch imported (a script that uses it, a CUDA run), other threads running, no `fork` (Windows, macOS
defaults), or a single core. The Animator asks only before its model is loaded (not in a batch worker,
whose model is loaded once for all its clips).

`align_file` aligns in the calling process and returns an `Aligned`, which answers `result()` the same way:
a batch's main process aligns waiting items with it while its workers start (engines.run_local).
"""

from __future__ import annotations

import os
import sys
import threading
import time
from dataclasses import dataclass

from facegen.errors import FacegenError
from facegen.processes import start_process
from facegen.runtime import PROFILE, cores


@dataclass
class Aligned:
    """A forced alignment done already: the words, phones (None without) and the transcript's Match (not
    refused here: the caller decides, facegen.word_timing.forced), or the FacegenError's message; `seconds`
    and `cpu_seconds` it took where it ran."""

    words: list | None = None
    phones: list | None = None
    match: object = None  # facegen.transcript_match.Match
    error: str | None = None
    error_param: str | tuple[str, ...] | None = None  # the parameter the FacegenError names
    seconds: float = 0.0
    cpu_seconds: float = 0.0

    def result(self) -> tuple[list, list | None, object]:
        """(words, phones or None, Match) as align.align_checked gives them; raises its FacegenError."""
        if self.error is not None:
            raise FacegenError(self.error, param=self.error_param)
        PROFILE.add("alignment_in_parallel", self.seconds)
        return self.words, self.phones, self.match

    def ready(self) -> bool:
        """Done already: always."""
        return True

    def close(self) -> None:
        """Nothing runs: nothing to stop."""


def align_file(audio: str | os.PathLike, text: str, with_phones: bool, language: str = "en") -> Aligned:
    """Align `text` (in `language`) to the audio file `audio` here (with its phones if `with_phones`), as the
    clip's own animation would: read with load_audio, aligned by align.align_checked."""
    from facegen import align
    from facegen.audio import load_audio

    start, cpu = time.perf_counter(), time.process_time()
    try:
        samples, rate = load_audio(audio)
        done = align.align_checked(samples, rate, text, with_phones, language)
        found = Aligned(done.words, done.phones, done.match)
    except FacegenError as exc:
        found = Aligned(error=str(exc), error_param=exc.param)
    found.seconds, found.cpu_seconds = time.perf_counter() - start, time.process_time() - cpu
    return found


class AlignAhead:
    """The forked aligner of one clip: `result()` waits for it, `close()` stops it."""

    def __init__(self, process, receiver) -> None:
        self._process, self._receiver = process, receiver

    def ready(self) -> bool:
        """Whether `result()` would answer at once (the child has answered, or is gone)."""
        try:
            return self._receiver.poll()
        except (EOFError, OSError):
            return True

    def result(self) -> tuple[list, list | None, object] | None:
        """(words, phones or None, Match) as align.align_checked gives them, None when the child gave no
        answer; raises the child's FacegenError. The child's own alignment time is the profile's
        "alignment_in_parallel"."""
        try:
            answer = self._receiver.recv()
        except (EOFError, OSError):
            answer = None
        finally:
            self.close()
        return None if answer is None else answer.result()

    def close(self) -> None:
        """Stop the child if it still runs (the caller failed or was interrupted) and reap it."""
        if self._process.is_alive():
            self._process.kill()
        self._process.join()
        self._receiver.close()


def start(audio: str | os.PathLike, text: str, with_phones: bool, language: str = "en") -> AlignAhead | None:
    """Fork a process aligning `text` to the audio file `audio` (with its phones if `with_phones`), or None
    where that is not worth it or not safe (see the module docstring)."""
    from multiprocessing import Pipe

    if "torch" in sys.modules or threading.active_count() > 1 or not text.strip() or cores() < 2:
        return None
    receiver, sender = Pipe(duplex=False)
    process = start_process(_child, (sender, str(audio), text, with_phones, language), start="fork",
                            name="facegen-align")
    sender.close()
    if process is None:  # no fork on this platform
        receiver.close()
        return None
    return AlignAhead(process, receiver)


def _child(sender, audio: str, text: str, with_phones: bool, language: str) -> None:
    """In the forked process: align and send the Aligned (its words, phones or error)."""
    import signal

    for name in ("SIGINT", "SIGTERM", "SIGHUP"):  # the parent decides: it kills this process when it stops
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), signal.SIG_DFL)
    answer = None  # a bug leaves no answer: the parent aligns itself and reports it there
    try:
        answer = align_file(audio, text, with_phones, language)
    except Exception:  # noqa: BLE001, S110 - no traceback here: the parent's own alignment shows it
        pass
    try:
        if answer is not None:
            sender.send(answer)
    finally:
        sender.close()
