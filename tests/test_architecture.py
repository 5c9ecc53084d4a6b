"""The package's shape: imports flow one way (docs/architecture.md) and no module imports
itself back through another at import time. Read from the sources (ast), not by importing."""

from __future__ import annotations

import ast
from pathlib import Path

from repo_paths import REPO

PKG = REPO / "pmdcid"
#: lower layers first: a module may import from its own layer and the layers before it only
#: (function-level imports included: a lazy import is still a dependency)
LAYERS = ["errors", "notes", "runtime", "io", "model", "simulate", "synth", "fit",
          "identify", "diagnose", "report", "plan", "export", "pipeline", "files", "fleet",
          "demo", "api", "cli", "__main__"]
#: upward imports allowed, each with its reason (none)
ALLOWED: set[tuple[str, str]] = set()


def _module(path: Path) -> str:
    parts = list(path.with_suffix("").relative_to(PKG.parent).parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _type_only(tree: ast.Module) -> set[int]:
    """ids of the import nodes under ``if TYPE_CHECKING:``: annotations, never run."""
    out: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            out |= {id(n) for b in node.body for n in ast.walk(b)}
    return out


def _imports(path: Path, top_only: bool) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    skip = _type_only(tree)
    nodes = [n for n in (tree.body if top_only else ast.walk(tree)) if id(n) not in skip]
    out: set[str] = set()
    for node in nodes:
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("pmdcid"):
            out.add(node.module)
            for a in node.names:  # `from pmdcid.model import signatures`: the submodule
                if (PKG.parent / (node.module.replace(".", "/") + "/" + a.name + ".py")).exists():
                    out.add(f"{node.module}.{a.name}")
        elif isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.startswith("pmdcid")}
    return out


def _layer(mod: str) -> str | None:
    parts = mod.split(".")
    return parts[1] if len(parts) > 1 else None  # the lazy front door `pmdcid` itself: none


def _sources():
    return sorted(PKG.rglob("*.py"))


def test_sources_are_found():
    mods = {_module(p) for p in _sources()}
    assert {"pmdcid.io.logs", "pmdcid.simulate.kernel", "pmdcid.fit.solver",
            "pmdcid.diagnose.loop", "pmdcid.cli"} <= mods


def test_imports_flow_one_way():
    wrong = []
    for path in _sources():
        mod = _module(path)
        here = _layer(mod)
        for target in _imports(path, top_only=False):
            there = _layer(target)
            if here is None or there is None or here not in LAYERS or there not in LAYERS:
                continue
            if LAYERS.index(there) > LAYERS.index(here) and (mod, target) not in ALLOWED:
                wrong.append(f"{mod} -> {target}")
    assert not wrong, "imports against the layer order: " + "; ".join(sorted(wrong))


def test_every_package_has_a_layer():
    packages = {_layer(_module(p)) for p in _sources()} - {None}
    assert packages <= set(LAYERS), sorted(packages - set(LAYERS))


def find_cycle(graph: dict[str, set[str]]) -> list[str]:
    """A cycle of ``graph`` (module -> modules it imports) as a path, or [] when acyclic."""
    state: dict[str, int] = {}

    def visit(m: str, stack: list[str]) -> list[str]:
        state[m] = 1
        for t in sorted(graph.get(m, ())):
            if state.get(t) == 1:
                return stack[stack.index(t):] + [m, t] if t in stack else [m, t]
            if state.get(t) is None:
                found = visit(t, stack + [m])
                if found:
                    return found
        state[m] = 2
        return []

    for m in sorted(graph):
        if state.get(m) is None:
            found = visit(m, [])
            if found:
                return found
    return []


def _module_graph(top_only: bool) -> dict[str, set[str]]:
    """module -> the package's modules it imports (package ``__init__`` files aside: a package
    runs before its submodules by Python's rules)."""
    graph: dict[str, set[str]] = {}
    for path in _sources():
        if path.name == "__init__.py":
            continue
        mod = _module(path)
        graph[mod] = {t for t in _imports(path, top_only=top_only) if t != mod}
    modules = set(graph)
    return {m: {t for t in ts if t in modules} for m, ts in graph.items()}


def test_no_import_cycle_between_modules():
    """Module-level imports form no cycle."""
    cycle = find_cycle(_module_graph(top_only=True))
    assert not cycle, " -> ".join(cycle)


def test_no_import_cycle_through_function_level_imports():
    """Nor do all imports, those inside functions included (a lazy import is still a
    dependency: two modules that need each other are one idea split in two). Imports under
    ``if TYPE_CHECKING:`` are annotations only and are not counted."""
    cycle = find_cycle(_module_graph(top_only=False))
    assert not cycle, " -> ".join(cycle)


def test_the_checks_catch_a_planted_cycle_and_an_upward_import(tmp_path):
    """The checks above can fail: a made-up cycle is found, an upward import is read."""
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}})[-1] == "a"
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) == []
    a = tmp_path / "a.py"
    a.write_text("def f():\n    from pmdcid.cli import main\n")
    assert "pmdcid.cli" in _imports(a, top_only=False)
    assert "pmdcid.cli" not in _imports(a, top_only=True)


def test_tests_mirror_the_package_tree():
    """Each folder of tests/ holds the tests of the package of that name (tests/io/ tests
    pmdcid/io/), but tests/system/: whole-pipeline tests, slow by folder (tests/conftest.py)."""
    tests = REPO / "tests"
    folders = {p.name for p in tests.iterdir() if p.is_dir() and any(p.glob("test_*.py"))}
    packages = {p.parent.name for p in PKG.glob("*/__init__.py")}
    assert folders - {"system"} <= packages, sorted(folders - {"system"} - packages)
    assert "system" in folders

