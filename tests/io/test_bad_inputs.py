"""Malformed and hostile inputs, one row each: exit status, one clear stderr line, nothing lost.

Each row of :data:`CASES` is ``Case(id, build, args, status, pattern)``:

- ``build(d)`` writes the files the case needs into the folder ``d`` (the test's cwd);
- ``args`` is the command line after ``pmdcid`` (paths relative to ``d``);
- ``status`` the expected exit status: 1 for a problem with the user's data/files/model, 2 for a
  usage error, 0 for suspicious-but-usable data;
- ``pattern`` a regex that the ONE stderr line must match (``re.search``). For exit 1 the line must
  begin ``error: `` and name the file; for exit 0 a ``warning: `` line must match (or, with
  ``pattern=None``, stderr must be empty).

For every row: no traceback, no "internal error", every file that existed before is byte-identical
afterwards (except files listed in ``changes`` when the command succeeds, e.g. the model a stage
updates), and no temporary file is left behind.

To add a case: write a ``build`` (the helpers below make logs and models in one line) and append a
row. A row for a command that is not registered fails (a skip could hide a regression): add rows
only for commands that exist.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from repo_paths import FIXTURES

from pmdcid.cli import main
from pmdcid.synth import PAPER

FIX = FIXTURES
PMDCID = Path(sys.executable).parent / "pmdcid"


# ----------------------------------------------------------------------------------------------
# builders: each returns a function of the case folder ``d``

def fixture(src: str, name: str | None = None):
    """Copy a bundled fixture log, e.g. ``fixture('paper/step_1.5V.csv', 'step.csv')``."""
    def build(d: Path):
        (d / (name or Path(src).name)).write_bytes((FIX / src).read_bytes())
    return build


def text(name: str, content: str | bytes):
    def build(d: Path):
        p = d / name
        p.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(content, bytes):
            p.write_bytes(content)
        else:
            p.write_text(content, newline="")
    return build


def edited(src: str, name: str, fn: Callable[[list[str]], list[str]]):
    """A fixture log with its lines passed through ``fn`` (list of lines, comments included)."""
    def build(d: Path):
        lines = (FIX / src).read_text().splitlines()
        (d / name).write_text("\n".join(fn(lines)) + "\n")
    return build


def table(name: str, columns: dict[str, np.ndarray], header: str | None = None):
    """A CSV log from arrays (``header`` overrides the column names line)."""
    def build(d: Path):
        arr = np.column_stack(list(columns.values()))
        body = "\n".join(",".join(f"{x:.9g}" for x in row) for row in arr)
        (d / name).write_text((header or ",".join(columns)) + "\n" + body + "\n")
    return build


def model(name: str = "model.json", drop: tuple[str, ...] = (), only: tuple[str, ...] | None = None,
          effects: tuple[str, ...] = (), **override):
    """A model file with the paper's values (minus ``drop``, or ``only`` some), then overrides."""
    def build(d: Path):
        vals = {k: v for k, v in PAPER.items() if k not in drop and (only is None or k in only)}
        vals.update(override)
        obj = {"parameters": {k: {"value": v, "stderr": None, "unit": "", "stage": "test"}
                              for k, v in vals.items()},
               "effects": list(effects)}
        (d / name).write_text(json.dumps(obj, indent=2) + "\n")
    return build


def regular_file(name: str):
    return text(name, "I am a regular file, not a folder\n")


def combine(*builders):
    def build(d: Path):
        for b in builders:
            b(d)
    return build


def _replace_data_row(k: int, col: int, value: str):
    """Edit data row ``k`` (0-based, after the header) column ``col`` of a fixture's lines."""
    def fn(lines):
        h = next(i for i, ln in enumerate(lines) if not ln.startswith("#"))
        cells = lines[h + 1 + k].split(",")
        cells[col] = value
        lines[h + 1 + k] = ",".join(cells)
        return lines
    return fn


def _map_column(col: int, f):
    """Apply ``f`` to every value of data column ``col`` of a fixture's lines."""
    def fn(lines):
        h = next(i for i, ln in enumerate(lines) if not ln.startswith("#"))
        out = lines[:h + 1]
        for ln in lines[h + 1:]:
            cells = ln.split(",")
            cells[col] = f"{f(float(cells[col])):.9g}"
            out.append(",".join(cells))
        return out
    return fn


def _clip_column(col: int, level: float):
    """Clip data column ``col`` of a fixture's lines at ``level`` (a saturated sensor)."""
    return _map_column(col, lambda x: min(x, level))


def _scale_columns(lines, cols, factor):
    for c in cols:
        lines = _map_column(c, lambda x: x * factor)(lines)
    return lines


def _head(k: int):
    """Keep the comments, the header and the first ``k`` data rows of a fixture's lines."""
    def fn(lines):
        h = next(i for i, ln in enumerate(lines) if not ln.startswith("#"))
        return lines[:h + 1 + k]
    return fn


def _drop_column(col: int):
    def fn(lines):
        return [ln if ln.startswith("#") else ",".join(c for j, c in enumerate(ln.split(","))
                                                       if j != col) for ln in lines]
    return fn


# ----------------------------------------------------------------------------------------------
# synthetic logs for the defects no fixture shows

T1K = np.arange(3000) * 1e-3
STEP = combine(fixture("paper/step_1.5V.csv", "step.csv"))
BLOCKED = fixture("paper/blocked_1.5V.csv", "blocked.csv")
MODEL = model()
SIM = ["simulate", "step.csv", "-m", "model.json", "-o", "out.csv"]
FE = ["fit-electrical", "blocked.csv", "-m", "model.json"]
FM = ["fit-mechanical", "step.csv", "-m", "model.json"]
FN = ["fit-nonlinear", "tri.csv", "-m", "model.json"]
EXP = ["export", "-m", "model.json", "--to"]


def _step_log(name, omega_scale=1.0, theta_scale=1.0, clip=None, v=1.5, onset=0.5, n=3000,
              seed=1, theta=True):
    """A free-speed step log of the paper motor (analytic first order, small noise)."""
    def build(d: Path):
        rng = np.random.default_rng(seed)
        t = np.arange(n) * 1e-3
        km, R, b, J = PAPER["km"], PAPER["R"], PAPER["bv"], PAPER["J"]
        K = km / (R * b + km * km)
        tau = J * R / (R * b + km * km)
        s = np.clip(t - onset, 0.0, None)
        om = np.where(t >= onset, v * K * (1 - np.exp(-s / tau)), 0.0)
        th = np.where(t >= onset, v * K * (s - tau * (1 - np.exp(-s / tau))), 0.0)
        i = (np.where(t >= onset, v, 0.0) - km * om) / R
        om_meas = om + rng.normal(0, 2e-3, n)
        if clip is not None:
            om_meas = np.minimum(om_meas, clip)
        cols = {"t": t, "v": np.where(t >= onset, v, 0.0), "i": i + rng.normal(0, 2e-3, n),
                "omega": om_meas * omega_scale, "theta": th * theta_scale}
        if not theta:
            cols.pop("theta")
        table(name, cols)(d)
    return build


def _triangle_log(name, clip=None, seconds=40.0, omega_scale=1.0, theta=True, **params):
    """A +-2 V triangle log of the paper motor, simulated by the kernel (noise, optional clip)."""
    def build(d: Path):
        from pmdcid.simulate import neutral_values
        from pmdcid.synth import NoiseSpec, synth_log, triangle

        t = np.arange(int(seconds * 1000)) * 1e-3
        cols, _ = synth_log(t, triangle(t, 2.0, 20.0), {**neutral_values(), **PAPER, **params},
                            NoiseSpec(4e-3, 4e-3, 4096), np.random.default_rng(2))
        if clip is not None:
            cols["omega"] = np.clip(cols["omega"], -np.inf, clip)
        cols["omega"] = cols["omega"] * omega_scale
        if not theta:
            cols.pop("theta")
        table(name, {"t": t, **cols})(d)
    return build


TRI = _triangle_log("tri.csv")


# ---- builders for round two (issue 15) ---------------------------------------------------------

def _scale_column(col: int, k: float):
    """Multiply data column ``col`` of a fixture's lines by ``k`` (a unit left unmapped)."""
    return _map_column(col, lambda x: x * k)


def model_units(name: str = "model.json", encoding: str = "utf-8", bom: bool = False, **given):
    """The paper's model with some values given as ``name=(value, unit)``."""
    def build(d: Path):
        params = {k: {"value": v, "unit": ""} for k, v in PAPER.items()}
        for k, (v, unit) in given.items():
            params[k] = {"value": v, "unit": unit}
        text_ = json.dumps({"parameters": params, "effects": []}, indent=2) + "\n"
        data = text_.encode(encoding)
        (d / name).write_bytes((b"\xef\xbb\xbf" if bom else b"") + data)
    return build


def _fixture_text(src: str) -> str:
    return (FIX / src).read_text()


def encoded(src: str, name: str, encoding: str, prefix: str = ""):
    """A fixture log re-encoded (``utf-16`` writes a BOM), with ``prefix`` text before it."""
    def build(d: Path):
        (d / name).write_bytes((prefix + _fixture_text(src)).encode(encoding))
    return build


def european(src: str, name: str):
    """A fixture log as a European Excel export: ';' separator, ',' decimal mark."""
    def build(d: Path):
        out = []
        for ln in _fixture_text(src).splitlines():
            out.append(ln if ln.startswith("#") else ln.replace(",", ";").replace(".", ","))
        (d / name).write_text("\n".join(out) + "\n")
    return build


def transposed(name: str, ncols: int = 120_000):
    """A log exported the wrong way round: one row per signal, one column per sample."""
    def build(d: Path):
        head = ",".join(f"s{k}" for k in range(ncols))
        rows = [",".join(f"{k * 1e-3:.3f}" for k in range(ncols)),
                ",".join("1.5" for _ in range(ncols))]
        (d / name).write_text(head + "\n" + "\n".join(rows) + "\n")
    return build


def symlinked(link: str, target: str):
    def build(d: Path):
        (d / link).symlink_to(target)
    return build


def pwm_log(name: str, header: str = "t,pwm,dir"):
    """Sign-magnitude PWM: 8-bit duty and a 0/1 direction column."""
    def build(d: Path):
        t = np.arange(2000) * 1e-3
        pwm = np.full(2000, 128.0)
        direction = (np.sin(2 * np.pi * t) > 0).astype(float)
        table(name, {"t": t, "pwm": pwm, "dir": direction}, header)(d)
    return build


#: the one warning of fit-electrical on a single blocked-rotor log
SAME_V = r"^warning: all logs step to the same voltage"
OVERLOAD = edited("paper/step_1.5V.csv", "step.csv", _replace_data_row(700, 1, "9.9E+37"))


# ----------------------------------------------------------------------------------------------

@dataclass
class Case:
    id: str
    build: Callable[[Path], None]
    args: list[str]
    status: int
    pattern: str | None
    changes: tuple[str, ...] = ()  # files allowed to change when the command succeeds
    subprocess: bool = False  # also run as a real process (the no-traceback guarantee)
    marks: tuple = field(default=())


def C(id, build, args, status, pattern, **kw):  # noqa: N802 - a table row
    return Case(id, build, args, status, pattern, **kw)


CASES: list[Case] = [
    # ---- the log reader (through simulate, the command that reads any log) -------------------
    C("log-missing", MODEL, SIM, 1, r"^error: step\.csv: no such log file"),
    C("log-empty", combine(MODEL, text("step.csv", "")), SIM, 1, r"^error: step\.csv: .*empty",
      subprocess=True),
    C("log-blank-lines", combine(MODEL, text("step.csv", "\n\n  \n")), SIM, 1,
      r"^error: step\.csv: .*empty"),
    C("log-comments-only", combine(MODEL, text("step.csv", "# kind: step\n# nothing else\n")),
      SIM, 1, r"^error: step\.csv: .*empty"),
    C("log-header-only", combine(MODEL, text("step.csv", "t,v,i,omega,theta\n")), SIM, 1,
      r"^error: step\.csv: has a header but no data rows"),
    C("log-binary", combine(MODEL, text("step.csv", bytes(range(256)) * 4)), SIM, 1,
      r"^error: step\.csv: is not a text CSV"),
    C("log-no-time-column", combine(MODEL, edited("paper/step_1.5V.csv", "step.csv",
                                                  _drop_column(0))), SIM, 1,
      r"^error: step\.csv: has no time column 't'.*-c t="),
    C("log-no-input-column", combine(MODEL, edited("paper/step_1.5V.csv", "step.csv",
                                                   _drop_column(1))), SIM, 1,
      r"^error: step\.csv: .*'v'.*'tau'"),
    C("log-duplicated-column", combine(MODEL, text("step.csv", "t,v,v\n0,1,1\n1,1,1\n2,1,1\n")),
      SIM, 1, r"^error: step\.csv: header names column\(s\) v more than once"),
    C("log-duplicated-after-strip",
      combine(MODEL, text("step.csv", 't ,"t",v\n0,0,1\n1,1,1\n2,2,1\n')),
      SIM, 1, r"^error: step\.csv: header names column\(s\) t more than once"),
    C("log-newline-in-header-name",
      combine(MODEL, text("step.csv", '"ti\nme",v\n0,1\n1,1\n2,1\n')),
      SIM, 1, r"^error: step\.csv: has no time column 't' \(columns are ti me, v"),
    C("log-semicolon-separated", combine(MODEL, text(
        "step.csv", "t;v;i\n0,000;1,5;0,1\n0,001;1,5;0,1\n0,002;1,5;0,1\n")), SIM, 0, None,
      changes=("out.csv",)),
    C("log-semicolon-ragged", combine(MODEL, text(
        "step.csv", "t;v;i\n0,000;1,5\n0,001;1,5;0,1;7\n0,002;1,5;0,1\n")), SIM, 1,
      r"^error: step\.csv: .*(semicolon|';')"),
    C("log-non-numeric-cell", combine(MODEL, edited("paper/step_1.5V.csv", "step.csv",
                                                    _replace_data_row(100, 1, "1.5V"))), SIM, 1,
      r"^error: step\.csv: column 'v' holds non-numeric value '1\.5V' \(data row 101\)"),
    C("log-nan-in-time", combine(MODEL, edited("paper/step_1.5V.csv", "step.csv",
                                               _replace_data_row(10, 0, "nan"))), SIM, 1,
      r"^error: step\.csv: time column .*non-finite.*row 11"),
    C("log-inf-in-input", combine(MODEL, edited("paper/step_1.5V.csv", "step.csv",
                                                _replace_data_row(7, 1, "inf"))), SIM, 1,
      r"^error: step\.csv: column 'v' holds an infinite value \(data row 8\)"),
    C("log-overflow-to-inf", combine(MODEL, edited("paper/step_1.5V.csv", "step.csv",
                                                   _replace_data_row(7, 2, "1e999"))), SIM, 1,
      r"^error: step\.csv: column 'i' holds an infinite value"),
    C("log-many-nan", combine(MODEL, edited(
        "paper/step_1.5V.csv", "step.csv",
        lambda ls: [ln if (k < 600 or k > 700) else ",".join(ln.split(",")[:1] + ["nan"] * 4)
                    for k, ln in enumerate(ls)])), SIM, 1,
      r"^error: step\.csv: column '\w+' has \d+ missing/NaN values.*clean or cut"),
    C("log-few-nan-filled", combine(MODEL, edited("paper/step_1.5V.csv", "step.csv",
                                                  _replace_data_row(500, 3, "NaN"))), SIM, 0,
      r"^warning: step\.csv: column 'omega': filled 1 NaN"),
    C("log-time-stands-still", combine(MODEL, edited("paper/step_1.5V.csv", "step.csv",
                                                     _replace_data_row(20, 0, "0.019"))), SIM, 1,
      r"^error: step\.csv: time stands still at data row 21"),
    C("log-time-goes-back", combine(MODEL, edited("paper/step_1.5V.csv", "step.csv",
                                                  _replace_data_row(20, 0, "0.001"))), SIM, 1,
      r"^error: step\.csv: time goes back at data row 21"),
    C("log-jittery-sampling", combine(MODEL, table("step.csv", {
        "t": T1K + np.random.default_rng(3).uniform(0, 4e-4, 3000), "v": np.ones(3000)})), SIM, 0,
      r"^warning: step\.csv: loop-timed samples .* put on a uniform 1 ms grid",
      changes=("out.csv",)),
    C("log-dropout-gap", combine(MODEL, table("step.csv", {
        "t": np.delete(T1K, np.s_[1000:1050]), "v": np.ones(2950)})), SIM, 1,
      r"^error: step\.csv: samples missing: 1 gap\(s\), the first of 0\.051 s after data row "
      r"1000 \(t=0\.999 s\)"),
    C("log-small-jitter-ok", combine(MODEL, table("step.csv", {
        "t": T1K + np.random.default_rng(3).uniform(0, 5e-6, 3000), "v": np.ones(3000)})), SIM, 0,
      None),
    C("log-too-short", combine(MODEL, text("step.csv", "t,v\n0,1\n0.001,1\n")), SIM, 1,
      r"^error: step\.csv: has only 2 data row\(s\)"),
    C("log-ragged-long-row", combine(MODEL, edited("paper/step_1.5V.csv", "step.csv",
                                                   _replace_data_row(30, 4, "0,7,8"))), SIM, 1,
      r"^error: step\.csv: is not a readable CSV"),
    C("log-unclosed-quote", combine(MODEL, edited("paper/step_1.5V.csv", "step.csv",
                                                  _replace_data_row(30, 2, '"0.1'))), SIM, 1,
      r"^error: step\.csv: is not a readable CSV"),
    C("log-utf8-bom", combine(MODEL, text("step.csv", "\ufefft,v\n0,0\n0.001,1\n0.002,1\n")),
      SIM, 0, None),
    C("log-latin1-comment", combine(MODEL, text(
        "step.csv", "# température: 21 °C\nt,v\n0,0\n0.001,1\n0.002,1\n".encode("latin-1"))),
      SIM, 0, None),
    C("log-is-folder", combine(MODEL, lambda d: (d / "step.csv").mkdir()), SIM, 1,
      r"^error: step\.csv: is a folder"),
    C("log-saturated-sensor", combine(MODEL, _step_log("step.csv", clip=0.9)), SIM, 0,
      r"^warning: step\.csv: column 'omega' .*(saturat|clip)"),
    C("log-rpm-as-rad-per-s", combine(MODEL, _step_log("step.csv", omega_scale=60 / (2 * np.pi))),
      SIM, 0, r"^warning: step\.csv: .*omega.*rpm"),
    C("log-deg-as-rad", combine(MODEL, _step_log("step.csv", theta_scale=180 / np.pi)),
      SIM, 0, r"^warning: step\.csv: .*theta.*deg"),
    C("log-large-300k-rows", combine(MODEL, table("step.csv", {
        "t": np.arange(300_000) * 1e-4,
        "v": np.sign(np.sin(np.arange(300_000) * 1e-4))})), SIM, 0, None, changes=("out.csv",)),
    C("log-unix-timestamps", combine(MODEL, text("step.csv", "t,v\n" + "".join(
        f"{1.7e9 + k * 1e-3:.15g},{1.0 if k > 100 else 0.0}\n" for k in range(2000)))), SIM, 0,
      None, changes=("out.csv",)),
    C("log-crlf-quoted-padded-header", combine(MODEL, text(
        "step.csv", '" t ", "v" ,i\r\n0,0,0\r\n0.001,1,0.1\r\n0.002,1,0.2\r\n')), SIM, 0, None),
    C("log-trailing-comma", combine(MODEL, text("step.csv", "t,v,\n0,0,\n0.001,1,\n0.002,1,\n")),
      SIM, 0, None),
    C("log-empty-measured-column", combine(MODEL, text("step.csv", "t,v,i\n" + "".join(
        f"{k * 1e-3:.3f},1,\n" for k in range(100)))), SIM, 0,
      r"^warning: step\.csv: column 'i' is empty \(no number in any row\): ignored",
      changes=("out.csv",)),
    C("log-empty-needed-column", combine(MODEL, text("blocked.csv", "t,v,i\n" + "".join(
        f"{k * 1e-3:.3f},1,\n" for k in range(100)))), FE, 1,
      r"^error: blocked\.csv: needs column\(s\) i .*; column 'i' is empty; it has v"),
    # ---- column mappings -------------------------------------------------------------------
    C("map-unknown-source", combine(MODEL, STEP), SIM + ["-c", "omega=speed_rpm*rpm"], 1,
      r"^error: step\.csv: column mapping omega=speed_rpm: no column 'speed_rpm'"),
    C("map-bad-syntax", combine(MODEL, STEP), SIM + ["-c", "omega"], 2,
      r"column mapping 'omega' is not of the form"),
    C("map-unknown-unit", combine(MODEL, STEP), SIM + ["-c", "omega=omega*furlongs"], 2,
      r"'furlongs' is neither a number nor a unit"),
    C("map-not-canonical", combine(MODEL, STEP), SIM + ["-c", "speed=omega"], 2,
      r"'speed' is not a canonical column"),
    C("map-twice", combine(MODEL, STEP), SIM + ["-c", "omega=omega*rpm", "-c", "omega=omega"],
      2, r"omega is mapped twice, by -c omega=omega\*rpm and by -c omega=omega: keep one"),
    C("map-file-twice", combine(MODEL, STEP, text("cols.map", "omega=omega*rpm\nomega=omega\n")),
      SIM + ["--map", "cols.map"], 1, r"^error: cols\.map: omega is mapped twice, by cols\.map "
      r"line 1 \(omega=omega\*rpm\) and by cols\.map line 2 \(omega=omega\)"),
    C("map-file-missing", combine(MODEL, STEP), SIM + ["--map", "cols.map"], 1,
      r"^error: cols\.map: cannot read column-mapping file"),
    C("map-file-bad-json", combine(MODEL, STEP, text("cols.map", '{"omega": ')),
      SIM + ["--map", "cols.map"], 1, r"^error: cols\.map: mapping file is not valid JSON"),
    C("map-file-deeply-nested", combine(MODEL, STEP, text("cols.map", '{"a":' * 50000)),
      SIM + ["--map", "cols.map"], 1, r"^error: cols\.map: mapping file is not usable JSON"),
    C("map-file-binary", combine(MODEL, STEP, text("cols.map", b"\xff\xfe\x00omega=x")),
      SIM + ["--map", "cols.map"], 1, r"^error: cols\.map: column-mapping file is not UTF-8"),
    C("map-file-bad-line", combine(MODEL, STEP, text("cols.map", "omega = speed * bananas\n")),
      SIM + ["--map", "cols.map"], 1, r"^error: cols\.map: column mapping .*bananas"),
    # ---- the model file --------------------------------------------------------------------
    C("model-missing", STEP, SIM, 1, r"^error: model\.json: no such model file"),
    C("model-empty", combine(STEP, text("model.json", "")), SIM, 1,
      r"^error: model\.json: model file is empty", subprocess=True),
    C("model-not-json", combine(STEP, text("model.json", "R = 2.37\nL = 0.0178\n")), SIM, 1,
      r"^error: model\.json: model file is not valid JSON \(line 1"),
    C("model-truncated-json", combine(STEP, text("model.json", '{"parameters": {"R": {"val')),
      SIM, 1, r"^error: model\.json: model file is not valid JSON"),
    C("model-json-list", combine(STEP, text("model.json", "[1, 2, 3]")), SIM, 1,
      r"^error: model\.json: model file must hold a JSON object"),
    C("model-missing-parameter", combine(STEP, model(drop=("J",))), SIM, 1,
      r"^error: model\.json: model lacks J .*run fit-mechanical"),
    C("model-no-parameters", combine(STEP, text("model.json", '{"effects": []}')), SIM, 1,
      r"^error: model\.json: model lacks R, L, km, J"),
    C("model-negative-R", combine(STEP, model(R=-2.37)), SIM, 1,
      r"^error: model\.json: parameter 'R' = -2\.37 ohm is impossible"),
    C("model-zero-J", combine(STEP, model(J=0.0)), SIM, 1,
      r"^error: model\.json: parameter 'J' = 0 .*impossible"),
    C("model-nan-value", combine(STEP, text("model.json",
                                            '{"parameters": {"R": {"value": NaN}}}')), SIM, 1,
      r"^error: model\.json: parameter 'R' is not finite"),
    C("model-huge-integer", combine(STEP, text("model.json", '{"parameters": {"R": {"value": 1'
                                                 + "0" * 400 + "}}}")), SIM, 1,
      r"^error: model\.json: parameter 'R' is not finite"),
    C("model-5000-digit-integer", combine(STEP, text(
        "model.json", '{"parameters": {"R": {"value": 1' + "0" * 5000 + "}}}")), SIM, 1,
      r"^error: model\.json: parameter 'R' is not finite"),
    C("model-deeply-nested", combine(STEP, text("model.json", "[" * 100000 + "]" * 100000)),
      SIM, 1, r"^error: model\.json: model file is not usable JSON"),
    C("model-string-value", combine(STEP, model(L="17.8 mH")), SIM, 1,
      r"^error: model\.json: parameter 'L' has non-numeric value '17\.8 mH'"),
    C("model-bad-entry", combine(STEP, text("model.json", '{"parameters": {"R": [2.37]}}')), SIM,
      1, r"^error: model\.json: parameter 'R' must be an object with a 'value'"),
    C("model-unknown-effect", combine(STEP, model(effects=("flux_capacitor",))), SIM, 1,
      r"^error: model\.json: unknown effect\(s\) flux_capacitor"),
    C("model-effect-without-params", combine(STEP, model(effects=("stribeck",))), SIM, 0,
      r"^warning: model\.json: .*stribeck.*lacks", changes=("out.csv",)),
    C("model-not-utf8", combine(STEP, text("model.json", b'{"parameters": {"R\xff": 1}}')), SIM, 1,
      r"^error: model\.json: "),
    C("model-is-folder", combine(STEP, lambda d: (d / "model.json").mkdir()), SIM, 1,
      r"^error: model\.json: is a folder"),
    # ---- outputs ---------------------------------------------------------------------------
    C("out-under-regular-file", combine(STEP, MODEL, regular_file("notes.txt")),
      ["simulate", "step.csv", "-m", "model.json", "-o", "notes.txt/out.csv"], 1,
      r"^error: notes\.txt: .*not a folder"),
    C("out-in-missing-folder", combine(STEP, MODEL),
      ["simulate", "step.csv", "-m", "model.json", "-o", "nowhere/out.csv"], 1,
      r"^error: nowhere: output folder does not exist"),
    C("out-in-proc", combine(STEP, MODEL),
      ["simulate", "step.csv", "-m", "model.json", "-o", "/proc/pmdcid-out.csv"], 1,
      r"^error: /proc.*cannot write"),
    C("out-is-input", combine(STEP, MODEL),
      ["simulate", "step.csv", "-m", "model.json", "-o", "./step.csv"], 1,
      r"^error: \./step\.csv: output would overwrite the input"),
    C("out-is-input-even-forced", combine(STEP, MODEL),
      ["simulate", "step.csv", "-m", "model.json", "-o", "step.csv", "--force"], 1,
      r"^error: step\.csv: output would overwrite the input"),
    C("out-is-model", combine(STEP, MODEL),
      ["simulate", "step.csv", "-m", "model.json", "-o", "model.json", "--force"], 1,
      r"^error: model\.json: output would overwrite the model file"),
    C("out-is-map-file", combine(STEP, MODEL, text("cols.map", "v=v\n")),
      SIM[:-1] + ["cols.map", "--map", "cols.map", "--force"], 1,
      r"^error: cols\.map: output would overwrite the input cols\.map"),
    C("out-is-symlink-to-input", combine(STEP, MODEL, lambda d: (d / "ln.csv").symlink_to(
        d / "step.csv")), SIM[:-1] + ["ln.csv", "--force"], 1,
      r"^error: ln\.csv: output would overwrite the input"),
    C("out-exists-not-ours", combine(STEP, MODEL, text("out.csv", "t,omega\n0,1\n")), SIM, 1,
      r"^error: out\.csv: exists and was not written by pmdcid; use --force"),
    C("out-is-folder", combine(STEP, MODEL, lambda d: (d / "out.csv").mkdir()), SIM, 2,
      r"out\.csv.*(directory|folder)"),
    # ---- fit-electrical --------------------------------------------------------------------
    C("fe-empty-log", text("blocked.csv", ""), FE, 1, r"^error: blocked\.csv: .*empty"),
    C("fe-no-current", edited("paper/blocked_1.5V.csv", "blocked.csv", _drop_column(2)), FE, 1,
      r"^error: blocked\.csv: .*\bi\b"),
    C("fe-step-never-happens", table("blocked.csv", {
        "t": np.arange(1500) * 2e-4, "v": np.zeros(1500),
        "i": np.random.default_rng(5).normal(0, 4e-3, 1500)}), FE, 1, r"^error: blocked\.csv: "),
    C("fe-too-short", text("blocked.csv", "t,v,i\n0,0,0\n0.0002,1,0.01\n0.0004,1,0.02\n"
                           "0.0006,1,0.03\n"), FE, 1, r"^error: blocked\.csv: "),
    C("fe-model-not-json", combine(BLOCKED, text("model.json", "{R: 2.37}")), FE, 1,
      r"^error: model\.json: model file is not valid JSON", subprocess=True),
    C("fe-model-negative-R", combine(BLOCKED, model(R=-1.0)), FE, 1,
      r"^error: model\.json: parameter 'R' = -1 ohm is impossible"),
    C("fe-model-under-regular-file", combine(BLOCKED, regular_file("notes.txt")),
      ["fit-electrical", "blocked.csv", "-m", "notes.txt/model.json"], 1,
      r"^error: notes\.txt: .*not a folder"),
    C("fe-model-is-input-log", BLOCKED, ["fit-electrical", "blocked.csv", "-m", "blocked.csv"], 1,
      r"^error: blocked\.csv: "),
    C("fe-rotor-turns", combine(MODEL, fixture("paper/step_1.5V.csv", "blocked.csv")), FE, 0,
      r"^warning: blocked\.csv: .*rotor turns", changes=("model.json",)),
    C("fe-saturated-current", combine(MODEL, edited("paper/blocked_2.5V.csv", "blocked.csv",
                                                    _clip_column(2, 0.9))), FE, 1,
      r"^error: blocked\.csv: column 'i' .*saturated.*--force"),
    C("fe-saturated-current-forced", combine(MODEL, edited("paper/blocked_2.5V.csv", "blocked.csv",
                                                           _clip_column(2, 0.9))), FE + ["--force"],
      0, r"^warning: blocked\.csv: column 'i' .*saturated", changes=("model.json",)),
    C("fe-second-log-bad", combine(MODEL, BLOCKED, text("bad.csv", "t,v,i\n")),
      ["fit-electrical", "blocked.csv", "bad.csv", "-m", "model.json"], 1,
      r"^error: bad\.csv: has a header but no data rows"),
    C("fe-current-against-voltage", combine(MODEL, edited(
        "paper/blocked_1.5V.csv", "blocked.csv", _map_column(2, lambda x: -x))), FE, 1,
      r"^error: blocked\.csv: blocked-rotor fit gives a non-positive conductance.*-c i=SRC\*-1"),
    # the voltage in pV (x 1e-12): R comes out 2.4e-12 ohm; before, the model writer's check
    # blamed model.json; now the gate names the log and what to check
    C("fe-voltage-in-picovolts", combine(MODEL, edited(
        "paper/blocked_1.5V.csv", "blocked.csv", _map_column(1, lambda x: x * 1e-12))), FE, 1,
      r"^error: blocked\.csv: the fit gives parameter 'R' = .* is impossible.*units, signs"),
    C("fe-no-logs", MODEL, ["fit-electrical", "-m", "model.json"], 2, r"Missing argument"),
    # ---- fit-mechanical --------------------------------------------------------------------
    C("fm-before-fit-electrical", combine(STEP, model(only=("km",))), FM, 1,
      r"^error: model\.json: .*\bR\b.*fit-electrical"),
    C("fm-no-km", combine(STEP, model(drop=("km", "J", "bv", "bc", "dz"))), FM, 1,
      r"^error: model\.json: .*km.*--km"),
    C("fm-motor-never-moves", combine(MODEL, _step_log("step.csv", omega_scale=0.0,
                                                       theta_scale=0.0)), FM, 1,
      r"^error: step\.csv: "),
    # the voltage logged with an offset (steps -2 V -> -0.5 V) while the speed rises: the
    # steps' damping b comes out negative; before, the model's own check blamed model.json
    C("fm-speed-against-input-offset", combine(MODEL, edited(
        "paper/step_1.5V.csv", "step.csv", _map_column(1, lambda x: x - 2.0))), FM, 1,
      r"^error: step\.csv: the steps give a non-positive damping b = .*speed's sign"),
    C("fm-step-never-happens", combine(MODEL, _step_log("step.csv", v=0.0)), FM, 1,
      r"^error: step\.csv: "),
    C("fm-too-short", combine(MODEL, _step_log("step.csv", n=30, onset=0.01)), FM, 1,
      r"^error: step\.csv: "),
    C("fm-no-speed-or-angle", combine(MODEL, edited("paper/step_1.5V.csv", "step.csv",
                                                    lambda ls: _drop_column(3)(
                                                        _drop_column(4)(ls)))), FM, 1,
      r"^error: step\.csv: .*omega"),
    C("fm-rpm-as-rad-per-s", combine(MODEL, _step_log("step.csv", omega_scale=60 / (2 * np.pi))),
      FM, 1, r"^error: step\.csv: omega is 9\.5\d* x d\(theta\)/dt.*-c omega=COLUMN\*rpm"),
    C("fm-rpm-as-rad-per-s-forced", combine(MODEL, _step_log("step.csv",
                                                             omega_scale=60 / (2 * np.pi))),
      FM + ["--force"], 0, r"^warning: step\.csv: .*rpm", changes=("model.json",)),
    # a torque log is fitted (torque steps need no km: J, bv, bc in SI); a speed that never
    # settles (a ramp) is said so, and a torque log beside a voltage log is refused
    C("fm-torque-driven-log", combine(MODEL, table("step.csv", {
        "t": T1K, "tau": np.where(T1K > 0.5, 0.02, 0.0), "omega": T1K})), FM, 1,
      r"^error: step\.csv: no usable step: the input is not held long enough"),
    C("fm-torque-beside-voltage", combine(STEP, MODEL, table("torque.csv", {
        "t": T1K, "tau": np.where(T1K > 0.5, 0.02, 0.0), "omega": T1K})),
      ["fit-mechanical", "step.csv", "torque.csv", "-m", "model.json"], 1,
      r"^error: step\.csv, torque\.csv: fit-mechanical fits voltage steps or torque steps, "
      r"not both"),
    C("fm-km-not-positive", combine(STEP, MODEL), FM + ["--km", "-0.05"], 2, r"--km"),
    C("fm-bad-km", combine(STEP, MODEL), ["fit-mechanical", "step.csv", "-m", "model.json",
                                          "--km", "fast"], 2, r"'fast' is not a number"),
    # ---- fit-nonlinear ---------------------------------------------------------------------
    # without J, bv (no fit-mechanical) it starts from identify's first-order fit (a note)
    C("fn-before-fit-mechanical", combine(TRI, model(drop=("J", "bv", "bc", "dz"))), FN, 0,
      None, changes=("model.json",)),
    C("fn-before-fit-electrical", combine(TRI, model(drop=("km", "J", "bv", "bc", "dz"))), FN,
      1, r"^error: model\.json: model lacks km"),
    C("fn-model-missing", TRI, FN, 1, r"^error: model\.json: "),
    C("fn-no-speed-or-angle", combine(MODEL, table("tri.csv", {
        "t": T1K, "v": np.sin(T1K), "i": np.sin(T1K) / 2.37})), FN, 1,
      r"^error: tri\.csv: .*(omega|theta)"),
    C("fn-too-short", combine(MODEL, table("tri.csv", {
        "t": T1K[:8], "v": T1K[:8], "omega": T1K[:8], "theta": T1K[:8]})), FN, 1,
      r"^error: tri\.csv: "),
    C("fn-nothing-moves", combine(MODEL, table("tri.csv", {
        "t": T1K, "v": 0 * T1K, "i": 0 * T1K, "omega": 0 * T1K, "theta": 0 * T1K})), FN, 1,
      r"^error: tri\.csv: nothing moves"),
    C("fn-saturated-speed", combine(MODEL, _triangle_log("tri.csv", clip=0.8)), FN, 1,
      r"^error: tri\.csv: column 'omega' .*saturat.*--force"),
    # ---- fit-inverse-dynamics (beyond the contract) ----------------------------------------
    C("fid-voltage-log-without-km", TRI, ["fit-inverse-dynamics", "tri.csv", "-m", "model.json"],
      1, r"^error: tri\.csv: voltage-driven log: .*--km"),
    C("fid-nothing-moves", table("tri.csv", {
        "t": T1K, "tau": 0.01 * np.sin(T1K), "omega": 0 * T1K}),
      ["fit-inverse-dynamics", "tri.csv", "-m", "model.json"], 1, r"^error: .*(move|excite)"),
    C("fid-slow-short-log", table("tri.csv", {
        "t": np.arange(200) * 2.0, "tau": 0.02 * np.sign(np.sin(np.arange(200) / 3.0)),
        "omega": np.sign(np.sin(np.arange(200) / 3.0)) + 0.01 * np.cos(np.arange(200.0))}),
      ["fit-inverse-dynamics", "tri.csv", "-m", "model.json"], 1, r"^error: ", subprocess=True),
    C("fid-model-is-input", TRI, ["fit-inverse-dynamics", "tri.csv", "-m", "tri.csv", "--km",
                                  "0.05"], 1, r"^error: tri\.csv: .*overwrite"),
    C("fid-ok-with-km", TRI, ["fit-inverse-dynamics", "tri.csv", "-m", "model.json", "--km",
                              "0.0502"], 0, None, changes=("model.json",)),
    # ---- report ----------------------------------------------------------------------------
    C("report-out-is-input", combine(STEP, MODEL),
      ["report", "step.csv", "-m", "model.json", "-o", "step.csv"], 1,
      r"^error: step\.csv: "),
    C("report-out-under-regular-file", combine(STEP, MODEL, regular_file("notes.txt")),
      ["report", "step.csv", "-m", "model.json", "-o", "notes.txt/rep"], 1,
      r"^error: notes\.txt\b"),
    C("report-out-in-proc", combine(STEP, MODEL),
      ["report", "step.csv", "-m", "model.json", "-o", "/proc/pmdcid-report"], 1,
      r"^error: /proc"),
    C("report-out-is-its-summary", combine(STEP, MODEL, text("sum.json", '{"added": []}')),
      ["report", "step.csv", "-m", "model.json", "-o", "sum.json", "--summary", "sum.json"], 1,
      r"^error: sum\.json: "),
    C("report-summary-not-json", combine(STEP, MODEL, text("sum.json", "added: stribeck")),
      ["report", "step.csv", "-m", "model.json", "-o", "rep", "--summary", "sum.json"], 1,
      r"^error: sum\.json: "),
    C("report-out-is-model", combine(STEP, MODEL),
      ["report", "step.csv", "-m", "model.json", "-o", "model.json"], 1, r"^error: model\.json: "),
    C("report-summary-deeply-nested", combine(STEP, MODEL, text("sum.json", "[" * 100000)),
      ["report", "step.csv", "-m", "model.json", "-o", "rep", "--summary", "sum.json"], 1,
      r"^error: sum\.json: .*nested"),
    C("report-model-missing", STEP, ["report", "step.csv", "-m", "model.json", "-o", "rep"], 1,
      r"^error: model\.json: "),
    C("report-model-incomplete", combine(STEP, model(only=("R", "L"))),
      ["report", "step.csv", "-m", "model.json", "-o", "rep"], 1, r"^error: model\.json: "),
    C("report-log-header-only", combine(MODEL, text("step.csv", "t,v,i,omega,theta\n")),
      ["report", "step.csv", "-m", "model.json", "-o", "rep"], 1, r"^error: step\.csv: "),
    # ---- diagnose --------------------------------------------------------------------------
    C("diag-out-is-input", combine(STEP, MODEL),
      ["diagnose", "step.csv", "-m", "model.json", "-o", "step.csv"], 1, r"^error: step\.csv: "),
    C("diag-summary-is-input", combine(STEP, MODEL),
      ["diagnose", "step.csv", "-m", "model.json", "-o", "new.json", "--summary", "step.csv"], 1,
      r"^error: step\.csv: "),
    C("diag-model-missing", STEP, ["diagnose", "step.csv", "-m", "model.json", "-o", "new.json"],
      1, r"^error: model\.json: "),
    C("diag-model-empty", combine(STEP, text("model.json", "")),
      ["diagnose", "step.csv", "-m", "model.json", "-o", "new.json"], 1,
      r"^error: model\.json: .*empty"),
    C("diag-out-under-regular-file", combine(STEP, MODEL, regular_file("notes.txt")),
      ["diagnose", "step.csv", "-m", "model.json", "-o", "notes.txt/new.json"], 1,
      r"^error: notes\.txt\b"),
    C("diag-log-jittery", combine(MODEL, table("step.csv", {
        "t": T1K + np.random.default_rng(3).uniform(0, 4e-4, 3000), "v": np.ones(3000),
        "omega": np.ones(3000)})),
      ["diagnose", "step.csv", "-m", "model.json", "-o", "new.json"], 0,
      r"^warning: step\.csv: loop-timed samples", changes=("new.json",)),
    C("diag-summary-is-new-model", combine(STEP, MODEL),
      ["diagnose", "step.csv", "-m", "model.json", "-o", "x.json", "--summary", "x.json"], 1,
      r"^error: x\.json: "),
    C("diag-summary-is-model", combine(STEP, MODEL),
      ["diagnose", "step.csv", "-m", "model.json", "-o", "new.json", "--summary", "model.json"],
      1, r"^error: model\.json: "),
    C("diag-model-lacks-J", combine(STEP, model(only=("R", "L", "km"))),
      ["diagnose", "step.csv", "-m", "model.json", "-o", "new.json"], 1,
      r"^error: model\.json: model lacks J"),
    C("diag-unknown-effect", combine(STEP, MODEL),
      ["diagnose", "step.csv", "-m", "model.json", "-o", "new.json", "--effect", "warp_drive"],
      2, r"unknown effect 'warp_drive'"),
    C("diag-log-too-short", combine(MODEL, text("step.csv", "t,v,omega\n0,0,0\n0.01,1,0.1\n"
                                                        "0.02,1,0.3\n0.03,1,0.4\n")),
      ["diagnose", "step.csv", "-m", "model.json", "-o", "new.json"], 1,
      r"^error: step\.csv: too short to judge an effect: 4 samples"),
    C("diag-log-without-measurement", combine(MODEL, table("step.csv", {
        "t": T1K, "v": np.ones(3000)})),
      ["diagnose", "step.csv", "-m", "model.json", "-o", "new.json"], 1,
      r"^error: step\.csv: no log carries current, speed or angle"),
    C("diag-rpm-as-rad-per-s", combine(MODEL, _step_log("step.csv", omega_scale=60 / (2 * np.pi))),
      ["diagnose", "step.csv", "-m", "model.json", "-o", "new.json"], 1,
      r"^error: step\.csv: .*omega looks like rpm.*--force"),
    # speeds no motor reaches (v, i, omega, theta all x 1e12, consistent with each other):
    # refused (forced, diagnose's refit range for Stribeck's ws from such speeds lay beyond its
    # physical bound: scipy's ValueError as an internal error; tests/fit/test_solver.py)
    C("diag-speed-beyond-any-motor", combine(MODEL, _step_log("step.csv", v=1.5e12)),
      ["diagnose", "step.csv", "-m", "model.json", "-o", "new.json"], 1,
      r"^error: step\.csv: omega reaches .* beyond any motor's speed.*--force", subprocess=True),
    C("sim-speed-beyond-any-motor", combine(MODEL, _step_log("step.csv", v=1.5e12)), SIM, 0,
      r"^warning: step\.csv: omega reaches .* beyond any motor's speed", changes=("out.csv",)),
    C("diag-rpm-as-rad-per-s-forced", combine(MODEL, _step_log("step.csv",
                                                               omega_scale=60 / (2 * np.pi))),
      ["diagnose", "step.csv", "-m", "model.json", "-o", "new.json", "--force"], 0,
      r"^warning: step\.csv: .*rpm", changes=("new.json",)),
    # forced past the speed gate: the fit's refusal (no room for ws) names the log
    C("diag-no-room-names-the-log", combine(MODEL, edited(
        "paper/step_1.5V.csv", "step.csv", lambda ls: _scale_columns(ls, (1, 2, 3, 4), 1e12))),
      ["diagnose", "step.csv", "-m", "model.json", "-o", "new.json", "--force"], 1,
      r"^error: step\.csv: no room to fit ws"),
    # voltages and currents no DC motor reaches: the same gate as the speed's, naming the column
    C("fm-voltage-beyond-any-motor", combine(MODEL, edited("paper/step_1.5V.csv", "step.csv",
                                                           _map_column(1, lambda x: x * 1e12))),
      FM, 1, r"^error: step\.csv: v reaches 1\.5e\+12 V, beyond any DC motor's voltage.*--force",
      subprocess=True),
    C("fe-current-beyond-any-motor", combine(MODEL, edited("paper/blocked_1.5V.csv", "blocked.csv",
                                                           _map_column(2, lambda x: x * 1e12))),
      FE, 1, r"^error: blocked\.csv: i reaches .* A, beyond any DC motor's current"),
    C("sim-voltage-beyond-any-motor", combine(MODEL, edited("paper/step_1.5V.csv", "step.csv",
                                                            _map_column(1, lambda x: x * 1e12))),
      SIM, 0, r"^warning: step\.csv: v reaches 1\.5e\+12 V", changes=("out.csv",)),
    # a command that fails prints its one error line, not the warnings it gave on the way (a NaN
    # filled in the speed, then no step in a constant input)
    C("fm-warning-then-refusal-one-line", combine(MODEL, edited(
        "paper/step_1.5V.csv", "step.csv", lambda ls: _map_column(1, lambda x: 0.0)(
            _replace_data_row(100, 3, "nan")(ls)))), FM, 1, r"^error: step\.csv: "),
    # 3 rows: said as too short, not as "no step" (whose hint, fit-nonlinear, needs 50)
    C("fm-three-rows", combine(MODEL, edited("paper/step_1.5V.csv", "step.csv", _head(3))), FM, 1,
      r"^error: step\.csv: too short \(3 samples\) to hold a step response"),
    C("fm-twelve-rows", combine(MODEL, edited("paper/step_1.5V.csv", "step.csv", _head(12))), FM,
      1, r"^error: step\.csv: no log holds a voltage step, and at 12 samples the logs are too "
         r"short for fit-nonlinear too"),
    C("identify-three-rows", edited("paper/step_1.5V.csv", "step.csv", _head(3)),
      ["identify", "step.csv", "-m", "model.json", "--no-diagnose"], 1,
      r"^error: no log identifies anything: step\.csv: only 3 samples: too short for any stage"),
    # a time column that wraps (a 16-bit ms counter) or drops to 0 (a logger that stopped)
    C("log-time-wraps", combine(MODEL, table("step.csv", {
        "t [ms]": (np.arange(3000) + 64000) % 65536, "v": np.ones(3000)})), SIM, 1,
      r"^error: step\.csv: time goes back .* 16-bit millisecond counter"),
    C("log-time-zeros-at-the-end", combine(MODEL, table("step.csv", {
        "t": np.where(np.arange(3000) < 2950, T1K, 0.0), "v": np.ones(3000)})), SIM, 1,
      r"^error: step\.csv: time goes back at data row 2951 .* every stamp from there to the end "
      r"\(50 rows\) is 0.*cut the log after data row 2950"),
    # a controller whose reference column no log carries: refused before any stage (was: each
    # closed-loop fit skipped, exit 0 with fit-mechanical's open-loop model)
    C("identify-controller-reference-absent", STEP,
      ["identify", "step.csv", "-m", "model.json", "--no-diagnose", "--controller",
       "type=PI,kp=0.05,ki=2,reference=nosuch"], 1,
      r"^error: step\.csv: the controller's reference column 'nosuch' is in none of the logs"),
    # ---- demo ------------------------------------------------------------------------------
    C("demo-out-under-regular-file", regular_file("notes.txt"), ["demo", "-o", "notes.txt/d"], 1,
      r"^error: notes\.txt\b"),
    C("demo-out-is-a-file", regular_file("notes.txt"), ["demo", "-o", "notes.txt"], 1,
      r"^error: notes\.txt\b"),
    C("demo-out-in-proc", lambda d: None, ["demo", "-o", "/proc/pmdcid-demo"], 1, r"^error: /proc"),
    # ---- export ----------------------------------------------------------------------------
    C("export-model-missing", lambda d: None, EXP + ["c", "-o", "motor.c"], 1,
      r"^error: model\.json: no such model file", subprocess=True),
    C("export-model-lacks-km", model(drop=("km",)), EXP + ["python-control", "-o", "m.py"], 1,
      r"^error: model\.json: model has R, L but lacks km"),
    C("export-model-lacks-J", model(drop=("J",)), EXP + ["matlab", "-o", "motor.m"], 1,
      r"^error: model\.json: model lacks J"),
    C("export-over-a-log", combine(MODEL, STEP), EXP + ["c", "-o", "step.csv"], 1,
      r"^error: step\.csv: exists and was not written by pmdcid export; use --force"),
    C("export-header-over-a-log", combine(MODEL, fixture("paper/step_1.5V.csv", "motor.h")),
      EXP + ["c", "-o", "motor.c"], 1, r"^error: motor\.h: exists and was not written"),
    C("export-over-the-model", MODEL, EXP + ["python-control", "-o", "model.json", "--force"], 1,
      r"^error: model\.json: output would overwrite the model file"),
    C("export-matlab-bad-name", MODEL, EXP + ["matlab", "-o", "my-motor.m"], 1,
      r"^error: my-motor\.m: a MATLAB function file must be NAME\.m"),
    C("usage-export-unknown-format", MODEL, EXP + ["fortran", "-o", "m.f"], 2,
      r"'fortran' is not one of", subprocess=True),
    # ---- plan ------------------------------------------------------------------------------
    C("plan-both-limits", MODEL, ["plan", "-m", "model.json", "--vmax", "2", "--taumax", "0.1",
                                  "-o", "out"], 2, r"--vmax or --taumax, not both"),
    C("plan-neither-model-nor-guess", lambda d: None, ["plan", "--vmax", "2", "-o", "out"], 2,
      r"give -m MODEL, or --guess", subprocess=True),
    C("plan-guess-without-limit", lambda d: None, ["plan", "--guess", "-o", "out"], 2,
      r"--guess needs --vmax"),
    # t in ms without a unit: before, simulated at a 10 s period (newrigs' PI loop: no answer in
    # 120 s; the demo's step: a prediction from the wrong time base); now refused like a fit
    C("plan-check-time-in-ms", combine(MODEL, edited("paper/step_1.5V.csv", "step.csv",
                                                     _map_column(0, lambda x: 1000 * x))),
      ["plan", "--check", "step.csv", "-m", "model.json", "-o", "plan"], 1,
      r"^error: step\.csv: t looks like milliseconds.*-c t=COLUMN\*ms"),
    C("plan-check-without-logs", MODEL, ["plan", "--check", "-m", "model.json"], 2,
      r"--check needs the LOGs"),
    C("plan-budget-too-large", MODEL, ["plan", "-m", "model.json", "--budget", "1e9", "-o",
                                       "out"], 2, r"--budget 1e\+09 s at --rate 1000 Hz"),
    C("plan-missing-model", lambda d: None, ["plan", "-m", "nope.json", "--vmax", "2", "-o", "out"],
      1, r"^error: nope\.json: no such model file"),
    C("plan-model-lacks-J", model(only=("R", "L", "km")),
      ["plan", "-m", "model.json", "--vmax", "2", "-o", "out"], 1,
      r"^error: model\.json: model lacks J"),
    C("plan-torque-model-with-vmax", model(only=("J", "bv", "bc", "dz")),
      ["plan", "-m", "model.json", "--vmax", "2", "-o", "out"], 1,
      r"^error: model\.json: .*give --taumax"),
    C("plan-out-is-a-file", combine(MODEL, regular_file("notes.txt")),
      ["plan", "-m", "model.json", "--vmax", "2", "-o", "notes.txt"], 1, r"^error: notes\.txt\b"),
    C("plan-out-under-a-file", combine(MODEL, regular_file("notes.txt")),
      ["plan", "-m", "model.json", "--vmax", "2", "-o", "notes.txt/d"], 1,
      r"^error: notes\.txt/d\b"),
    C("plan-check-mixed-drives", combine(MODEL, STEP, table("tau.csv", {
        "t": T1K, "tau": np.where(T1K > 0.5, 0.01, 0.0), "omega": np.zeros(3000)})),
      ["plan", "--check", "step.csv", "tau.csv", "-m", "model.json"], 1,
      r"^error: step\.csv: logs mix voltage"),
    # ---- usage errors (click) --------------------------------------------------------------
    C("usage-no-model", STEP, ["simulate", "step.csv", "-o", "out.csv"], 2,
      r"Missing option '-m'"),
    C("usage-bad-seed", combine(STEP, MODEL), SIM + ["--seed", "abc"], 2,
      r"'abc' is not a valid integer"),
    C("usage-negative-noise", combine(STEP, MODEL), SIM + ["--noise-i", "-0.01"], 2,
      r"'-0\.01' is not a finite number >= 0"),
    C("usage-nan-noise", combine(STEP, MODEL), SIM + ["--noise-omega", "nan"], 2,
      r"'nan' is not a finite number >= 0"),
    C("usage-negative-encoder", combine(STEP, MODEL), SIM + ["--encoder", "-4096"], 2,
      r"-4096 is not in the range x>=0"),
    C("usage-negative-seed", combine(STEP, MODEL), SIM + ["--noise-i", "0.01", "--seed", "-1"], 2,
      r"-1 is not in the range x>=0"),
    C("usage-nan-cutoff", combine(STEP, MODEL), SIM + ["--cutoff", "nan"], 2,
      r"'nan' is not a finite number > 0"),
    C("usage-unknown-option", combine(STEP, MODEL), SIM + ["--frobnicate"], 2,
      r"No such option '--frobnicate'", subprocess=True),
    # ---- round two (issue 15): the plausibility gate -----------------------------------------
    C("fm-time-in-ms", combine(MODEL, edited("paper/step_1.5V.csv", "step.csv",
                                             _scale_column(0, 1e3))), FM, 1,
      r"^error: step\.csv: t looks like milliseconds.*-c t=COLUMN\*ms"),
    C("fe-time-in-us", combine(MODEL, edited("paper/blocked_1.5V.csv", "blocked.csv",
                                             _scale_column(0, 1e6))), FE, 1,
      r"^error: blocked\.csv: t looks like microseconds.*-c t=COLUMN\*us"),
    C("fn-time-in-ms", combine(MODEL, edited("paper/triangle.csv", "tri.csv",
                                             _scale_column(0, 1e3))), FN, 1,
      r"^error: tri\.csv: t looks like milliseconds"),
    C("diag-time-in-ms", combine(MODEL, edited("paper/step_1.5V.csv", "step.csv",
                                               _scale_column(0, 1e3))),
      ["diagnose", "step.csv", "-m", "model.json", "-o", "new.json"], 1,
      r"^error: step\.csv: t looks like milliseconds"),
    C("fm-rpm-speed-only", combine(MODEL, _step_log("step.csv", omega_scale=60 / (2 * np.pi),
                                                    theta=False)), FM, 1,
      r"^error: step\.csv: km\*omega is 9\.\d+ x the back-EMF.*-c omega=COLUMN\*rpm"),
    C("fm-rpm-speed-only-km-option", combine(
        model(drop=("km", "J", "bv", "bc", "dz")),
        _step_log("step.csv", omega_scale=60 / (2 * np.pi), theta=False)),
      FM + ["--km", "0.0502"], 1, r"^error: step\.csv: km\*omega is .*rpm"),
    C("fn-deg-per-s-speed-only", combine(MODEL, _triangle_log(
        "tri.csv", omega_scale=180 / np.pi, theta=False, seconds=20.0, bv=2e-4, bc=1e-3)),
      FN, 1, r"^error: tri\.csv: the speed is 4\d\.?\d* x the no-load speed.*deg/s"),
    C("sim-overload-sample", combine(MODEL, OVERLOAD), SIM, 1,
      r"^error: step\.csv: column 'v' holds 9\.9e\+37 \(data row 701\): an instrument overload"),
    C("fm-overload-sample", combine(MODEL, OVERLOAD), FM, 1,
      r"^error: step\.csv: column 'v' holds 9\.9e\+37"),
    C("report-overload-in-speed", combine(MODEL, edited("paper/step_1.5V.csv", "step.csv",
                                                        _replace_data_row(9, 3, "-9.91e37"))),
      ["report", "step.csv", "-m", "model.json", "-o", "rep"], 1,
      r"^error: step\.csv: column 'omega' holds -9\.91e\+37"),
    # ---- model values with units, values the loader would refuse ----------------------------
    C("model-unit-mohm", combine(STEP, model_units(R=(2370.0, "mohm"))), SIM, 0, None,
      changes=("out.csv",)),
    C("model-unit-mH-and-mNm-per-A", combine(STEP, model_units(L=(17.8, "mH"),
                                                                km=(50.2, "mN m/A"))), SIM, 0,
      None, changes=("out.csv",)),
    C("model-unit-unknown", combine(STEP, model_units(J=(2.0, "oz in^2"))), SIM, 1,
      r"^error: model\.json: parameter 'J' has unit 'oz in\^2', which pmdcid cannot convert"),
    C("model-unit-not-text", combine(STEP, text("model.json", '{"parameters": {"R": {"value": '
                                                '2.37, "unit": 5}}}')), SIM, 1,
      r"^error: model\.json: parameter 'R' has unit 5"),
    C("model-unit-prefix-out-of-bounds", combine(STEP, model_units(R=(2.37, "Mohm"))), SIM, 1,
      r"^error: model\.json: parameter 'R' = 2\.37e\+06 ohm is impossible"),
    C("model-utf8-bom", combine(STEP, model_units(bom=True)), SIM, 0, None, changes=("out.csv",)),
    C("model-utf16", combine(STEP, model_units(encoding="utf-16")), SIM, 0, None,
      changes=("out.csv",)),
    C("fm-km-huge", combine(STEP, MODEL), FM + ["--km", "1e300"], 2,
      r"'1e300' is above 1000"),
    C("fid-km-huge", TRI, ["fit-inverse-dynamics", "tri.csv", "-m", "model.json", "--km", "1e9"],
      2, r"'1e9' is above 1000"),
    C("sim-noise-huge", combine(STEP, MODEL), SIM + ["--noise-i", "1e308", "--seed", "1"], 1,
      r"^error: out\.csv: simulated column 'i' reaches .*--noise-i"),
    # ---- bounded work ------------------------------------------------------------------------
    C("sim-tiny-J", combine(STEP, model(J=1e-12)), SIM, 0,
      r"^warning: model\.json: the model's mechanical time constant .* is shorter than any "
      r"motor's .*check J", changes=("out.csv",), subprocess=True),
    C("sim-time-in-us", combine(MODEL, table("step.csv", {"t": T1K * 1e6, "v": np.ones(3000)})),
      SIM, 1,
      r"^error: model\.json: the simulation would take .*t in ms or us"),
    C("fm-time-step-1e300", combine(MODEL, text("step.csv", "t,v,omega\n0,1,0\n1e300,1,1\n"
                                                "2e300,1,2\n")), FM, 1,
      r"^error: step\.csv: the sample period 1e\+300 s is no motor log's"),
    C("sim-time-step-1e300", combine(MODEL, text("step.csv", "t,v\n0,1\n1e300,1\n2e300,1\n")),
      SIM, 1, r"^error: model\.json: the simulation would take"),
    C("log-transposed-120k-columns", combine(MODEL, transposed("step.csv")), SIM, 1,
      r"^error: step\.csv: has no time column 't' \(columns are s0, s1, .*more\)",
      subprocess=True),
    C("log-200kb-column-name", combine(MODEL, text("step.csv", "x" * 200_000 + ",v\n1,2\n3,4\n"
                                                   "5,6\n")), SIM, 1,
      r"^error: step\.csv: has no time column"),
    C("log-200kb-cell", combine(MODEL, text("step.csv", "t,v\n0,1\n0.001," + "7" * 200_000
                                            + "x\n0.002,1\n")), SIM, 1,
      r"^error: step\.csv: column 'v' holds non-numeric value"),
    C("fm-cutoff-tiny", combine(MODEL, edited("paper/step_1.5V.csv", "step.csv",
                                              _drop_column(3))), FM + ["--cutoff", "1e-9"], 1,
      r"^error: step\.csv: filter cut-off 1e-09 Hz is too low.*at least 0\.01 Hz"),
    C("sim-cutoff-tiny", combine(MODEL, edited("paper/step_1.5V.csv", "step.csv",
                                               _drop_column(3))), SIM + ["--cutoff", "1e-9"], 1,
      r"^error: step\.csv: filter cut-off 1e-09 Hz is too low"),
    # ---- outputs -----------------------------------------------------------------------------
    C("diag-out-is-a-measured-log", combine(STEP, MODEL, fixture("paper/step_2.5V.csv",
                                                                 "other.csv")),
      ["diagnose", "step.csv", "-m", "model.json", "-o", "other.csv"], 1,
      r"^error: other\.csv: exists and is not a pmdcid model file.*--force"),
    C("diag-summary-is-a-measured-log", combine(STEP, MODEL, fixture("paper/step_2.5V.csv",
                                                                     "other.csv")),
      ["diagnose", "step.csv", "-m", "model.json", "-o", "new.json", "--summary", "other.csv"],
      1, r"^error: other\.csv: exists and is not a pmdcid summary file"),
    C("diag-summary-is-notes", combine(STEP, MODEL, regular_file("notes.json")),
      ["diagnose", "step.csv", "-m", "model.json", "-o", "new.json", "--summary", "notes.json"],
      1, r"^error: notes\.json: exists and is not a pmdcid summary file"),
    C("diag-out-is-another-model", combine(STEP, MODEL, model("old.json")),
      ["diagnose", "step.csv", "-m", "model.json", "-o", "old.json", "--effect", "stribeck"], 0,
      None, changes=("old.json",)),
    C("fe-model-symlink", combine(BLOCKED, lambda d: (d / "real").mkdir(), model("real/m.json"),
                                  symlinked("model.json", "real/m.json")), FE, 0, SAME_V,
      changes=("model.json", "real/m.json")),
    C("sim-out-dangling-symlink", combine(STEP, MODEL, symlinked("out.csv", "new.csv")), SIM, 0,
      None),
    C("report-summary-wrong-types", combine(STEP, MODEL, text(
        "sum.json", '{"added": 5, "candidates": "x", "unexplained": "no"}')),
      ["report", "step.csv", "-m", "model.json", "-o", "rep", "--summary", "sum.json"], 1,
      r"^error: sum\.json: summary field 'added' must be a list of effect names"),
    C("report-summary-bad-candidates", combine(STEP, MODEL, text(
        "sum.json", '{"added": [], "candidates": [{"effect": "x", "delta_bic": "big"}]}')),
      ["report", "step.csv", "-m", "model.json", "-o", "rep", "--summary", "sum.json"], 1,
      r"^error: sum\.json: summary field 'candidates'"),
    C("report-summary-bad-unexplained", combine(STEP, MODEL, text(
        "sum.json", '{"added": [], "unexplained": "no"}')),
      ["report", "step.csv", "-m", "model.json", "-o", "rep", "--summary", "sum.json"], 1,
      r"^error: sum\.json: summary field 'unexplained'"),
    # ---- reading what rigs export -----------------------------------------------------------
    C("map-quoted-column-with-slash", combine(MODEL, text(
        "step.csv", "t,v,speed [rad/s]\n0,0,0\n0.001,1,0.1\n0.002,1,0.2\n")),
      SIM + ["-c", 'omega="speed [rad/s]"*1'], 0, None, changes=("out.csv",)),
    C("map-quoted-column-absent", combine(MODEL, STEP), SIM + ["-c", 'omega="speed [rpm]"*rpm'],
      1, r"^error: step\.csv: column mapping omega=speed \[rpm\]: no column 'speed \[rpm\]'"),
    C("map-sign-magnitude-pwm", combine(MODEL, pwm_log("step.csv")),
      SIM + ["-c", "v=pwm*(2*dir-1)*12/255"], 0, None, changes=("out.csv",)),
    C("map-sign-function", combine(MODEL, pwm_log("step.csv")),
      SIM + ["-c", "v=pwm*sign(dir-0.5)*12/255"], 0, None, changes=("out.csv",)),
    C("map-unknown-function", combine(MODEL, pwm_log("step.csv")),
      SIM + ["-c", "v=pwm*exp(dir)"], 2, r"unknown function 'exp' \(known: sign, abs\)"),
    C("map-unclosed-parenthesis", combine(MODEL, pwm_log("step.csv")),
      SIM + ["-c", "v=(pwm*12/255"], 2, r"a '\(' is not closed"),
    C("map-no-eval", combine(MODEL, pwm_log("step.csv")),
      SIM + ["-c", "v=__import__('os').getcwd()"], 2, r"column mapping"),
    C("map-expression-divides-by-zero", combine(MODEL, pwm_log("step.csv")),
      SIM + ["-c", "v=(pwm)/0"], 2, r"divides by zero"),
    C("map-file-skips-absent-column", combine(MODEL, STEP, text(
        "rig.map", "omega = speed_rpm*rpm\nv = v\n")), SIM + ["--map", "rig.map"], 0, None,
      changes=("out.csv",)),
    C("map-file-skipped-line-needed", combine(MODEL, pwm_log("step.csv", "t,duty,direction"), text(
        "rig.map", "# two rigs\nv = pwm*sign(dir-0.5)*12/255\n")),
      SIM + ["--map", "rig.map"], 1,
      r"^error: step\.csv: has no input column.*rig\.map line 2 \(v = pwm.*skipped: no column "
      r"'pwm'"),
    C("map-file-skipped-line-fit", combine(MODEL, edited("paper/step_1.5V.csv", "step.csv", lambda
                                                         ls: _drop_column(3)(_drop_column(4)(ls))),
                                           text("rig.map", "omega=tacho*150*rpm\n")),
      FM + ["--map", "rig.map"], 1, r"^error: step\.csv: .*rig\.map line 1 .*no column 'tacho'"),
    C("map-file-partly-absent", combine(MODEL, pwm_log("step.csv"), text(
        "rig.map", "v = pwm*sign(direction)*12/255\n")), SIM + ["--map", "rig.map"], 1,
      r"^error: step\.csv: column mapping v=direction: no column 'direction'"),
    C("map-file-utf8-bom", combine(MODEL, STEP, text("cols.map", "\ufeffv=v*1\n")),
      SIM + ["--map", "cols.map"], 0, None, changes=("out.csv",)),
    C("map-file-quoted-hash", combine(MODEL, text("step.csv", 't,v,"speed #2"\n0,0,0\n'
                                                  "0.001,1,0.1\n0.002,1,0.2\n"),
                                      text("cols.map", 'omega = "speed #2"  # quoted\n')),
      SIM + ["--map", "cols.map"], 0, None, changes=("out.csv",)),
    C("log-european-excel", combine(MODEL, european("paper/step_1.5V.csv", "step.csv")), SIM, 0,
      None, changes=("out.csv",)),
    C("fm-european-excel", combine(MODEL, european("paper/step_1.5V.csv", "step.csv")), FM, 0,
      r"^warning: all steps have the same amplitude", changes=("model.json",)),
    C("log-tab-separated", combine(MODEL, text("step.csv", "t\tv\n0\t0\n0.001\t1\n"
                                               "0.002\t1\n")), SIM, 0, None,
      changes=("out.csv",)),
    C("log-bom-before-comments", combine(MODEL, encoded("paper/step_1.5V.csv", "step.csv",
                                                        "utf-8-sig")), SIM, 0, None,
      changes=("out.csv",)),
    C("log-utf16-with-bom", combine(MODEL, encoded("paper/step_1.5V.csv", "step.csv", "utf-16")),
      SIM, 0, None, changes=("out.csv",)),
    C("fe-utf16-with-bom", combine(MODEL, encoded("paper/blocked_1.5V.csv", "blocked.csv",
                                                  "utf-16")), FE, 0, SAME_V,
      changes=("model.json",)),
    C("log-utf16-garbage", combine(MODEL, text("step.csv", b"\xff\xfe" + bytes(range(1, 200)))),
      SIM, 1, r"^error: step\.csv: starts like UTF-16 text but is not"),
    C("summary-utf8-bom", combine(STEP, MODEL, text("sum.json", '\ufeff{"added": []}')),
      ["report", "step.csv", "-m", "model.json", "-o", "rep", "--summary", "sum.json"], 0, None),
]


# ----------------------------------------------------------------------------------------------

def _snapshot(d: Path) -> dict[str, str]:
    out = {}
    for p in d.rglob("*"):
        if p.is_file():
            out[str(p.relative_to(d))] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def _check_outcome(case: Case, d: Path, status: int, stderr: str, before: dict[str, str]):
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert "Traceback" not in stderr, stderr
    assert "internal error" not in stderr, stderr
    assert status == case.status, f"exit {status}, stderr:\n{stderr}"
    if case.status == 1:
        assert len(lines) == 1, f"expected one stderr line, got:\n{stderr}"
        assert lines[0].startswith("error: "), lines[0]
        assert re.search(case.pattern, lines[0]), lines[0]
    elif case.status == 2:
        assert re.search(case.pattern, stderr), stderr
    elif case.pattern is None:
        assert lines == [], stderr
    else:
        assert any(re.search(case.pattern, ln) for ln in lines), stderr
        assert all(ln.startswith("warning: ") for ln in lines), stderr
    after = _snapshot(d)
    for name, digest in before.items():
        if case.status == 0 and name in case.changes:
            continue
        assert after.get(name) == digest, f"{name} was modified or removed"
    leftovers = [n for n in after if n not in before and n.endswith(".tmp")]
    assert not leftovers, leftovers
    if case.status != 0:
        assert set(after) <= set(before), f"failed command left files: {set(after) - set(before)}"


def _command_available(args: list[str]) -> bool:
    return args[0] in main.commands


def _require_command(case: Case) -> None:
    assert _command_available(case.args), (
        f"row {case.id}: command {case.args[0]!r} is not registered (a removed or renamed "
        "command must not pass as a skip)")


def _params(cases):
    return [pytest.param(c, id=c.id, marks=c.marks) for c in cases]


@pytest.mark.parametrize("case", _params(CASES))
def test_bad_input(case: Case, tmp_path, monkeypatch):
    _require_command(case)
    monkeypatch.chdir(tmp_path)
    case.build(tmp_path)
    before = _snapshot(tmp_path)
    res = CliRunner().invoke(main, case.args, catch_exceptions=False)
    _check_outcome(case, tmp_path, res.exit_code, res.stderr, before)


SUB = [c for c in CASES if c.subprocess]


@pytest.mark.parametrize("case", _params(SUB))
def test_bad_input_real_process(case: Case, tmp_path):
    """The same rows through a real process: what a user's terminal shows."""
    _require_command(case)
    case.build(tmp_path)
    before = _snapshot(tmp_path)
    env = {k: v for k, v in os.environ.items() if k != "PMDCID_DEBUG"}
    exe = [str(PMDCID)] if PMDCID.exists() else [
        sys.executable, "-c", "import sys; from pmdcid.cli import main; sys.exit(main())"]
    proc = subprocess.run([*exe, *case.args], cwd=tmp_path, capture_output=True,
                          text=True, env=env, timeout=120)
    _check_outcome(case, tmp_path, proc.returncode, proc.stderr, before)


def test_table_is_large_enough():
    assert len(CASES) >= 150
    assert len({c.id for c in CASES}) == len(CASES), "row ids must be unique"


# ---- the plausibility checks themselves: no false alarms on good logs, right unit named ------

@pytest.mark.parametrize("folder", ["paper", "hidden"])
def test_no_warning_on_the_bundled_logs(folder):
    import warnings

    from pmdcid.errors import PmdcidWarning
    from pmdcid.io import read_log

    with warnings.catch_warnings():
        warnings.simplefilter("error", PmdcidWarning)
        for p in sorted((FIX / folder).glob("*.csv")):
            read_log(p)


def test_no_warning_on_real_emps_logs():
    import warnings

    from pmdcid.errors import PmdcidWarning
    from pmdcid.io import parse_mapping, read_log

    logs = sorted((FIX.parents[1] / "shared" / "data" / "emps").glob("*.csv"))
    if not logs:
        pytest.skip("no EMPS logs under ../shared/data/emps")
    m = parse_mapping(["t=t_s", "theta=qm_meas_m", "tau=force_N"])
    with warnings.catch_warnings():
        warnings.simplefilter("error", PmdcidWarning)
        for p in logs:
            read_log(p, m)


@pytest.mark.parametrize("scale, unit", [(60 / (2 * np.pi), "rpm"), (180 / np.pi, "deg/s"),
                                         (1 / (2 * np.pi), "rev/s"), (1e3, "milli"),
                                         (1e-3, r"t is scaled 1000 x too small \(a t in s "
                                                r"mapped with \*ms\)"),
                                         (1e-6, r"t is scaled 1e6 x too small")])
def test_speed_unit_named(scale, unit, rng):
    from pmdcid.errors import PmdcidWarning
    from pmdcid.io.checks import check_speed_units

    t = np.arange(20000) * 5e-4
    om = 3.0 * np.sin(2 * np.pi * 0.3 * t) + rng.normal(0, 0.05, t.size)
    th = np.round(3.0 / (2 * np.pi * 0.3) * (1 - np.cos(2 * np.pi * 0.3 * t)) / 1.5e-3) * 1.5e-3
    assert check_speed_units(om, th, 5e-4, "x.csv") == pytest.approx(1.0, rel=0.02)
    with pytest.warns(PmdcidWarning, match=unit):
        k = check_speed_units(om * scale, th, 5e-4, "x.csv")
    assert k == pytest.approx(scale, rel=0.02)


def test_saturation_needs_a_pile_up_at_the_rail(rng):
    from pmdcid.errors import PmdcidWarning
    from pmdcid.io.checks import check_saturation

    t = np.arange(5000) * 1e-3
    x = 2.0 * (1 - np.exp(-t / 0.3)) + rng.normal(0, 0.01, t.size)
    assert not check_saturation(x, "omega", "x.csv")  # noisy settle: no rail
    assert not check_saturation(2.0 * (1 - np.exp(-t / 0.05)), "omega", "x.csv")  # exact settle
    assert not check_saturation(np.round(x / 0.02) * 0.02, "omega", "x.csv")  # ADC steps
    with pytest.warns(PmdcidWarning, match="maximum 1.5"):
        assert check_saturation(np.minimum(x, 1.5), "omega", "x.csv")
    with pytest.warns(PmdcidWarning, match="minimum -1.5"):
        assert check_saturation(np.maximum(-x, -1.5), "i", "x.csv")


def _counted_settle(rng, top: float = 8533.0, q: float = 23.0, share: float = 0.8):
    """A speed [rpm] from encoder counts (one count: ``q`` rpm a sample), 500 rows at 200 Hz:
    a first-order rise from rest (at 0.1 s) to the level ``top``, then dithering between
    ``top`` (a ``share`` of the settled rows) and the level below, as the counts do."""
    t = np.arange(500) * 5e-3
    w = np.round(top * (1 - np.exp(-np.clip(t - 0.1, 0, None) / 0.25)) / q) * q
    settled = t > 1.5
    w[settled] = np.where(rng.random(settled.sum()) < share, top, top - q)
    return w


def test_a_settled_speed_in_whole_counts_is_no_rail():
    """newrigs dcm-pwm seed 7: a speed logged in counts of 23 rpm settles between its top level
    and the one below (166 and 41 rows): the top is entered only from the next level and
    alternates with it, a quantised settle, not a clip (refused at main). The same signal
    clipped below its settled speed (entered from further below, the signal still rising), or
    a coarse one held in a single run where it would go on, stays a rail."""
    from pmdcid.errors import PmdcidWarning
    from pmdcid.io.checks import check_saturation

    rng = np.random.default_rng(7)
    w = _counted_settle(rng)
    assert not check_saturation(w, "omega", "x.csv")
    with pytest.warns(PmdcidWarning, match="maximum 7000"):
        assert check_saturation(np.minimum(w, 7000.0), "omega", "x.csv")
    slow = np.round(np.minimum(np.linspace(0, 30, 500), 20.0))  # 1 count per 17 rows, clipped
    with pytest.warns(PmdcidWarning, match="maximum 20"):
        assert check_saturation(slow, "omega", "x.csv")


def test_an_input_glitch_is_held_and_said_where_a_kick_or_a_pulse_is_not(rng):
    """A serial glitch of 100 V in a 0-2 V staircase is held at the value before it (a drive
    holds its command) with a warning naming its row; a 2-sample kick on a log otherwise at 0
    V (an impulse test) and a 10-sample pulse beyond the rest's range are left alone."""
    import warnings

    from pmdcid.errors import PmdcidWarning
    from pmdcid.io import Log

    t = np.arange(3000) * 1e-3
    u = np.where(t < 1.0, 0.0, np.where(t < 2.0, 1.0, 2.0))
    glitch = u.copy()
    glitch[1500] = 100.0
    with pytest.warns(PmdcidWarning, match=r"'v': 1 isolated glitch.*100 at data row 1501"):
        log = Log.from_arrays(t, v=glitch, omega=rng.normal(0, 0.01, t.size), name="g.csv")
    assert np.array_equal(log.u, u)
    kick = np.zeros_like(t)
    kick[100:102] = 12.0
    pulse = u.copy()
    pulse[2500:2510] = 40.0
    for x in (kick, pulse):
        with warnings.catch_warnings():
            warnings.simplefilter("error", PmdcidWarning)
            log = Log.from_arrays(t, v=x, omega=rng.normal(0, 0.01, t.size), name="k.csv")
        assert np.array_equal(log.u, x)
