"""Rows: fit-nonlinear (and its scaling), diagnose, the demo end to end, start-up, memory."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench.table import ROOT, Row, na
from bench.timing import Stats, collect, measure

FIX = ROOT / "fixtures"
HEAVY = ("numpy", "pandas", "scipy", "numba", "matplotlib")


def _fail(what: str, exc: BaseException, target: str = "") -> Row:
    msg = str(exc).strip().splitlines()[0][:90] if str(exc).strip() else ""
    return na(what, f"failed: {type(exc).__name__}: {msg}", target)


def _b1(seconds: float, b1: Stats) -> str:
    return f"{seconds / b1.median:.2g} B1"


def mechanical_model(truth: dict[str, float]):
    """The model fit-nonlinear starts from: R, L, km, J and the lumped b of the earlier stages."""
    from pmdcid.synth import truth_model

    m = truth_model({k: truth[k] for k in ("R", "L", "km", "J")})
    m.set("b", truth["bv"], stage="fit-mechanical")
    return m


def _import_fit():
    try:
        from pmdcid.identify.nonlinear import fit_nonlinear
    except ImportError:
        return None
    return fit_nonlinear


def _nfev(res) -> str:
    try:
        return f"{res.stats.nfev} least-squares evaluations"
    except Exception:  # noqa: BLE001 - informational only
        return ""


def _fit_quality(res, truth: dict[str, float]) -> str:
    try:
        errs = [f"{k} {100 * (res.estimates[k].value / truth[k] - 1):+.1f}%"
                for k in ("bc", "bv", "dz") if k in res.estimates]
        return "; ".join(filter(None, [_nfev(res), "error vs truth: " + ", ".join(errs)]))
    except Exception:  # noqa: BLE001 - informational only
        return ""


def fit_rows(b1: Stats, quick: bool, tmp: Path) -> list[Row]:
    """fit-nonlinear on the 120 s triangle fixture, then on 4x and 16x longer triangles."""
    from pmdcid.io import read_log
    from pmdcid.synth import PAPER

    what = "fit-nonlinear: 120 s triangle fixture"
    fit = _import_fit()
    if fit is None:
        return [na(what, target="<= 2 s"), na("scaling: fit-nonlinear at 4x, 16x")]
    model = mechanical_model(PAPER)
    logs = [read_log(FIX / "paper" / "triangle.csv")]
    out: list = []
    try:
        s1 = measure(lambda: out.append(fit(logs, model.copy())), repeat=3 if quick else 5,
                     budget_s=10.0 if quick else 20.0, warmup=1)
    except Exception as exc:  # noqa: BLE001 - a colleague's module may be in progress
        return [_fail(what, exc, "<= 2 s")]
    rows = [Row(what, s1, "s", _b1(s1.median, b1), "<= 2 s", s1.median <= 2.0,
                _fit_quality(out[-1], PAPER))]
    for factor in (4, 16):
        if quick and factor == 16:
            break
        log = read_log(_long_triangle(tmp, factor))
        got: list = []
        try:
            s = measure(lambda log=log, got=got: got.append(fit([log], model.copy())),
                        repeat=3 if factor == 4 else 1, budget_s=20.0, warmup=0)
        except Exception as exc:  # noqa: BLE001
            rows.append(_fail(f"scaling: fit-nonlinear at {factor}x", exc))
            continue
        rows.append(Row(f"scaling: fit-nonlinear at {factor}x ({120 * factor} s)", s, "s",
                        f"{s.median / s1.median:.1f}x the 1x time (linear: {factor}x)",
                        note=_nfev(got[-1])))
    return rows


def _long_triangle(tmp: Path, factor: int) -> Path:
    """A noisy triangle log ``factor`` times the fixture's length (same model, noise, rate)."""
    import numpy as np

    from pmdcid.io import write_log
    from pmdcid.simulate import neutral_values
    from pmdcid.synth import PAPER, PAPER_NOISE, synth_log, triangle

    path = tmp / f"triangle_{factor}x.csv"
    if not path.exists():
        t = np.arange(120000 * factor) / 1000.0
        u = triangle(t, 2.0, 40.0)
        cols, _ = synth_log(t, u, {**neutral_values(), **PAPER}, PAPER_NOISE,
                            np.random.default_rng(8000 + factor))
        write_log(path, t, cols, {"generator": "pmdcid", "kind": "triangle"})
    return path


def diagnose_rows(b1: Stats, quick: bool) -> list[Row]:
    """diagnose with every catalogue effect a candidate, on the hidden set's free-running logs,
    from the paper's model (the hidden set carries an undeclared Stribeck effect)."""
    import json

    from pmdcid.io import read_log
    from pmdcid.synth import truth_model

    what = "diagnose: whole catalogue, hidden steps + triangle"
    try:
        from pmdcid.diagnose import diagnose
    except ImportError:
        return [na(what, target="<= 20 s")]
    truth = json.loads((FIX / "hidden" / "truth.json").read_text())["parameters"]
    model = truth_model({k: v for k, v in truth.items() if k not in ("fs", "ws")})
    logs = [read_log(p) for p in sorted((FIX / "hidden").glob("step_*.csv"))]
    logs.append(read_log(FIX / "hidden" / "triangle.csv"))
    out: list = []
    try:
        s = measure(lambda: out.append(diagnose(logs, model.copy())), repeat=3,
                    budget_s=15.0 if quick else 45.0, warmup=0)
    except Exception as exc:  # noqa: BLE001
        return [_fail(what, exc, "<= 20 s")]
    try:
        note = f"added {out[-1].summary.get('added')}"
    except Exception:  # noqa: BLE001
        note = ""
    return [Row(what, s, "s", _b1(s.median, b1), "<= 6 s (#16; #8: 20 s)", s.median <= 6.0,
                note)]


def pmdcid_cmd() -> list[str]:
    exe = Path(sys.executable).parent / "pmdcid"
    if exe.exists():
        return [str(exe)]
    found = shutil.which("pmdcid")
    return [found] if found else [sys.executable, "-c", "from pmdcid.cli import main; main()"]


def run_child(cmd: list[str], timeout: float = 600.0, cwd: str | None = None):
    """Run ``cmd``; return (seconds, peak RSS [bytes], exit code, stderr, CPU seconds) of that
    child alone (rusage from ``os.wait4``; peak RSS from /proc VmHWM polled while it runs)."""
    err = tempfile.TemporaryFile()
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err, cwd=cwd)
    deadline = t0 + timeout
    hwm = 0
    while True:
        hwm = max(hwm, _vm_hwm(proc.pid))
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            break
        if time.perf_counter() > deadline:
            proc.kill()
            pid, status, usage = os.wait4(proc.pid, 0)
            break
        time.sleep(0.002)
    seconds = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    err.seek(0)
    text = err.read().decode(errors="replace")
    rss = usage.ru_maxrss * (1 if sys.platform == "darwin" else 1024)
    if hwm:
        # Linux carries the parent's RSS at fork into the child's ru_maxrss (kept across exec):
        # the child's own high-water mark (VmHWM, read while it runs) is the true figure
        rss = hwm
    return seconds, rss, proc.returncode, text, usage.ru_utime + usage.ru_stime


def _vm_hwm(pid: int) -> int:
    """Peak resident set [bytes] of a running process (Linux /proc VmHWM), 0 if unknown."""
    try:
        with open(f"/proc/{pid}/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 0


def demo_rows(b1: Stats, quick: bool, tmp: Path) -> list[Row]:
    """``pmdcid demo`` as a user runs it (subprocess), its wall time and its peak memory."""
    what = "demo: `pmdcid demo` end to end"
    times, rss = Stats(), Stats()
    for k in range(2 if quick else 3):
        sec, mem, code, err, cpu = run_child(pmdcid_cmd() + ["demo", "-o", str(tmp / f"demo{k}")],
                                        timeout=300.0)
        if code != 0:
            if "No such command" in err:
                return [na(what, target="<= 30 s"), na("demo: peak memory (RSS)")]
            line = (err.strip().splitlines() or [""])[-1][:100]
            return [na(what, f"failed: exit {code}: {line}", "<= 30 s")]
        times.values.append(sec)
        times.cpu.append(cpu)
        rss.values.append(mem / 2**20)
        if sec > 60.0:
            break
    b3 = collect(lambda: run_child([sys.executable, "-c", "import " + ", ".join(HEAVY)])[1]
                 / 2**20, repeat=3)
    return [Row(what, times, "s", _b1(times.median, b1), "<= 30 s", times.median <= 30.0,
                "subprocess, every run counted; numba cache already warm"),
            Row("demo: peak memory (RSS)", rss, "MB", f"{rss.median / b3.median:.1f}x B3"),
            Row("B3 baseline: python importing " + "+".join(HEAVY), b3, "MB", "B3")]


def startup_rows(quick: bool) -> list[Row]:
    """``pmdcid --help`` wall time against a bare interpreter, and which heavy modules load."""
    n = 5 if quick else 15
    run_child(pmdcid_cmd() + ["--help"])  # warm the file cache
    hs = collect(lambda: run_child(pmdcid_cmd() + ["--help"])[::4], repeat=n)
    b2 = collect(lambda: run_child([sys.executable, "-c", "pass"])[::4], repeat=n)
    heavy = heavy_imports()
    return [Row("start-up: `pmdcid --help`", hs, "s", f"{hs.median / b2.median:.1f}x B2",
                "<= 0.15 s", hs.median <= 0.15,
                "heavy imports at start-up: " + (heavy or "none")),
            Row("B2 baseline: `python -c pass`", b2, "s", "B2")]


_PROBE = r"""
import sys, traceback
HEAVY = %r
seen = {}
class Spy:
    def find_spec(self, name, path=None, target=None):
        top = name.split('.')[0]
        if top in HEAVY and top not in seen:
            mods = [f.filename for f in traceback.extract_stack()
                    if '/pmdcid/' in f.filename.replace('\\', '/')]
            seen[top] = mods[-1].split('pmdcid/', 1)[-1] if mods else '?'
        return None
sys.meta_path.insert(0, Spy())
import pmdcid.cli
print('; '.join(f'{k} (via {v})' for k, v in sorted(seen.items())))
"""


def heavy_imports() -> str:
    """Heavy modules imported by ``import pmdcid.cli``, each with the pmdcid file that did it."""
    out = subprocess.run([sys.executable, "-c", _PROBE % (HEAVY,)], capture_output=True,
                         text=True, timeout=120, cwd=str(ROOT))
    if out.returncode != 0:
        return "probe failed: " + (out.stderr.strip().splitlines() or [""])[-1][:100]
    return out.stdout.strip()
