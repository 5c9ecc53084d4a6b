"""Signals on offset clocks (docs/io.md, 'Clocks'): blocked-rotor current steps and free-speed
steps written to MCAP with the measurement on its own clock, offset by a fraction of the
command's period; fit-electrical's R, L and fit-mechanical's J, bv against the truth.

    PYTHONPATH=. python bench/clock_offset.py [--seeds 1 2 3] [--offsets 0 0.3 0.5]
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import warnings

import numpy as np

from pmdcid.synth import PAPER, step, synth_log

RATE = float(os.environ.get("CLOCK_RATE", 1000.0))  # the command's rate [Hz]
SUB = 20  # fine-grid steps per command period (offsets are multiples of 1/SUB)
#: the measurement is taken every EVERY command periods (its own, slower clock)
EVERY = int(os.environ.get("CLOCK_EVERY", 1))
NOISE_I, NOISE_W = 4e-3, 4e-3


def truth() -> dict:
    from pmdcid.simulate import neutral_values

    return {**neutral_values(), **PAPER}


def write_mcap(path, t_cmd, v, t_meas, meas: dict) -> None:
    from mcap.writer import Writer

    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start()
        sid = w.register_schema(name="x", encoding="jsonschema", data=b"{}")
        cmd = w.register_channel(topic="/cmd", message_encoding="json", schema_id=sid)
        sen = w.register_channel(topic="/sensor", message_encoding="json", schema_id=sid)
        msgs = [(int(round(tk * 1e9)), cmd, {"volts": float(vk)})
                for tk, vk in zip(t_cmd, v, strict=True)]
        msgs += [(int(round(tk * 1e9)), sen, {n: float(x[k]) for n, x in meas.items()})
                 for k, tk in enumerate(t_meas)]
        for ns, ch, d in sorted(msgs, key=lambda m: m[0]):
            w.add_message(ch, log_time=ns, publish_time=ns, data=json.dumps(d).encode())
        w.finish()


def offset_logs(folder, vals, offset, rng, blocked, amplitudes, dur, t0=0.05):
    """One MCAP per amplitude: the command at k/RATE, the measurement at (k + offset)/RATE,
    both from one simulation on a grid SUB times finer (exact at the measurement's instants)."""
    n = int(round(dur * RATE))
    tf = np.arange(n * SUB) / (RATE * SUB)
    k_off = int(round(offset * SUB * EVERY))
    paths = []
    for a in amplitudes:
        u = step(tf, a, t0)
        cols, _ = synth_log(tf, u, vals, None, None, blocked=blocked)
        # the measurement's instants, each k_off fine steps after a command's (none after the last)
        idx = np.arange(0, n - EVERY, EVERY) * SUB + k_off
        t_cmd = tf[::SUB]
        meas = {}
        if blocked:
            meas["i"] = cols["i"][idx] + rng.normal(0, NOISE_I, len(idx))
        else:
            meas["omega"] = cols["omega"][idx] + rng.normal(0, NOISE_W, len(idx))
        p = os.path.join(folder, f"{'blk' if blocked else 'free'}_{a:g}V_{offset:g}.mcap")
        write_mcap(p, t_cmd, u[::SUB], tf[idx], meas)
        paths.append(p)
    return paths


def run(seed: int, offset: float) -> dict:
    from pmdcid.identify.electrical import fit_electrical
    from pmdcid.identify.mechanical import fit_mechanical
    from pmdcid.io import parse_mapping, read_log
    from pmdcid.model import Model

    vals = truth()
    rng = np.random.default_rng(seed)
    out = {}
    with tempfile.TemporaryDirectory() as d, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        blk = offset_logs(d, vals, offset, rng, True, (2.0, 4.0, 6.0), 0.15)
        logs = [read_log(p, parse_mapping(["v=/cmd.volts", "i=/sensor.i"])) for p in blk]
        res = fit_electrical(logs)
        for k in ("R", "L"):
            out[k] = res.estimates[k].value / vals[k] - 1
        out["d"] = res.estimates["delay"].value if "delay" in res.estimates else float("nan")
        free = offset_logs(d, vals, offset, rng, False, (3.0, 6.0), 1.0)
        logs = [read_log(p, parse_mapping(["v=/cmd.volts", "omega=/sensor.omega"])) for p in free]
        m = Model()
        for k in ("R", "L", "km"):
            m.set(k, vals[k], stage="truth")
        res = fit_mechanical(logs, m)
        for k in ("J", "bv"):
            out[k] = res.estimates[k].value / vals[k] - 1
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--offsets", type=float, nargs="+", default=[0.0, 0.3, 0.5])
    a = ap.parse_args()
    print("offset seed    R%      L%      J%      bv%")
    for off in a.offsets:
        for s in a.seeds:
            r = run(s, off)
            print(f"{off:6.2f} {s:4d} " + " ".join(f"{100 * r[k]:+7.2f}"
                                                   for k in ("R", "L", "J", "bv")))


if __name__ == "__main__":
    main()
