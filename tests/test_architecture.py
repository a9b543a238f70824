"""The package's shape: imports run one way (the layers of docs/architecture.md), modules stay small, lines
stay short (ruff), tests stand alone."""

import ast
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "facegen"
TESTS = Path(__file__).resolve().parent
ARCHITECTURE = ROOT / "docs" / "architecture.md"
MAX_LINES = 500


def module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for p in PACKAGE.rglob("*.py")}


def _is_type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def imports_of(name: str, path: Path, known: set[str]) -> set[str]:
    """Every facegen module `name` imports, at top level or inside functions (not under TYPE_CHECKING)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()

    def visit(node: ast.AST) -> None:
        if name != "facegen":  # modules loaded by name: importlib's argument, a list of modules to preload
            named = []
            if isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) in (
                    "import_module", "__import__") and node.args:
                named = node.args[:1]
            elif isinstance(node, ast.List | ast.Tuple | ast.Set):
                named = node.elts
            found.update(n.value for n in named if isinstance(n, ast.Constant) and n.value in known
                         and "." in str(n.value))
        if isinstance(node, ast.If) and _is_type_checking(node):
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name in known)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                if sub in known:
                    found.add(sub)
                elif base in known:
                    found.add(base)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(ast.parse(path.read_text()))
    found.discard(name)
    return found


def import_graph() -> dict[str, set[str]]:
    mods = modules()
    known = set(mods)
    return {name: imports_of(name, path, known) for name, path in mods.items()}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    stack: list[str] = []

    def dfs(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state and (cycle := dfs(nxt)):
                return cycle
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (cycle := dfs(node)):
            return cycle
    return None


def test_graph_sees_imports_inside_functions():
    graph = import_graph()
    assert "facegen.errors" in graph["facegen.cli"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


def test_no_import_cycles():
    cycle = find_cycle(import_graph())
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def layers() -> list[tuple[str, list[str]]]:
    """The layers of docs/architecture.md, bottom up: (name, module patterns) from the table under "## The
    layers, bottom up", patterns as written there (`errors.py`, `exchange/`, `exchange/usd.py`)."""
    text = ARCHITECTURE.read_text()
    section = text.split("## The layers, bottom up", 1)[1].split("\n## ", 1)[0]
    rows = []
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) >= 2 and cells[0] and not set(cells[0]) <= set("-: ") and cells[0] != "layer":
            rows.append((cells[0], re.findall(r"`([\w/]+(?:\.py|/))`", cells[1])))
    return rows


def layer_of(module: str, table: list[tuple[str, list[str]]]) -> int | None:
    """The index of the layer whose most specific pattern covers `module` (facegen.exchange.usd)."""
    best: tuple[int, int] | None = None  # (specificity, layer)
    for index, (_, patterns) in enumerate(table):
        for pattern in patterns:
            name = "facegen." + pattern.removesuffix("/").removesuffix(".py").replace("/", ".")
            covers = module == name or (pattern.endswith("/") and module.startswith(name + "."))
            if covers and (best is None or len(name) > best[0]):
                best = (len(name), index)
    return None if best is None else best[1]


def test_every_module_has_a_layer():
    table = layers()
    assert len(table) >= 8, table
    unplaced = sorted(m for m in modules() if m != "facegen" and layer_of(m, table) is None)
    assert unplaced == [], f"modules in no layer of {ARCHITECTURE.name}: {unplaced}"


def test_imports_follow_the_layers():
    """No module imports one of a higher layer (top-level, inside functions, or by name)."""
    table = layers()
    upward = []
    for module, imported in import_graph().items():
        if module == "facegen":  # the package's lazy API is the top surface
            continue
        mine = layer_of(module, table)
        for other in imported:
            theirs = layer_of(other, table)
            if mine is not None and theirs is not None and theirs > mine:
                upward.append(f"{module} ({table[mine][0]}) imports {other} ({table[theirs][0]})")
    assert upward == []


def test_the_layer_check_can_fail(tmp_path):
    table = [("low", ["errors.py", "exchange/"]), ("high", ["cli/", "exchange/usd.py"])]
    assert layer_of("facegen.errors", table) == 0
    assert layer_of("facegen.exchange.gltf", table) == 0 and layer_of("facegen.exchange.usd", table) == 1
    assert layer_of("facegen.cli.animate", table) == 1 and layer_of("facegen.train", table) is None
    source = tmp_path / "mod.py"
    source.write_text('import importlib\n"""facegen.cli is named in a docstring"""\n'
                      'ROW = dict(writer="facegen.model")\nPRELOAD = ["torch", "facegen.runtime"]\n'
                      'def f():\n    return importlib.import_module("facegen.cli")\n')
    known = {"facegen.cli", "facegen.errors", "facegen.runtime", "facegen.model"}
    assert imports_of("facegen.mod", source, known) == {"facegen.cli", "facegen.runtime"}


@pytest.mark.skipif(shutil.which("ruff", path=str(Path(sys.executable).parent)) is None and
                    shutil.which("ruff") is None, reason="ruff is not installed (pip install -e '.[test]')")
def test_ruff_is_clean_line_length_included():
    ruff = shutil.which("ruff", path=str(Path(sys.executable).parent)) or shutil.which("ruff")
    config = (ROOT / "pyproject.toml").read_text()
    assert re.search(r"line-length = 110", config) and "E501" in config  # the length is checked, not only set
    proc = subprocess.run([ruff, "check", "--quiet", "facegen", "tests", "benchmarks"], cwd=ROOT,
                          capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-1000:]


def test_no_module_over_500_lines():
    long = {n: len(p.read_text().splitlines()) for n, p in modules().items()}
    assert {n: c for n, c in long.items() if c > MAX_LINES} == {}


def test_no_test_module_imports_another():
    tests = {p.stem for p in TESTS.glob("test_*.py")}
    offenders = []
    for path in TESTS.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
                [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            offenders += [f"{path.name}: {n}" for n in names if n.split(".")[-1] in tests]
    assert offenders == []
