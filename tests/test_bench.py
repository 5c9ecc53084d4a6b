"""The benchmark's baseline simulates the same model as the kernel (correctness, not speed)."""


import numpy as np

from bench.baseline import rms, simulate_baseline
from bench.table import BEGIN, END, write_docs
from bench.timing import Stats
from pmdcid.simulate import simulate_values
from pmdcid.synth import triangle


def test_baseline_agrees_with_kernel_on_a_short_triangle(paper_values):
    # 1 s at 1 kHz, a fast triangle so that the rotor sticks, breaks away and reverses
    t = np.arange(1000) / 1000.0
    u = triangle(t, 2.0, 0.5)
    k = simulate_values(t, u, paper_values)
    assert np.ptp(k.omega) > 0.2 and np.any(k.omega == 0.0)
    b = simulate_baseline(t, u, paper_values)
    assert b.success
    for name in ("i", "omega", "theta"):
        ref = getattr(k, name)
        assert rms(getattr(b, name), ref) < 5e-3 * np.std(ref), name
    # and a model that differs (10 % more Coulomb friction) is told apart by the same measure
    other = simulate_baseline(t, u, {**paper_values, "bc": 1.1 * paper_values["bc"]})
    assert rms(other.omega, k.omega) > 5e-3 * np.std(k.omega)


def test_table_goes_between_the_markers(tmp_path):
    doc = tmp_path / "performance.md"
    doc.write_text(f"# Performance\n\nprose\n\n{BEGIN}\nold\n{END}\n\nmore prose\n")
    write_docs(doc, "new table")
    text = doc.read_text()
    assert "new table" in text and "old" not in text
    assert text.startswith("# Performance\n\nprose") and text.endswith("more prose\n")
    s = Stats([3.0, 1.0, 2.0, 10.0])
    assert (s.median, s.min, s.max, s.n) == (2.5, 1.0, 10.0, 4)


def test_benches_import_test_helpers_that_exist():
    """bench/ borrows truths and pipelines from the tests (ident_util, tests/system's
    test_diagnose ...): every such module it imports exists under tests/ or tests/system/ and
    defines each name it takes, so a move of the test tree cannot leave a bench broken."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    places = [root / "tests", root / "tests" / "system"]
    seen = 0
    for path in sorted((root / "bench").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                mod, names = node.module, [a.name for a in node.names]
            elif isinstance(node, ast.Import):
                mod, names = node.names[0].name, []
            else:
                continue
            if not (mod.startswith("test_") or mod.endswith("_util")):
                continue
            found = [p / f"{mod}.py" for p in places if (p / f"{mod}.py").is_file()]
            assert found, f"{path.name} imports {mod}, which tests/ no longer holds"
            tree = ast.parse(found[0].read_text())
            defined = {t.id for n in tree.body if isinstance(n, ast.Assign) for t in n.targets
                       if isinstance(t, ast.Name)} | {
                n.name for n in tree.body if isinstance(n, ast.FunctionDef | ast.ClassDef)} | {
                a.asname or a.name for n in tree.body
                if isinstance(n, ast.Import | ast.ImportFrom) for a in n.names}
            missing = [n for n in names if n not in defined]
            assert not missing, f"{path.name}: {mod} has no {', '.join(missing)}"
            seen += 1
    assert seen >= 3


def test_benches_import_library_names_that_exist():
    """Every ``from pmdcid... import name`` in bench/ (function-level imports included, where
    most of them are) names something the library defines: a bench is run by hand, seldom, and
    a renamed function must not leave it broken until then."""
    import ast
    import importlib
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    missing, seen = [], 0
    for path in sorted((root / "bench").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if not (isinstance(node, ast.ImportFrom) and node.module
                    and node.module.split(".")[0] == "pmdcid" and node.level == 0):
                continue
            mod = importlib.import_module(node.module)
            for alias in node.names:
                seen += 1
                if not hasattr(mod, alias.name):
                    try:
                        importlib.import_module(f"{node.module}.{alias.name}")
                    except ImportError:
                        missing.append(f"{path.name}: from {node.module} import {alias.name}")
    assert seen > 50  # the walk found the benches' imports
    assert not missing, missing
