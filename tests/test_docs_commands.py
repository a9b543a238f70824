"""Every facegen command in README.md and docs/*.md runs as written on a fresh clone (issue 22).

What is extracted, from README.md and every docs/*.md, in document order:
- every line of a fenced code block whose info string is sh, bash, shell or console that starts with
  `facegen ` (in a console block: `$ facegen `);
- every line of an indented code block (four or more spaces, outside fenced blocks) that starts with
  `facegen `;
- a line ending in a backslash continues on the next line, as in the shell.
Words are split as the shell splits them (shlex); a trailing `# ...` is a comment. Inline code in prose is
not a command; fenced blocks in other languages (python, js, yaml) are not searched, but a fenced block
without a language must hold no `facegen ` line (a command there would escape this test).

Marks, in the trailing comment:
- `# needs: WHAT`: the command needs what a test cannot give (a data set, a cluster, hours). It is parsed
  only: click resolves the subcommand and converts and checks every option and argument (`make_context`),
  nothing runs;
- `# exits N: WHY`: the command runs and must end with exit code N (e.g. validate's 1 when a check fails).
Every other command runs for real as `python -m facegen ARGS`, with the current folder a temporary one holding
a copy of examples/ (as the repository root of a fresh clone), the commands of one document one after another
in document order (a command may use what an earlier one wrote, as a reader following the page would), and
must exit 0.
"""

from __future__ import annotations

import re
import shlex
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import click
import pytest

REPO = Path(__file__).resolve().parents[1]
DOCUMENTS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
SHELL_BLOCKS = {"sh", "bash", "shell", "console"}
UNTAGGED = "a language on its block"
MARK = re.compile(r"\s#\s*(needs|exits (\d+)):\s*(.*)$")


@dataclass(frozen=True)
class Command:
    """One documented command: its words after `facegen`, where it is, and its mark."""

    args: tuple[str, ...]
    document: str
    line: int
    needs: str | None = None  # what it needs that a test cannot give: parsed only
    exit_code: int = 0

    def __str__(self) -> str:
        return f"{self.document}:{self.line}: facegen {shlex.join(self.args)}"


def command_lines(text: str) -> list[tuple[int, str, str | None]]:
    """(line number, command line, info string of its fenced block or None for an indented one) for every
    line that starts with `facegen ` in a code block, continuation lines joined; untagged fenced blocks too,
    with the info string ''."""
    found, fence, continued = [], None, None
    lines = text.splitlines()
    for number, raw in enumerate(lines, 1):
        stripped = raw.strip()
        if continued is not None:
            start, kind, words = continued
            words += " " + stripped.removesuffix("\\").strip()
            continued = (start, kind, words) if stripped.endswith("\\") else None
            if continued is None:
                found.append((start, words, kind))
            continue
        if stripped.startswith("```"):
            fence = None if fence is not None else stripped[3:].strip().lower()
            continue
        if fence is not None:
            kind = fence
            if fence == "console":  # commands after the prompt; the other lines are their output
                line = stripped[2:] if stripped.startswith("$ ") else ""
            else:
                line = stripped
        elif raw.startswith("    ") and (number == 1 or not lines[number - 2].strip() or
                                        lines[number - 2].startswith("    ")):
            kind, line = None, stripped
        else:
            continue
        if not line.startswith("facegen "):
            continue
        if line.endswith("\\"):
            continued = (number, kind, line.removesuffix("\\").strip())
        else:
            found.append((number, line, kind))
    return found


def extract(text: str, document: str) -> list[Command]:
    """The facegen commands of one document (see the module's docstring), in document order; those in a
    fenced block without a language with needs "a language on its block" (test_no_untagged_commands)."""
    commands = []
    for number, line, kind in command_lines(text):
        if kind is not None and kind not in SHELL_BLOCKS | {""}:
            continue
        mark = MARK.search(line)
        words = shlex.split(line, comments=True)
        needs = mark.group(3).strip() if mark and mark.group(1) == "needs" else None
        needs = UNTAGGED if kind == "" else needs
        exit_code = int(mark.group(2)) if mark and mark.group(2) else 0
        commands.append(Command(tuple(words[1:]), document, number, needs, exit_code))
    return commands


COMMANDS = {name: extract((REPO / name).read_text(encoding="utf-8"), name)
            for name in (path.relative_to(REPO).as_posix() for path in DOCUMENTS)}


def parse_only(command: Command) -> None:
    """Resolve the command's subcommand and parse its options and arguments as click does before running it
    (types, choices, ranges, required ones, callbacks); raises click's UsageError when one is wrong."""
    from facegen.cli import cli

    ctx = click.Context(cli, info_name="facegen")
    name, sub, words = cli.resolve_command(ctx, list(command.args))
    while isinstance(sub, click.Group):
        ctx = click.Context(sub, info_name=name, parent=ctx)
        name, sub, words = sub.resolve_command(ctx, words)
    with sub.make_context(name, words, parent=ctx, resilient_parsing=False):
        pass


def test_extraction_reads_blocks_marks_and_continuations():
    text = """
```sh
facegen animate a.wav --text "one # two" -o out/a.npy   # a comment
facegen train data -o m.safetensors \\
    --epochs 1   # needs: BIWI data
make demo
```

```python
facegen.animate("a.wav")
```

```console
$ facegen info
facegen        0.1.0
```

```yaml
entrypoint: facegen batch lines.csv -o out
```

```
facegen/  errors.py
```

    facegen validate out/a.npy   # exits 1: a failed check
"""
    lines = command_lines(text)
    assert [(n, k) for n, _, k in lines] == [(3, "sh"), (4, "sh"), (14, "console"), (26, None)]
    first, second, info, third = extract(text, "sample.md")
    assert info.args == ("info",)
    assert first.args == ("animate", "a.wav", "--text", "one # two", "-o", "out/a.npy")
    assert first.needs is None and first.exit_code == 0
    assert second.args == ("train", "data", "-o", "m.safetensors", "--epochs", "1")
    assert second.needs == "BIWI data"
    assert third.args == ("validate", "out/a.npy") and third.exit_code == 1
    (untagged,) = extract("```\nfacegen info\n```\n", "sample.md")
    assert untagged.needs == UNTAGGED  # test_no_untagged_commands fails on it


def test_no_untagged_commands():
    """A command in a fenced block without a language would be neither run nor marked: none may be there."""
    assert [str(c) for cs in COMMANDS.values() for c in cs if c.needs == UNTAGGED] == []


def test_docs_have_their_commands():
    """The documents this test is for hold commands, and the README's first animates the shipped example
    with its whole transcript (issue 22: it used to give half of it)."""
    assert {"README.md", "docs/dcc.md", "docs/scale.md"} <= {d for d, c in COMMANDS.items() if c}
    readme = COMMANDS["README.md"]
    assert readme[0].args[:2] == ("animate", "examples/excellent_room.wav")
    transcript = (REPO / "examples" / "excellent_room.txt").read_text(encoding="utf-8").strip()
    for command in (c for commands in COMMANDS.values() for c in commands):
        if "--text" in command.args and "examples/excellent_room.wav" in command.args:
            assert command.args[command.args.index("--text") + 1] == transcript, str(command)
    assert sum(c.needs is None for c in readme) >= 15


def parse_error(command: Command) -> str | None:
    """What click (or an option's own check) says is wrong with the command, or None."""
    from facegen.errors import FacegenError

    try:
        parse_only(command)
    except click.ClickException as exc:
        return exc.format_message()
    except FacegenError as exc:  # an option's callback (e.g. --usd-clips) refuses its value
        return str(exc)
    return None


@pytest.mark.parametrize("args, fragment", [
    (("animate", "in.wav", "--bogus", "-o", "a.npy"), "No such option"),
    (("animate", "in.wav"), "Missing option"),
    (("data", "synthh", "out"), "No such command"),
    (("train", "data", "-o", "m.safetensors", "--epochs", "0"), "not in the range"),
    (("animate", "in.wav", "-o", "a.usdc", "--usd-clips", "zz"), "USD clips must be"),
])
def test_parse_only_refuses_wrong_commands(args, fragment):
    assert fragment in (parse_error(Command(args, "sample.md", 1)) or "")


@pytest.mark.parametrize("command", [c for commands in COMMANDS.values() for c in commands], ids=str)
def test_every_command_parses(command):
    """Every documented command, marked or not, names a real subcommand with valid options and arguments."""
    assert parse_error(command) is None, f"{command}: {parse_error(command)}"


@pytest.mark.parametrize("document", [d for d, c in COMMANDS.items() if any(x.needs is None for x in c)])
def test_document_commands_run(document, tmp_path):
    """The document's unmarked commands run in order in a fresh copy of examples/ and end as documented."""
    shutil.copytree(REPO / "examples", tmp_path / "examples")
    took = []
    for command in COMMANDS[document]:
        if command.needs is not None:
            continue  # parsed in test_every_command_parses
        start = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "facegen", *command.args], check=False,
                              cwd=tmp_path, capture_output=True, text=True, timeout=600)
        took.append(f"{time.perf_counter() - start:5.1f} s  {command}")
        assert proc.returncode == command.exit_code, (
            "\n".join(took) + f"\n{command}\nexit {proc.returncode}, documented {command.exit_code}\n"
            f"stdout: {proc.stdout[-1500:]}\nstderr: {proc.stderr[-1500:]}")
    print("\n".join(took))
