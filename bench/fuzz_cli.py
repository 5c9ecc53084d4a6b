"""Red team: every command on odd real-world logs, through the real CLI in a subprocess.

    python bench/fuzz_cli.py [--case NAME[,NAME]] [--cmd NAME[,NAME]] [--base paper,rig] [--models]
                              [--jobs 2] [--keep DIR] [--json FILE] [--lib TREE]

The base logs are the demo's (``fixtures/hidden``: a blocked-rotor step, a free-speed step, the
first 40 s of the triangle at 100 Hz) and bench/newrigs.py's ``bench-step`` rig (ms, volts, rpm
at 100 Hz, turning at the first row, a few NaN cells; ``rigpi``: its PI speed loop, a controller
in the loop). Each mutation (:data:`MUTATIONS`) edits
the log a command reads (one at a time), or adds files and options beside it (a ``--map`` file
naming absent columns, a ``rep/`` folder the user wrote, ``--controller`` specs with bad fields);
each command runs in its own folder with a timeout. Files a mutation writes are inputs too.
A base model is identified once from the unmutated logs. Flagged, per run:

- ``traceback`` / ``internal``: a Python traceback or the edge's "internal error" line;
- ``exit N``: an exit status outside the contract (0, 1, 2);
- ``lines``: exit 1 with anything but one ``error:`` line on stderr (a warning before it too);
- ``hang``: no answer in :data:`TIMEOUT_S`;
- ``modified``: an input file changed;
- ``nan-model``: a written model holds NaN or inf;
- ``refused-model``: ``simulate`` refuses a model the command wrote.

Not a test: nothing here asserts; it prints one row per (mutation, command) and a summary.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import shutil
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

HIDDEN = ROOT / "fixtures" / "hidden"
TIMEOUT_S = 120
RPM = 60 / (2 * math.pi)
KM = "0.0502"
CODE = "import sys; from pmdcid.cli import main; sys.argv=['pmdcid']+sys.argv[1:]; main()"


# -- the base logs -------------------------------------------------------------------------------
def read_fixture(name: str, every: int = 1, seconds: float | None = None) -> pd.DataFrame:
    df = pd.read_csv(HIDDEN / name, comment="#")
    if seconds is not None:
        df = df[df["t"] < seconds]
    return df.iloc[::every].reset_index(drop=True)


def rig_step(which: str = "step") -> pd.DataFrame:
    """newrigs' bench-step log: ms, volts, rpm (NaN cells); the fit step turns at its first row,
    ``pi`` is a held-out PI speed loop."""
    from bench.newrigs import bench_step

    rig = bench_step(1)
    name, cols = rig.steps[0] if which == "step" else rig.held["pi"][0]
    return pd.DataFrame(cols)


RIG_MAPS = ["-c", "t=ms*ms", "-c", "v=volts", "-c", "omega=rpm*rpm"]


def to_csv(df: pd.DataFrame, comments: str = "") -> str:
    return comments + df.to_csv(index=False, float_format="%.9g", lineterminator="\n")


# -- mutations: (DataFrame, comments) -> (bytes of the file, extra CLI args) ----------------------
def m_none(df, c):
    return to_csv(df, c).encode(), []


def rows(k):
    return lambda df, c: (to_csv(df.iloc[:k], c).encode(), [])


def m_dup_t(df, c):
    d = df.copy()
    d.loc[len(d) // 2, "t"] = d.loc[len(d) // 2 - 1, "t"]
    return to_csv(d, c).encode(), []


def m_dup_rows(df, c):
    d = pd.concat([df, df.iloc[len(df) // 3:len(df) // 3 + 20]]).sort_values("t", kind="stable")
    return to_csv(d, c).encode(), []


def m_decreasing(df, c):
    return to_csv(df.iloc[::-1], c).encode(), []


def m_swap2(df, c):
    d = df.copy()
    k = len(d) // 2
    d.iloc[[k, k + 1]] = d.iloc[[k + 1, k]].to_numpy()
    return to_csv(d, c).encode(), []


def col(name, f):
    def m(df, c):
        d = df.copy()
        for n in name.split("+"):
            if n in d:
                d[n] = f(d[n].to_numpy(float), d)
        return to_csv(d, c).encode(), []
    return m


def m_t_unit(scale, header, unit_arg=None):
    def m(df, c):
        d = df.copy()
        d["t"] = d["t"] * scale
        d = d.rename(columns={"t": header})
        return to_csv(d, c).encode(), (["-c", unit_arg] if unit_arg else [])
    return m


def m_integers(df, c):
    d = df.copy()
    d["t"] = np.round(d["t"] * 1000).astype(int)
    for n in ("v", "i", "omega", "theta"):
        if n in d:  # Int64: a NaN cell (the rig's) stays an empty cell
            d[n] = np.round(d[n] * (1000 if n == "i" else 1)).astype("Int64")
    d = d.rename(columns={"t": "t [ms]", "i": "i [mA]"}) if "i" in d else d.rename(
        columns={"t": "t [ms]"})
    return to_csv(d, c).encode(), []


def rename(new: dict, scale: dict | None = None, args=()):
    def m(df, c):
        d = df.copy()
        for k, s in (scale or {}).items():
            if k in d:
                d[k] = d[k] * s
        d = d.rename(columns={k: v for k, v in new.items() if k in d})
        return to_csv(d, c).encode(), list(args)
    return m


def m_extra_cols(df, c):
    d = df.copy()
    d["temp"] = 25.0
    d["note"] = "ok"
    d["pwm"] = (d["v"] * 255 / 12).round() if "v" in d else 0
    return to_csv(d, c).encode(), []


def m_crlf(df, c):
    return to_csv(df, c).replace("\n", "\r\n").encode(), []


def m_bom(df, c):
    return b"\xef\xbb\xbf" + to_csv(df, c).encode(), []


def m_excel(df, c):
    txt = df.to_csv(index=False, sep=";", decimal=",", float_format="%.9g", lineterminator="\n")
    return (c + txt).encode(), []


def m_excel_crlf_bom(df, c):
    txt = df.to_csv(index=False, sep=";", decimal=",", float_format="%.9g", lineterminator="\r\n")
    return b"\xef\xbb\xbf" + (c.replace("\n", "\r\n") + txt).encode(), []


def m_header_only(df, c):
    return (c + ",".join(df.columns) + "\n").encode(), []


def m_gap(df, c):
    t = df["t"].to_numpy()
    mid = t[len(t) // 2]
    return to_csv(df[(t < mid) | (t > mid + 2.0)], c).encode(), []


def m_starts_turning(df, c):
    d = df.iloc[len(df) // 2:].copy()
    d["t"] = d["t"] - d["t"].iloc[0]
    if "theta" in d:
        d["theta"] = d["theta"] - d["theta"].iloc[0]
    return to_csv(d, c).encode(), []


def cells(name, value, k=3):
    def m(df, c):
        d = df.copy()
        if name in d:
            d[name] = d[name].astype(object)
            for j in range(k):
                d.loc[len(d) // 3 + 17 * j, name] = value
        return to_csv(d, c).encode(), []
    return m


def keep(*cols, rows=None):
    """Only these columns (the others dropped), the first ``rows`` rows."""
    def m(df, c):
        d = df[[k for k in df.columns if k in cols]]
        return to_csv(d if rows is None else d.iloc[:rows], c).encode(), []
    return m


def m_negate(df, c):
    d = df.copy()
    for n in ("v", "i", "omega", "theta"):
        if n in d:
            d[n] = -d[n]
    return to_csv(d, c).encode(), []


def m_neg_offset(df, c):
    d = df.copy()
    d["v"] = d["v"] - d["v"].abs().max() - 0.5
    return to_csv(d, c).encode(), []


def m_no_comments(df, c):
    return to_csv(df).encode(), []


def m_ms_loop(df, c):
    """Loop-timed rows: every 2nd-4th row kept, times jittered to whole ms."""
    rng = np.random.default_rng(3)
    keep = np.cumsum(rng.integers(2, 5, size=len(df)))
    keep = keep[keep < len(df)]
    return to_csv(df.iloc[keep], c).encode(), []


def m_quoted(df, c):
    txt = to_csv(df, c)
    head, _, body = txt.rpartition(",".join(df.columns) + "\n")
    hdr = ",".join(f'"{n}"' for n in df.columns) + "\n"
    return (head + hdr + body).encode(), []


def m_nan_burst(df, c):
    """50 rows mid-log with every column but t NaN (a logger hiccup)."""
    d = df.copy()
    k = len(d) // 2
    for n in d.columns:
        if n != "t":
            d[n] = d[n].astype(float)
            d.loc[k:k + 49, n] = np.nan
    return to_csv(d, c).encode(), []


def m_t_wrap(df, c):
    """t as a uint16 millisecond counter that wraps (65535 -> 0) mid-log."""
    d = df.copy()
    ms = np.round(d["t"].to_numpy(float) * 1000).astype(np.int64)
    ms = (ms + 65536 - ms[len(ms) // 2]) % 65536
    d["t"] = ms
    d = d.rename(columns={"t": "t [ms]"})
    return to_csv(d, c).encode(), []


def m_trailing_zeros(df, c):
    """The last 50 rows all zeros, t too (the logger stopped and padded its buffer)."""
    d = df.copy()
    d.iloc[-50:] = 0
    return to_csv(d, c).encode(), []


def m_string_cells(df, c):
    """'N/A' and '--' cells in the speed column."""
    d = df.copy()
    if "omega" in d:
        d["omega"] = d["omega"].astype(object)
        for j, s in enumerate(("N/A", "--", "N/A")):
            d.loc[len(d) // 3 + 17 * j, "omega"] = s
    return to_csv(d, c).encode(), []


def with_files(files: dict, args=()):
    """The log unchanged, files written beside it (inputs too: never modified), ``args`` added."""
    def m(df, c):
        return to_csv(df, c).encode(), list(args), {k: v.encode() for k, v in files.items()}
    return m


def controller(spec: str):
    return lambda df, c: (to_csv(df, c).encode(), ["--controller", spec])


MUTATIONS = {
    "none": m_none,
    "rows3": rows(3),
    "rows1": rows(1),
    "rows12": rows(12),
    "dup-t": m_dup_t,
    "dup-rows": m_dup_rows,
    "decreasing-t": m_decreasing,
    "swapped-rows": m_swap2,
    "const-input": col("v", lambda x, d: np.full_like(x, 1.5)),
    "zero-input": col("v", lambda x, d: np.zeros_like(x)),
    "zero-speed": col("omega+theta", lambda x, d: np.zeros_like(x)),
    "speed-all-nan": col("omega", lambda x, d: np.full_like(x, np.nan)),
    "theta-all-nan": col("theta", lambda x, d: np.full_like(x, np.nan)),
    "i-all-nan": col("i", lambda x, d: np.full_like(x, np.nan)),
    "v-all-nan": col("v", lambda x, d: np.full_like(x, np.nan)),
    "huge-speed": col("omega+theta", lambda x, d: x * 1e12),
    "tiny-speed": col("omega+theta", lambda x, d: x * 1e-12),
    "huge-all": col("v+i+omega+theta", lambda x, d: x * 1e12),
    "tiny-all": col("v+i+omega+theta", lambda x, d: x * 1e-12),
    "tiny-input": col("v", lambda x, d: x * 1e-12),
    "huge-input": col("v", lambda x, d: x * 1e12),
    "t-ms-plain": m_t_unit(1e3, "t"),
    "t-us-plain": m_t_unit(1e6, "t"),
    "t-ms-header": m_t_unit(1e3, "t [ms]"),
    "t-us-header": m_t_unit(1e6, "Time (us)"),
    "t-ms-mapped": m_t_unit(1e3, "time_ms", "t=time_ms*ms"),
    "t-offset-unix": col("t", lambda x, d: x + 1.7e9),
    "integers": m_integers,
    "rpm-header": rename({"omega": "omega [rpm]"}, {"omega": RPM}),
    "speed-rpm-paren": rename({"omega": "Speed(RPM)"}, {"omega": RPM}),
    "speed-rpm-mapped": rename({"omega": "Speed(RPM)"}, {"omega": RPM},
                               ["-c", 'omega="Speed(RPM)"*rpm']),
    "unicode-names": rename({"omega": "ω [rad/s]", "v": "U [V]"}),
    "unicode-mapped": rename({"omega": "ω [rad/s]", "v": "Uₐ"},
                             args=["-c", 'omega="ω [rad/s]"', "-c", "v=Uₐ"]),
    "spaces-names": rename({"omega": "motor speed", "v": "arm voltage"},
                           args=["-c", 'omega="motor speed"', "-c", 'v="arm voltage"']),
    "extra-columns": m_extra_cols,
    "quoted-header": m_quoted,
    "crlf": m_crlf,
    "bom": m_bom,
    "excel": m_excel,
    "excel-crlf-bom": m_excel_crlf_bom,
    "header-only": m_header_only,
    "gap-2s": m_gap,
    "loop-timed": m_ms_loop,
    "starts-turning": m_starts_turning,
    "inf-speed": cells("omega", "inf"),
    "inf-input": cells("v", "inf"),
    "neg-inf-current": cells("i", "-inf"),
    "nan-input-cells": cells("v", "nan"),
    "empty-cells": cells("omega", ""),
    "no-current": keep("t", "v", "omega", "theta"),
    "speed-only": keep("t", "v", "omega"),
    "angle-only": keep("t", "v", "theta"),
    "angle-only-30-rows": keep("t", "v", "theta", rows=30),
    "current-only": keep("t", "v", "i"),
    "negated": m_negate,
    "negative-only": m_neg_offset,
    "no-comments": m_no_comments,
    "nan-burst-50": m_nan_burst,
    "t-wrap-uint16-ms": m_t_wrap,
    "trailing-zeros": m_trailing_zeros,
    "string-cells": m_string_cells,
    "map-missing-column": with_files({"rig.map": "omega=speed_rpm*rpm\n"}, ["--map", "rig.map"]),
    "map-partly-missing": with_files({"rig.map": "v=v*(2*dir-1)\n"}, ["--map", "rig.map"]),
    "c-missing-column": lambda df, c: (to_csv(df, c).encode(), ["-c", "omega=nosuch*rpm"]),
    "report-dir-exists": with_files({"rep/mine.txt": "my notes\n", "rep/report.html": "<p>mine"}),
    "controller-bad-number": controller("type=PI,kp=abc,ki=2"),
    "controller-bad-type": controller("type=PIX,kp=1"),
    "controller-unknown-key": controller("type=PI,kp=0.05,gain=3"),
    "controller-no-reference": controller("type=PI,kp=0.05,ki=2,reference=nosuch"),
    "controller-neg-period": controller("type=PI,kp=0.05,ki=2,period=-1"),
    "controller-bad-file": lambda df, c: (to_csv(df, c).encode(), ["--controller", "pi.json"],
                                          {"pi.json": b'{"type": "PI", "kp": "x"'}),
}


# -- model mutations ----------------------------------------------------------------------------
def model_at_bound(obj):
    from pmdcid.model.effects import bounds_of

    for name in ("bc", "dz", "bv"):
        if name in obj["parameters"]:
            lo, _ = bounds_of(name)
            obj["parameters"][name]["value"] = float(lo)
    return obj


def model_unknown_key(obj):
    obj["parameters"]["R"]["colour"] = "blue"
    obj["whatever"] = {"x": 1}
    return obj


def model_unknown_param(obj):
    obj["parameters"]["Rx"] = {"value": 1.0, "stderr": 0.1, "unit": "ohm", "stage": "user"}
    return obj


def model_no_stderr(obj):
    for p in obj["parameters"].values():
        if isinstance(p, dict):
            p.pop("stderr", None)
    return obj


def model_minimal(obj):
    return {"parameters": {k: v["value"] if isinstance(v, dict) else v
                           for k, v in obj["parameters"].items()}}


def model_bare_numbers(obj):
    return {"parameters": {k: {"value": v["value"]} for k, v in obj["parameters"].items()
                           if isinstance(v, dict)}}


def model_stderr_nan(obj):
    for p in obj["parameters"].values():
        if isinstance(p, dict):
            p["stderr"] = float("nan")
    return obj


def model_stderr_neg(obj):
    for p in obj["parameters"].values():
        if isinstance(p, dict):
            p["stderr"] = -1.0
    return obj


def model_huge_J(obj):
    obj["parameters"]["J"]["value"] = 1e12
    return obj


def model_tiny_J(obj):
    obj["parameters"]["J"]["value"] = 1e-15
    return obj


def model_effects_no_params(obj):
    obj["effects"] = ["stribeck", "cogging", "sensor_delay"]
    return obj


def model_not_json(obj):
    return "R = 2.37\nL = 0.0178\n"


def model_truncated(obj):
    return json.dumps(obj)[:200]


MODEL_MUTATIONS = {
    "model-effects-no-params": model_effects_no_params,
    "model-not-json": model_not_json,
    "model-truncated": model_truncated,
    "model-at-bound": model_at_bound,
    "model-unknown-key": model_unknown_key,
    "model-unknown-param": model_unknown_param,
    "model-no-stderr": model_no_stderr,
    "model-bare-values": model_minimal,
    "model-value-only": model_bare_numbers,
    "model-stderr-nan": model_stderr_nan,
    "model-stderr-negative": model_stderr_neg,
    "model-huge-J": model_huge_J,
    "model-tiny-J": model_tiny_J,
}


# -- commands ------------------------------------------------------------------------------------
#: command -> (which base log the mutation edits, the other logs, the arguments after the logs;
#: "LOG" is the mutated log, "MODEL" a copy of the base model, "EMPTY" a model path that does not
#: exist yet, "OUT" an output path)
COMMANDS = {
    "channels": ("step", [], ["channels", "LOG"]),
    "simulate": ("step", [], ["simulate", "LOG", "-m", "MODEL", "-o", "out.csv"]),
    "simulate-x0": ("step", [], ["simulate", "LOG", "-m", "MODEL", "-o", "out.csv",
                                 "--x0", "measured"]),
    "fit-electrical": ("blocked", [], ["fit-electrical", "LOG", "-m", "EMPTY"]),
    "fit-mechanical": ("step", [], ["fit-mechanical", "LOG", "-m", "RL", "--km", KM]),
    "fit-nonlinear": ("triangle", [], ["fit-nonlinear", "LOG", "-m", "MODEL"]),
    "identify": ("step", ["blocked", "triangle"],
                 ["identify", "LOG", "OTHERS", "-m", "EMPTY", "--km", KM, "--no-diagnose"]),
    "identify-one": ("step", [], ["identify", "LOG", "-m", "EMPTY", "--no-diagnose"]),
    "diagnose": ("step", [], ["diagnose", "LOG", "-m", "MODEL", "-o", "new.json",
                              "--summary", "summary.json"]),
    "report": ("step", [], ["report", "LOG", "-m", "MODEL", "-o", "rep"]),
    "plan-check": ("step", [], ["plan", "--check", "LOG", "-m", "MODEL", "-o", "plan"]),
}
#: commands that read only a model (model mutations)
MODEL_COMMANDS = {
    "simulate": ["simulate", "step.csv", "-m", "MODEL", "-o", "out.csv"],
    "diagnose": ["diagnose", "step.csv", "-m", "MODEL", "-o", "new.json"],
    "report": ["report", "step.csv", "-m", "MODEL", "-o", "rep"],
    "fit-nonlinear": ["fit-nonlinear", "triangle.csv", "-m", "MODEL"],
    "plan": ["plan", "-m", "MODEL", "-o", "plan", "--budget", "20"],
    "export-c": ["export", "-m", "MODEL", "--to", "c", "-o", "m.c"],
    "export-python-control": ["export", "-m", "MODEL", "--to", "python-control", "-o", "m.py"],
    "export-matlab": ["export", "-m", "MODEL", "--to", "matlab", "-o", "motor.m"],
    "export-mujoco": ["export", "-m", "MODEL", "--to", "mujoco", "-o", "m.xml"],
}


@dataclass
class Base:
    frames: dict  # kind -> DataFrame
    comments: dict  # kind -> comment text
    maps: list


def paper_base() -> Base:
    frames = {"step": read_fixture("step_1.5V.csv"),
              "blocked": read_fixture("blocked_1.0V.csv"),
              "triangle": read_fixture("triangle.csv", every=10, seconds=40.0)}
    comments = {"step": "# kind: free-speed-step\n", "blocked": "# kind: blocked-rotor\n",
                "triangle": "# kind: triangle\n"}
    return Base(frames, comments, [])


def rig_base(which: str = "step") -> Base:
    """newrigs' bench-step rig in SI names: its fit step (``step``: turning at the first row), or
    a held-out PI speed loop (``pi``: a controller in the loop), as the ``step`` log."""
    df = rig_step(which).rename(columns={"ms": "t", "volts": "v", "rpm": "omega"})
    df["t"] = df["t"] / 1000
    df["omega"] = df["omega"] / RPM
    return Base({"step": df}, {"step": ""}, [])


#: the pmdcid tree the commands run from (``--lib``: another checkout, e.g. main's, for "before")
LIB = [ROOT]


def cli(args, cwd: Path, timeout=TIMEOUT_S):
    env = {"PYTHONPATH": str(LIB[0]), "PATH": "/usr/bin:/bin", "HOME": str(cwd),
           "PMDCID_THREADS": "1"}
    try:
        return subprocess.run([sys.executable, "-c", CODE, *map(str, args)], cwd=cwd, env=env,
                              capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return None


def snapshot(d: Path) -> dict:
    return {str(p.relative_to(d)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in d.rglob("*") if p.is_file()}


def bad_numbers(obj) -> bool:
    if isinstance(obj, float):
        return not math.isfinite(obj)
    if isinstance(obj, dict):
        return any(bad_numbers(v) for v in obj.values())
    if isinstance(obj, list):
        return any(bad_numbers(v) for v in obj)
    return False


def judge(res, d: Path, before: dict, inputs: list[str], written: list[str]) -> list[str]:
    if res is None:
        return ["hang"]
    flags = []
    if "Traceback" in res.stderr:
        flags.append("traceback")
    if "internal error" in res.stderr:
        flags.append("internal")
    if res.returncode not in (0, 1, 2):
        flags.append(f"exit {res.returncode}")
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    if res.returncode == 1 and (len(lines) != 1 or not lines[0].startswith("error:")):
        flags.append("lines")  # the one error line, no warning before it
    after = snapshot(d)
    flags += [f"modified {n}" for n in inputs if after.get(n) != before.get(n)]
    if res.returncode == 0:
        flags += check_models(d, [w for w in written if w in after])
    return flags


def check_models(d: Path, written: list[str]) -> list[str]:
    flags = []
    for w in written:
        try:
            obj = json.loads((d / w).read_text(), parse_constant=lambda s: float(s))
        except ValueError:
            flags.append(f"unreadable {w}")
            continue
        if bad_numbers(obj.get("parameters", {})):
            flags.append(f"nan-model {w}")
        if not (d / "probe.csv").exists():
            continue
        res = cli(["simulate", "probe.csv", "-m", w, "-o", "probe_out.csv"], d)
        if res is None or res.returncode != 0:
            flags.append(f"refused-model {w}: " + (res.stderr.strip().splitlines() or ["hang"])[-1]
                         if res else "hang")
    return flags


def fill(args, model: str, log: str, others: list[str], maps: list[str]) -> list[str]:
    out = []
    for a in args:
        if a == "LOG":
            out.append(log)
        elif a == "OTHERS":
            out += others
        elif a in ("MODEL", "EMPTY", "RL"):
            out.append(model)
        else:
            out.append(a)
    return out + (maps if args[0] != "channels" else [])


def guarded(fn):
    """A job whose own mutation fails (a bench bug) is a row flagged ``bench-error``, not the end
    of the run."""
    def run(work, base, base_model, mut, cmd):
        try:
            return fn(work, base, base_model, mut, cmd)
        except Exception as exc:  # noqa: BLE001 - reported as a row
            return {"case": mut, "cmd": cmd, "exit": None, "flags": ["bench-error"],
                    "last": f"{type(exc).__name__}: {exc}"[:220], "args": "", "stderr_lines": 0}
    return run


def run_log_case(work: Path, base: Base, base_model: Path, mut: str, cmd: str) -> dict:
    kind, others, args = COMMANDS[cmd]
    if any(k not in base.frames for k in (kind, *others)):
        return {}
    d = Path(tempfile.mkdtemp(prefix=f"{mut}-{cmd}-", dir=work))
    data, extra, *files = MUTATIONS[mut](base.frames[kind], base.comments[kind])
    log = f"{kind}.csv"
    (d / log).write_bytes(data)
    files = files[0] if files else {}
    for name, content in files.items():
        (d / name).parent.mkdir(parents=True, exist_ok=True)
        (d / name).write_bytes(content)
    other_paths = []
    for o in others:
        (d / f"{o}.csv").write_text(to_csv(base.frames[o], base.comments[o]))
        other_paths.append(f"{o}.csv")
    (d / "probe.csv").write_text(to_csv(base.frames["step"][["t", "v"]].iloc[:500]))
    model = "model.json"
    if "MODEL" in args:
        shutil.copy(base_model, d / model)
    elif "RL" in args:
        obj = json.loads(base_model.read_text())
        obj["parameters"] = {k: obj["parameters"][k] for k in ("R", "L")}
        obj["effects"] = []
        (d / model).write_text(json.dumps(obj))
    before = snapshot(d)
    full = fill(args, model, log, other_paths, base.maps + extra)
    res = cli(full, d)
    written = {"diagnose": ["new.json"], "fit-electrical": []}.get(
        cmd, [model] if {"EMPTY", "RL"} & set(args) or cmd == "fit-nonlinear" else [])
    inputs = [log, *other_paths, *files] + (
        [model] if model in before and model not in written else [])
    flags = judge(res, d, before, inputs, written)
    return row(mut, cmd, res, flags, full)


def run_model_case(work: Path, base: Base, base_model: Path, mut: str, cmd: str) -> dict:
    d = Path(tempfile.mkdtemp(prefix=f"{mut}-{cmd}-", dir=work))
    for k, f in base.frames.items():
        (d / f"{k}.csv").write_text(to_csv(f, base.comments[k]))
    (d / "probe.csv").write_text(to_csv(base.frames["step"][["t", "v"]].iloc[:500]))
    obj = MODEL_MUTATIONS[mut](json.loads(base_model.read_text()))
    (d / "model.json").write_text(obj if isinstance(obj, str) else json.dumps(obj, indent=1))
    before = snapshot(d)
    full = fill(MODEL_COMMANDS[cmd], "model.json", "", [], [])
    res = cli(full, d)
    written = ["new.json"] + (["model.json"] if cmd == "fit-nonlinear" else [])
    inputs = [f"{k}.csv" for k in base.frames] + ([] if cmd == "fit-nonlinear" else ["model.json"])
    flags = judge(res, d, before, inputs, written)
    return row(mut, cmd, res, flags, full)


def row(mut, cmd, res, flags, args) -> dict:
    if res is None:
        last = "(timeout)"
    else:
        lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
        last = lines[-1] if lines else ""
    return {"case": mut, "cmd": cmd, "exit": None if res is None else res.returncode,
            "flags": flags, "last": last[:220], "args": " ".join(args),
            "stderr_lines": 0 if res is None else len([ln for ln in res.stderr.splitlines()
                                                       if ln.strip()])}


def base_model(work: Path, base: Base) -> Path:
    d = work / "_base"
    d.mkdir(parents=True, exist_ok=True)
    logs = []
    for k, f in base.frames.items():
        (d / f"{k}.csv").write_text(to_csv(f, base.comments[k]))
        logs.append(f"{k}.csv")
    res = cli(["identify", *logs, "-m", "model.json", "--km", KM, "--no-diagnose"], d, 1800)
    if res is None or res.returncode != 0:
        raise SystemExit(f"base identify failed: {res.stderr if res else 'timeout'}")
    return d / "model.json"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", default="", help="mutations (comma list; default all)")
    ap.add_argument("--cmd", default="", help="commands (comma list; default all)")
    ap.add_argument("--base", default="paper,rig", help="base logs: paper, rig, rigpi")
    ap.add_argument("--models", action="store_true", help="model mutations too")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--keep", default="")
    ap.add_argument("--json", default="", help="write the rows here")
    ap.add_argument("--lib", default="", help="run the commands from this pmdcid tree")
    a = ap.parse_args(argv)
    if a.lib:
        LIB[0] = Path(a.lib).resolve()
    work = Path(a.keep or tempfile.mkdtemp(prefix="fuzz-"))
    work.mkdir(parents=True, exist_ok=True)
    muts = [m for m in (a.case.split(",") if a.case else MUTATIONS) if m in MUTATIONS]
    cmds = a.cmd.split(",") if a.cmd else list(COMMANDS)
    jobs = []
    bases = {"paper": paper_base, "rig": rig_base, "rigpi": lambda: rig_base("pi")}
    paper = paper_base()
    pmodel = base_model(work, paper)
    for bname in a.base.split(","):
        b = paper if bname == "paper" else bases[bname]()
        jobs += [(run_log_case, b, m, c, bname) for m in muts for c in cmds if c in COMMANDS]
    if a.models:
        mm = [m for m in (a.case.split(",") if a.case else MODEL_MUTATIONS) if m in MODEL_MUTATIONS]
        jobs += [(run_model_case, paper, m, c, "paper") for m in mm for c in MODEL_COMMANDS
                 if not a.cmd or c in cmds]
    rows = []
    with ThreadPoolExecutor(a.jobs) as ex:
        futs = [(bn, ex.submit(guarded(fn), work, b, pmodel, m, c)) for fn, b, m, c, bn in jobs]
        for bn, f in futs:
            r = f.result()
            if not r:
                continue
            r["base"] = bn
            rows.append(r)
            mark = "FLAG " + ";".join(r["flags"]) if r["flags"] else "ok"
            print(f"{bn:5s} {r['case']:18s} {r['cmd']:15s} exit {r['exit']}  {mark}  | {r['last']}",
                  flush=True)
    bad = [r for r in rows if r["flags"]]
    print(f"\n{len(bad)} flagged of {len(rows)} runs (work folder {work})")
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
