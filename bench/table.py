"""Rows of the benchmark table, their formatting, and the machine the figures came from."""

from __future__ import annotations

import math
import os
import platform
import re
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

from bench.timing import Stats

ROOT = Path(__file__).resolve().parents[1]
BEGIN, END = "<!-- bench:begin -->", "<!-- bench:end -->"


@dataclass
class Row:
    """One line of the table. ``stats`` in ``unit`` (None when not measured); ``ok`` against
    the target (None when there is no target or nothing was measured)."""

    what: str
    stats: Stats | None = None
    unit: str = "s"
    ratio: str = ""
    target: str = ""
    ok: bool | None = None
    note: str = ""


def na(what: str, note: str = "n/a (not built yet)", target: str = "") -> Row:
    return Row(what, None, target=target, note=note)


def fmt_value(x: float, unit: str) -> str:
    if not math.isfinite(x):
        return "nan"
    if unit == "s":  # pick a readable unit
        for scale, name in ((1.0, "s"), (1e-3, "ms"), (1e-6, "us")):
            if abs(x) >= scale or name == "us":
                return f"{x / scale:.3g} {name}"
    return f"{x:.3g} {unit}".rstrip()


def fmt_stats(s: Stats | None, unit: str) -> tuple[str, str]:
    """(median, "min .. max (n)") as text."""
    if s is None or s.n == 0:
        return "", ""
    if s.n == 1:
        return fmt_value(s.median, unit), "(1 run)"
    return fmt_value(s.median, unit), (f"{fmt_value(s.min, unit)} .. {fmt_value(s.max, unit)}"
                                       f" ({s.n} runs)")


def status(ok: bool | None) -> str:
    return {True: "ok", False: "**missed**", None: ""}[ok]


def markdown(rows: list[Row]) -> str:
    head = ("| figure | median | min .. max | CPU (median) | vs baseline | target | | note |\n"
            "|---|---|---|---|---|---|---|---|")
    lines = [head]
    for r in rows:
        med, rng = fmt_stats(r.stats, r.unit)
        cpu = fmt_value(r.stats.cpu_median, r.unit) if r.stats is not None and r.stats.cpu else ""
        cells = [r.what, med, rng, cpu, r.ratio, r.target, status(r.ok), r.note]
        lines.append("| " + " | ".join(c.replace("|", "/") for c in cells) + " |")
    return "\n".join(lines)


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def _version(mod: str) -> str:
    try:
        return __import__(mod).__version__
    except Exception:  # noqa: BLE001 - informational only
        return "?"


def _git_head() -> str:
    try:
        out = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                             capture_output=True, text=True, timeout=10)
        dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "--", "pmdcid"],
                               capture_output=True, text=True, timeout=10).stdout.strip()
        return out.stdout.strip() + (" (+ uncommitted changes in pmdcid/)" if dirty else "")
    except Exception:  # noqa: BLE001
        return "?"


def machine() -> str:
    """One paragraph naming the machine and software the figures came from."""
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:
        usable = os.cpu_count()
    return (f"Measured {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} on "
            f"{usable} usable CPU(s) (nproc; {os.cpu_count()} online), CPU "
            f"`{_cpu_model()}`, {platform.system()} {platform.machine()}; Python "
            f"{platform.python_version()}, numba {_version('numba')}, numpy "
            f"{_version('numpy')}, scipy {_version('scipy')}; pmdcid at commit {_git_head()}.")


def write_docs(path: Path, text: str) -> None:
    """Replace what stands between the bench markers of ``path`` (append them if missing)."""
    block = f"{BEGIN}\n{text.rstrip()}\n{END}"
    old = path.read_text() if path.exists() else "# Performance\n"
    if BEGIN in old and END in old:
        new = re.sub(re.escape(BEGIN) + ".*?" + re.escape(END), lambda _m: block, old,
                     flags=re.S)
    else:
        new = old.rstrip() + "\n\n" + block + "\n"
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(new)
    os.replace(tmp, path)
