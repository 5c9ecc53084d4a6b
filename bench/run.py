"""`make bench`: the figures that show pmdcid is fast, against baselines measured in the same run.

Each figure is the median of several runs with min and max. Baselines, measured here too:
B1 = scipy solve_ivp (LSODA, rtol 1e-6, tanh-smoothed friction and dead zone) simulating the same
120 s log (bench/baseline.py); B2 = a bare ``python -c pass``; B3 = the peak memory of a python
that imports numpy, pandas, scipy, numba and matplotlib; B4 = ``python -c "import numpy"``, the
floor of any command that reads a log (bench/rows_process.py). PMDCID_BENCH_LARGE=1 adds the
2-million-row fit.

    python bench/run.py [--quick] [--write docs/performance.md] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.rows_kernel import (  # noqa: E402
    hard_sign_row,
    kernel_rows,
    kernel_scaling_rows,
    paper_setup,
)
from bench.rows_pipeline import demo_rows, diagnose_rows, fit_rows, startup_rows  # noqa: E402
from bench.rows_process import process_rows, scaling_rows  # noqa: E402
from bench.rows_speed import diagnose_scaling_rows, identify_rows  # noqa: E402
from bench.table import Row, machine, markdown, write_docs  # noqa: E402

LEGEND = ("B1 = scipy `solve_ivp` LSODA (rtol 1e-6, atol 1e-9, tanh-smoothed Coulomb friction "
          "and dead zone) on the same model and 120 s log, measured in the same run; "
          "\"x B1\" = time / B1. B2 = `python -c pass`. B3 = peak RSS of a python importing "
          "numpy, pandas, scipy, numba, matplotlib. B4 = `python -c \"import numpy\"`, in turns "
          "with the whole-process rows. Targets from issues #8 and #16.")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="fewer runs, baseline on a 10 s window scaled per step, no 16x fit")
    ap.add_argument("--write", type=Path, help="put the table into this markdown file")
    ap.add_argument("--json", type=Path, help="also write the raw figures as JSON")
    args = ap.parse_args(argv)

    t0 = time.perf_counter()
    rows: list[Row] = []

    def step(name, fn):
        t = time.perf_counter()
        print(f"... {name}", file=sys.stderr, flush=True)
        got = fn()
        print(f"    {time.perf_counter() - t:.1f} s", file=sys.stderr, flush=True)
        return got

    setup = paper_setup()
    with tempfile.TemporaryDirectory(prefix="pmdcid-bench-") as tmpdir:
        tmp = Path(tmpdir)
        krows, _, b1 = step("kernel and solve_ivp baseline", lambda: kernel_rows(setup,
                                                                                 args.quick))
        rows += krows
        if not args.quick:
            rows.append(step("solve_ivp with hard sign()", lambda: hard_sign_row(b1)))
        rows += step("fit-nonlinear", lambda: fit_rows(b1, args.quick, tmp))
        rows += step("diagnose", lambda: diagnose_rows(b1, args.quick))
        rows += step("demo", lambda: demo_rows(b1, args.quick, tmp))
        rows += step("identify", lambda: identify_rows(args.quick, tmp))
        rows += step("start-up", lambda: startup_rows(args.quick))
        rows += step("whole processes", lambda: process_rows(args.quick, tmp))
        rows += step("command scaling", lambda: scaling_rows(args.quick, tmp))
        rows += step("kernel scaling", lambda: kernel_scaling_rows(setup, args.quick))
        rows += step("diagnose scaling", lambda: diagnose_scaling_rows(args.quick, tmp))
    total = time.perf_counter() - t0

    text = "\n\n".join([markdown(rows), LEGEND, machine() + f" `make bench` took {total:.0f} s"
                        + (" (--quick)." if args.quick else ".")])
    print(text)
    if args.write:
        write_docs(args.write, text)
        print(f"wrote {args.write}", file=sys.stderr)
    if args.json:
        data = [{"what": r.what, "unit": r.unit, "values": r.stats.values if r.stats else None,
                 "ratio": r.ratio, "target": r.target, "ok": r.ok, "note": r.note}
                for r in rows]
        args.json.write_text(json.dumps(data, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
