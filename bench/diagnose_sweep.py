"""diagnose's decisions over many synthetic rigs: does each hidden effect get named (#16's check
that a faster search decides the same).

    .venv/bin/python bench/diagnose_sweep.py --out new.json
    PYTHONPATH=/path/to/old/checkout .venv/bin/python bench/diagnose_sweep.py --out old.json
    .venv/bin/python bench/diagnose_sweep.py --compare old.json new.json

Each case: the paper's motor with every parameter moved by up to 20 %, one catalogue effect at the
visible size of tests/system/test_diagnose.py (and at half of it), fresh noisy logs of the paper's
three protocols, the paper's stages, then diagnose (one thread); plus clean rigs that must get
nothing. A row: what was added, the held-out speed NRMSE before and after (a 60 s staircase), the
CPU seconds. Not a test: nothing here asserts; ``--compare`` prints where two runs decide
differently. About 4 minutes.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def cases() -> list[tuple[str | None, int, float]]:
    sys.path[:0] = [str(ROOT / "tests"), str(ROOT / "tests" / "system")]
    import test_diagnose as td

    return ([(e, s, f) for e in sorted(td.VISIBLE) for s in (700, 701) for f in (1.0, 0.5)]
            + [(None, s, 0.0) for s in (800, 801, 802, 803)])


def run(out_path: Path) -> None:
    os.environ["PMDCID_THREADS"] = "1"
    import numpy as np

    sys.path[:0] = [str(ROOT / "tests"), str(ROOT / "tests" / "system")]
    import test_diagnose as td
    from ident_util import paper_stages, perturbed_truth

    from pmdcid.diagnose import diagnose

    rows = []
    for eff, seed, f in cases():
        rng = np.random.default_rng(seed)
        extra = ({k: v * f if k not in ("cn", "cphi") else v for k, v in td.VISIBLE[eff].items()}
                 if eff else {})
        truth = perturbed_truth(rng, 0.2, **extra)
        logs, model = paper_stages(truth, rng)
        t = time.process_time()
        res = diagnose(logs, model)
        rows.append({"effect": eff, "seed": seed, "size": f, "added": res.summary["added"],
                     "held_before": td.held_out_nrmse(truth, model, seed),
                     "held_after": td.held_out_nrmse(truth, res.model, seed),
                     "cpu": time.process_time() - t})
        print(json.dumps(rows[-1]), flush=True)
    out_path.write_text(json.dumps(rows, indent=1) + "\n")


def right(row: dict) -> bool:
    return row["added"] == ([row["effect"]] if row["effect"] else [])


def compare(a_path: Path, b_path: Path) -> None:
    a, b = json.loads(a_path.read_text()), json.loads(b_path.read_text())
    for x, y in zip(a, b, strict=True):
        if x["added"] != y["added"]:
            print(f"{x['effect']} seed {x['seed']} size {x['size']}: {x['added']} -> "
                  f"{y['added']} (held-out after {x['held_after']:.3g} -> {y['held_after']:.3g})")
    print(f"named right: {sum(map(right, a))} -> {sum(map(right, b))} of {len(a)}; CPU "
          f"{sum(r['cpu'] for r in a):.0f} -> {sum(r['cpu'] for r in b):.0f} s")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, help="run the sweep, write its rows here")
    ap.add_argument("--compare", nargs=2, type=Path, metavar=("A", "B"))
    args = ap.parse_args(argv)
    if args.compare:
        compare(*args.compare)
    elif args.out:
        run(args.out)
    else:
        ap.error("give --out FILE or --compare A B")
    return 0


if __name__ == "__main__":
    sys.exit(main())
