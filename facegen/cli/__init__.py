"""The `facegen` command line: the click group, the exit codes, and `main`, the process's entry point.

One module per command group beside this one (animate, align, files: render and validate, batch, model: info,
train and evaluate, data), each a thin layer over a library function; options.py holds what they share.
Errors a user can cause (FacegenError, bad options) print one line and exit 2; `--debug` shows the traceback.
Heavy libraries are imported inside the commands so `facegen --help` stays fast, and the `facegen` process
ends without the interpreter's teardown once its outputs are written and its streams flushed (`main`).
"""

from __future__ import annotations

import sys

import click

from facegen import __version__
from facegen.cli.align import align
from facegen.cli.animate import animate
from facegen.cli.batch import batch
from facegen.cli.data import data
from facegen.cli.files import render, validate
from facegen.cli.languages import languages
from facegen.cli.model import evaluate, info, train
from facegen.errors import FacegenError


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="facegen")
@click.option("--debug", is_flag=True, help="Show tracebacks for errors.")
def cli(debug: bool) -> None:
    """Speech (audio + transcript) to expressive 3D face animation in USD, glTF and npy."""


for _command in (animate, render, align, languages, info, validate, batch, train, evaluate, data):
    cli.add_command(_command)


def main(argv: list[str] | None = None) -> None:
    """Run the command line `argv` and exit: 0 done, 1 a check or item failed (or an internal error), 2 a user
    error (one line), 130 Ctrl-C, 128 + N signal N.

    Called without `argv` (the `facegen` script, `python -m facegen`) it is the whole process: once the
    command has returned (its outputs written, closed and renamed into place), it runs the atexit handlers
    (the FACEGEN_PROFILE report among them), flushes stdout and stderr and ends with os._exit, skipping the
    interpreter's teardown (about a second of freeing torch's and pxr's objects). With `argv` (tests, callers
    in a process of their own) it raises SystemExit as usual. `--debug` lets errors propagate with their
    traceback, through the usual exit.
    """
    import os

    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # before torch loads OpenMP: no spinning threads
    whole_process = argv is None
    argv = sys.argv[1:] if argv is None else argv
    debug = "--debug" in argv
    from facegen.runtime import stop_on_signals

    stop_on_signals()
    try:
        code = _run(argv, debug)
    except SystemExit as exc:  # a command's own exit code (validate: 1 when a check fails, batch: 1 ...)
        code = exc.code
    if not isinstance(code, int):  # sys.exit() or sys.exit("message"), as Python ends on them
        if code is not None:
            click.echo(str(code), err=True)
        code = 0 if code is None else 1
    if whole_process:
        _exit_now(code)
    sys.exit(code)


def _run(argv: list[str], debug: bool) -> int:
    """The command's exit code; errors a user can cause, interrupts and internal errors said in one line."""
    from facegen.runtime import Terminated

    try:
        cli.main(args=argv, prog_name="facegen", standalone_mode=False)
        return 0
    except FacegenError as exc:
        if debug:
            raise
        click.echo(f"facegen: error: {exc}", err=True)
        return 2
    except click.exceptions.Abort as exc:  # click turns KeyboardInterrupt into Abort
        return _interrupted(exc.__cause__)
    except click.ClickException as exc:
        hint = f" (see '{exc.ctx.command_path} --help')" if getattr(exc, "ctx", None) else ""
        click.echo(f"facegen: error: {exc.format_message()}{hint}", err=True)
        return exc.exit_code
    except (KeyboardInterrupt, Terminated) as exc:
        return _interrupted(exc)
    except Exception as exc:
        if debug:
            raise
        click.echo(f"facegen: internal error: {type(exc).__name__}: {exc} (rerun with --debug and report it)",
                   err=True)
        return 1


def _exit_now(code: int) -> None:
    """End the process with `code` without the interpreter's teardown, after what the interpreter would
    still do that matters: wait for non-daemon threads, run the atexit handlers (the profile report,
    multiprocessing's clean-up), flush stdout and stderr."""
    import atexit
    import os
    import threading

    for thread in threading.enumerate():
        if thread is not threading.current_thread() and not thread.daemon:
            thread.join()
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (AttributeError, OSError, ValueError):  # closed, or its reader went away (facegen ... | head)
            pass
    os._exit(code)


def _interrupted(exc: BaseException | None) -> int:
    """The exit code after Ctrl-C (130) or SIGTERM/SIGHUP (128 + the signal), said in one line."""
    from facegen.runtime import Terminated

    if isinstance(exc, Terminated):
        import signal

        click.echo(f"facegen: stopped by {signal.Signals(exc.signum).name}", err=True)
        return 128 + exc.signum
    click.echo("facegen: interrupted", err=True)
    return 130
