"""The package's layout is its architecture: each layer imports only the layers below it
(docs/design.md), every subpackage is reachable from `import mjzoo`, and every name a
subpackage exports exists. Checked from the source with `ast`, so no module is imported
for the layering check."""

from __future__ import annotations

import ast
import importlib
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SOURCES = {"mjzoo": ROOT / "lib", "mjzoo.algorithms": ROOT / "algorithms", "mjzoo.envs": ROOT / "envs"}
SUBPACKAGES = ("catalog", "learning", "planning", "robots", "harness", "interop", "algorithms", "envs")
# What each layer may import from mjzoo; "core" is any module at the package's root.
ALLOWED = {
    "core": {"core"},
    "catalog": {"core", "catalog"},
    "learning": {"core", "learning"},
    "planning": {"core", "planning"},
    "robots": {"core", "catalog", "robots"},  # models and terrain: the terrain's items are catalog-shaped
    "harness": {"core", "catalog", "learning", "planning", "robots", "harness"},
    "interop": {"core", "catalog", "learning", "planning", "robots", "interop"},
    "algorithms": {"core", "catalog", "learning", "planning", "harness", "interop", "algorithms"},
    "envs": {"core", "catalog", "learning", "planning", "robots", "harness", "interop", "envs"},
}
# The `mjzoo` command (the package mjzoo.harness.cli) is the application on top of
# everything: it alone reaches up.
EXCEPTIONS = {"mjzoo.harness.cli": {"algorithms", "envs", "interop"}, "mjzoo.__main__": {"harness"}}
# The guide is 150-400 lines of one concept, and a concept is never split to meet it; past
# this, a module holds more than one concept.
MAX_LINES = 800
LAZY_CORE = ("testing", "motion")  # core modules `import mjzoo` loads on first use


def modules() -> dict[str, Path]:
    """Every module of the distribution by its dotted name."""
    found = {}
    for package, folder in SOURCES.items():
        for path in sorted(folder.rglob("*.py")):
            parts = path.relative_to(folder).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            if parts[:1] == ("assets",):
                continue
            found[".".join((package, *parts))] = path
    return found


def layer(module: str) -> str:
    """The layer a dotted mjzoo module name belongs to."""
    parts = module.split(".")
    if len(parts) > 1 and parts[1] in SUBPACKAGES:
        return parts[1]
    return "core"


def imported(path: Path, module: str) -> set[str]:
    """The mjzoo modules `path` imports (absolute and relative), at any depth."""
    names = set()
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(
                    package.split(".")[: len(package.split(".")) - node.level + 1] + ([base] if base else [])
                )
            # `from mjzoo import catalog` imports the subpackage, `from mjzoo import tree` a core module
            names |= {f"{base}.{a.name}" if base == "mjzoo" else base for a in node.names}
    return {n for n in names if n == "mjzoo" or n.startswith("mjzoo.")}


@pytest.mark.parametrize("module", sorted(modules()))
def test_imports_follow_the_layers(module):
    owner = next((m for m in EXCEPTIONS if module == m or module.startswith(m + ".")), None)
    allowed = ALLOWED[layer(module)] | EXCEPTIONS.get(owner, set())
    wrong = sorted(m for m in imported(modules()[module], module) if layer(m) not in allowed)
    assert not wrong, f"{module} ({layer(module)}) imports {wrong}; its layer may import {sorted(allowed)}"


def test_modules_hold_one_concept_in_at_most_800_lines():
    long = {m: n for m, p in modules().items() if (n := p.read_text().count("\n")) > MAX_LINES}
    assert not long, f"modules over {MAX_LINES} lines: {long}"


def test_import_mjzoo_reaches_every_subpackage():
    """In a fresh interpreter: `import mjzoo` alone, then each subpackage (and each lazily
    loaded core module) as an attribute."""
    code = "import mjzoo; print([type(getattr(mjzoo, name)).__name__ for name in mjzoo.SUBPACKAGES])"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == str(["module"] * len(SUBPACKAGES + LAZY_CORE))


@pytest.mark.parametrize("package", ["mjzoo", *(f"mjzoo.{name}" for name in SUBPACKAGES + LAZY_CORE)])
def test_exported_names_exist(package):
    module = importlib.import_module(package)
    exported = getattr(module, "__all__", None)
    assert exported, f"{package} has no __all__"
    assert module.__doc__, f"{package} has no docstring"
    missing = [name for name in exported if getattr(module, name, None) is None]
    assert not missing, f"{package}.__all__ names what it lacks: {missing}"


def test_every_package_is_installed():
    """A non-editable install ships only the packages pyproject.toml lists: each folder
    with an __init__.py must be there (mjzoo.harness.cli once was not)."""
    import tomllib

    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    packages = {m for m, p in modules().items() if p.name == "__init__.py"}
    assert packages <= listed, f"pyproject.toml [tool.setuptools] packages lacks {sorted(packages - listed)}"


def import_graph() -> dict[str, set[str]]:
    """Module -> the modules of the distribution it imports (anywhere in its source,
    function bodies included): ``from a.b import c`` imports the module a.b.c if there is
    one, else a.b. Packages are left out: importing a module imports its packages first,
    which is no cycle, and a package's ``__init__`` re-exports its modules."""
    known = modules()
    packages = {m for m, p in known.items() if p.name == "__init__.py"}
    graph = {}
    for module, path in known.items():
        if module in packages:
            continue
        package = module.rpartition(".")[0]
        found = set()
        for node in _run_time_nodes(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                found |= {a.name for a in node.names}
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(parts + ([base] if base else []))
                found |= {f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in node.names}
        graph[module] = {m for m in found if m in known and m not in packages}
    return graph


def _run_time_nodes(tree: ast.AST):
    """Every node of `tree` but those under ``if TYPE_CHECKING:``: imports for annotations
    only, never run, so no cycle."""
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, ast.If) and ast.unparse(node.test) in ("TYPE_CHECKING", "typing.TYPE_CHECKING"):
            yield from (n for child in node.orelse for n in [child, *_run_time_nodes(child)])
            continue
        yield node
        yield from _run_time_nodes(node)


def cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of `graph` as [a, b, ..., a], or None (depth-first search)."""
    done, path = set(), []

    def visit(node: str) -> list[str] | None:
        if node in path:
            return path[path.index(node) :] + [node]
        if node in done:
            return None
        path.append(node)
        for other in sorted(graph.get(node, ())):
            if found := visit(other):
                return found
        path.pop()
        done.add(node)
        return None

    return next((c for node in sorted(graph) if (c := visit(node))), None)


def test_cycle_finds_a_circle_and_only_one():
    assert cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None


def test_the_core_types_import_neither_running_nor_parameters():
    assert not import_graph()["mjzoo.types"] & {"mjzoo.running", "mjzoo.parameters"}


def test_the_package_imports_without_circles():
    """Not even through an import inside a function: a module that needs another at run
    time sits above it."""
    graph = import_graph()
    assert cycle(graph) is None, f"an import cycle: {' -> '.join(cycle(graph))}"


def test_project_files_speak_of_the_project_not_its_tracker():
    """A tracker's issue number in the README, docs or code means nothing to a user, who
    has no tracker: say what it was (results files keep their recorded notes)."""
    pattern = re.compile(r"\bissues? #?\d+", re.IGNORECASE)
    files = [ROOT / "README.md", *(ROOT / "docs").rglob("*.md")]
    files += [
        p
        for folder in ("lib", "algorithms", "envs", "benchmarks", "scripts", "tests")
        for p in (ROOT / folder).rglob("*.py")
    ]
    found = [
        f"{path.relative_to(ROOT)}:{number}: {line.strip()}"
        for path in files
        for number, line in enumerate(path.read_text().splitlines(), 1)
        if pattern.search(line)
    ]
    assert not found, "\n".join(found)
