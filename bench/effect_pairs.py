"""Pairs of catalogue effects at once, through the paper's stages and diagnose (issue #14's
"named alone and in pairs" for the effects added after tests/system/test_diagnose.py's pair test).

    .venv/bin/python -m bench.effect_pairs [CASE ...]

Prints, per case, the effects diagnose added (both must be named) and the held-out speed NRMSE
on a random staircase (tests/system/test_diagnose.py's measure); about 20-60 s per case on 2 cores.
Not a test: each case costs a round trip the suite cannot afford.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path[:0] = [str(Path(__file__).resolve().parents[1] / "tests" / d) for d in ("", "system")]

from ident_util import paper_stages, perturbed_truth  # noqa: E402
from test_diagnose import VISIBLE, held_out_nrmse  # noqa: E402
from test_friction_curve import CURVE  # noqa: E402

from pmdcid.diagnose import diagnose  # noqa: E402

CASES = {
    "input_delay+stribeck": {"latency": 0.004, **VISIBLE["stribeck"]},
    "friction_curve+cogging": {**CURVE, **VISIBLE["cogging"]},
    "friction_curve+torque_offset": {**CURVE, **VISIBLE["torque_offset"]},
}


def run(case: str, seed: int = 77) -> str:
    rng = np.random.default_rng(seed)
    truth = perturbed_truth(rng, 0.2, **CASES[case])
    t0 = time.perf_counter()
    logs, model = paper_stages(truth, rng)
    res = diagnose(logs, model)
    held = held_out_nrmse(truth, res.model, seed)
    return (f"{case}: added {res.summary['added']}, held-out NRMSE {held:.4f}, "
            f"{time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    for name in sys.argv[1:] or list(CASES):
        print(run(name), flush=True)
