"""Rows of issue #16's diagnose targets: `pmdcid identify` on the demo logs as a user runs it
(without and with the report: `make demo`), and diagnose at 16x the log length against 1x."""

from __future__ import annotations

from pathlib import Path

from bench.rows_pipeline import FIX, _fail, pmdcid_cmd, run_child
from bench.table import Row, na
from bench.timing import Stats, measure

IDENTIFY_TARGET_S = 10.0
#: `make demo` (warm): identify with the report
DEMO_TARGET_S = 15.0
#: the candidates of the scaling rows: fixed, so that 1x and 16x refit the same effects
SCALING_EFFECTS = ("stribeck",)


def identify_rows(quick: bool, tmp: Path) -> list[Row]:
    """`pmdcid identify fixtures/hidden/*.csv -m M --km 0.0502`, whole process: without a
    report, and with one (``-o DIR``: what `make demo` runs)."""
    return [_identify_row(quick, tmp, False), _identify_row(quick, tmp, True)]


def _identify_row(quick: bool, tmp: Path, report: bool) -> Row:
    what = ("`make demo`: identify on the demo logs with the report (-o), whole process"
            if report else "identify on the demo logs (no -o), whole process")
    target = DEMO_TARGET_S if report else IDENTIFY_TARGET_S
    logs = sorted(str(p) for p in (FIX / "hidden").glob("*.csv"))
    times = Stats()
    for k in range(2 if quick else 3):
        model = tmp / f"identify{k}.json"
        model.unlink(missing_ok=True)
        out = ["-o", str(tmp / f"identify_report{k}")] if report else []
        sec, _, code, err, cpu = run_child(pmdcid_cmd() + ["identify", *logs, "-m", str(model),
                                                           "--km", "0.0502", *out],
                                           timeout=300.0)
        if code != 0:
            line = (err.strip().splitlines() or [""])[-1][:100]
            return na(what, f"failed: exit {code}: {line}", f"<= {target:g} s")
        times.values.append(sec)
        times.cpu.append(cpu)
    return Row(what, times, "s", "", f"<= {target:g} s", times.median <= target,
               "every stage, the joint fit and diagnose" + (", the report's 24 figures"
                                                            if report else "")
               + "; numba cache or ahead-of-time kernel warm; CPU = user + system of all its "
               "threads")


def _hidden_triangle(tmp: Path, factor: int) -> Path:
    """The hidden set's model (Stribeck friction included) on a noisy triangle ``factor``
    times the fixture's 120 s, the fixture's noise and rate."""
    import json

    import numpy as np

    from pmdcid.io import write_log
    from pmdcid.simulate import neutral_values
    from pmdcid.synth import PAPER_NOISE, synth_log, triangle

    path = tmp / f"hidden_triangle_{factor}x.csv"
    if not path.exists():
        truth = json.loads((FIX / "hidden" / "truth.json").read_text())["parameters"]
        t = np.arange(120000 * factor) / 1000.0
        cols, _ = synth_log(t, triangle(t, 2.0, 40.0), {**neutral_values(), **truth},
                            PAPER_NOISE, np.random.default_rng(9100 + factor))
        write_log(path, t, cols, {"generator": "pmdcid", "kind": "triangle"})
    return path


def diagnose_scaling_rows(quick: bool, tmp: Path) -> list[Row]:
    """diagnose (candidates :data:`SCALING_EFFECTS`) on the hidden model's triangle at 1x and
    16x, from the model without its Stribeck friction."""
    import json

    from pmdcid.io import read_log
    from pmdcid.synth import truth_model

    what = "scaling: diagnose at 16x (1920 s triangle)"
    if quick:
        return [na(what, "skipped (--quick)", "<= 18x")]
    try:
        from pmdcid.diagnose import diagnose
        from pmdcid.runtime.malloc import tune_malloc

        # as `pmdcid diagnose` runs it: the command line's heap setting (arrays of tens of MB
        # from the heap, not mapped afresh each simulation); this row runs last in the bench
        tune_malloc()

        truth = json.loads((FIX / "hidden" / "truth.json").read_text())["parameters"]
        model = truth_model({k: v for k, v in truth.items() if k not in ("fs", "ws")})
        one = [read_log(_hidden_triangle(tmp, 1))]
        s1 = measure(lambda: diagnose(one, model.copy(), effects=SCALING_EFFECTS), repeat=3,
                     budget_s=30.0, warmup=0)
        big = [read_log(_hidden_triangle(tmp, 16))]
        got: list = []
        s16 = measure(lambda: got.append(diagnose(big, model.copy(), effects=SCALING_EFFECTS)),
                      repeat=1, warmup=0)
    except Exception as exc:  # noqa: BLE001 - a colleague's module may be in progress
        return [_fail(what, exc, "<= 18x")]
    ratio = s16.median / s1.median
    added = got[-1].summary.get("added") if got else None
    return [Row("scaling: diagnose at 1x (120 s triangle)", s1, "s", "1x",
                note=f"candidates {list(SCALING_EFFECTS)}"),
            Row(what, s16, "s", f"{ratio:.1f}x the 1x time (linear: 16x)", "<= 18x",
                ratio <= 18.0, f"added {added}")]
