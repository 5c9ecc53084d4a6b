"""How long the report takes, and what each of its speed-ups buys (issue #16).

    .venv/bin/python bench/report_figures.py                  # identify's set: the 11 hidden logs
    .venv/bin/python bench/report_figures.py --set demo       # the demo's: triangle + 5 steps
    .venv/bin/python bench/report_figures.py --set triangle   # `pmdcid report` on one 120 s log
    .venv/bin/python bench/report_figures.py --without pool,png,ticks,envelope
    .venv/bin/python bench/report_figures.py --serial         # no worker (PMDCID_THREADS=1)
    .venv/bin/python bench/report_figures.py --set triangle --min-jobs 4   # a worker anyway

``make_report`` in a warm process (imports and the kernel loaded by a first report), the
model = fixtures/hidden/truth.json (it carries an effect, so the before/after figure is drawn).
Prints the median and min of wall and CPU (process) time over ``--runs``. ``--without`` turns
speed-ups off for an ablation, in this process only: ``pool`` (a new figure per log),
``png`` (matplotlib's ``savefig``, RGBA, zlib 6), ``ticks`` (locators rerun at every query),
``envelope`` (every k-th sample, at most 4000 points per line: the drawing before the
envelope). By default the figures are also drawn by a worker process on the spare CPU
(report/parallel.py; started anew by every report, as in a command); ``--serial`` draws in this
process only, ``--min-jobs`` changes the number of figures from which a worker is started.
CPU is this process's only: a worker's is not in it. Not a test: nothing here asserts a time.
"""

from __future__ import annotations

import argparse
import io
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
HIDDEN = ROOT / "fixtures" / "hidden"
SETS = {"identify": ["blocked_*.csv", "step_*.csv", "triangle.csv"],
        "demo": ["triangle.csv", "step_*.csv"], "triangle": ["triangle.csv"]}


def _without(parts: set[str]) -> None:
    import numpy as np

    from pmdcid.report import figures

    if "pool" in parts:
        figures.FigurePool.get = lambda self, key: figures._build(*key)
    if "ticks" in parts:
        figures._freeze_ticks = lambda fig: None
    if "png" in parts:
        def savefig_png(fig):
            figures._freeze_ticks(fig)
            buf = io.BytesIO()
            fig.savefig(buf, format="png", dpi=figures.DPI)
            return buf.getvalue()
        figures._png = savefig_png
    if "envelope" in parts:
        figures.envelope_indices = lambda t, y, columns: np.arange(0, len(y),
                                                                   max(1, len(y) // 4000))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--set", choices=sorted(SETS), default="identify")
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--without", default="", help="comma list of pool, png, ticks, envelope")
    ap.add_argument("--serial", action="store_true", help="no worker process (PMDCID_THREADS=1)")
    ap.add_argument("--min-jobs", type=int, default=None,
                    help="figures from which a worker is started (report/parallel.MIN_JOBS)")
    args = ap.parse_args(argv)
    if args.serial:
        os.environ["PMDCID_THREADS"] = "1"
    if args.min_jobs is not None:
        from pmdcid.report import parallel

        parallel.MIN_JOBS = args.min_jobs
    from pmdcid.io import read_log
    from pmdcid.model import load_model
    from pmdcid.report import make_report

    parts = {p for p in args.without.split(",") if p}
    unknown = parts - {"pool", "png", "ticks", "envelope"}
    if unknown:
        ap.error(f"unknown --without part(s): {', '.join(sorted(unknown))}")
    _without(parts)
    files = [f for pat in SETS[args.set] for f in sorted(HIDDEN.glob(pat))]
    logs = [read_log(f) for f in files]
    model = load_model(HIDDEN / "truth.json")
    walls, cpus = [], []
    with tempfile.TemporaryDirectory() as tmp:
        make_report(logs[:1], model, Path(tmp) / "warm")
        for k in range(args.runs):
            w0, c0 = time.perf_counter(), time.process_time()
            res = make_report(logs, model, Path(tmp) / f"r{k}")
            walls.append(time.perf_counter() - w0)
            cpus.append(time.process_time() - c0)
        size = sum((Path(res.out_dir) / f).stat().st_size for f in res.figures)
    print(f"make_report, {args.set} set ({len(logs)} logs, {len(res.figures)} figures, "
          f"{size / 1e6:.2f} MB of PNG), {'serial' if args.serial else 'worker'}, "
          f"without: {','.join(sorted(parts)) or '-'}: "
          f"wall median {statistics.median(walls):.2f} s (min {min(walls):.2f}), "
          f"CPU median {statistics.median(cpus):.2f} s (min {min(cpus):.2f}), {args.runs} runs")
    return 0


if __name__ == "__main__":
    sys.exit(main())
