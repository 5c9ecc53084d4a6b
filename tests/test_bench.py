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
