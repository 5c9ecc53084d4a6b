"""A new user's first command on each real log alone: ``pmdcid identify FILE`` then ``pmdcid
simulate FILE --x0 measured`` with the model it wrote.

    python bench/single_files.py [--every 3] [--jobs 2] [--mem-gb 8] [--rig NAME[,NAME]]

Reads ../shared/data/real (every rig's folder) and EMPS's estimation file, never copied here.
``--every K`` takes every K-th file of a rig's sorted list (all of a rig with fewer than 12).
Each command runs in its own process with an address-space limit of ``--mem-gb`` (a command
that needs more is reported, not left to the machine's OOM killer) and a timeout. Flagged per
file: an exit status outside 0 and 1, a traceback or "internal error", a hang, a killed
process, or a model that ``simulate`` refuses; exit 1 (a refusal with one ``error:`` line) is
listed with its line. Not a test: nothing here asserts (session 35, docs/identification.md).
"""

from __future__ import annotations

import argparse
import resource
import shutil
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"
EMPS = (SHARED / "emps" / "emps_train_DATA_EMPS.csv",
        ["-c", "t=t_s", "-c", "tau=force_N", "-c", "theta=qm_meas_m"])
CODE = "import sys; from pmdcid.cli import main; sys.argv=['pmdcid']+sys.argv[1:]; main()"


def files(every: int, only: set[str] | None) -> list[tuple[Path, list[str]]]:
    """(log, its mapping) of each rig's every ``every``-th file, and EMPS's estimation file."""
    out = []
    for rig in sorted(p for p in (SHARED / "real").iterdir() if p.is_dir()):
        if only and rig.name not in only:
            continue
        logs = sorted(rig.glob("*.csv"))
        out += [(f, []) for f in (logs if len(logs) < 12 else logs[::every])]
    if (not only or "EMPS" in only) and EMPS[0].exists():
        out.append(EMPS)
    return out


def _run(args: list[str], cwd: Path, mem_gb: float, timeout: float):
    limit = int(mem_gb * 2**30)

    def cap():
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))

    return subprocess.run([sys.executable, "-c", CODE, *args], cwd=cwd, capture_output=True,
                          text=True, timeout=timeout, preexec_fn=cap)


def one(item, mem_gb: float, timeout: float) -> str:
    """One file's row: its rig and name, then what identify and simulate did."""
    log, mapping = item
    name = f"{log.parent.name}/{log.name}"
    work = Path(tempfile.mkdtemp(prefix="single-"))
    try:
        try:
            ident = _run(["identify", str(log), *mapping, "-m", "m.json"], work, mem_gb, timeout)
        except subprocess.TimeoutExpired:
            return f"FLAG {name}: identify did not answer in {timeout:g} s"
        err = [ln for ln in ident.stderr.splitlines() if ln.startswith("error")]
        bad = (ident.returncode not in (0, 1) or "Traceback" in ident.stderr
               or "internal error" in ident.stderr)
        row = f"{'FLAG ' if bad else ''}{name}: identify exit {ident.returncode}"
        if err:
            row += f" ({err[-1][:200]})"
        if ident.returncode == 0:
            sim = _run(["simulate", str(log), *mapping, "-m", "m.json", "--x0", "measured",
                        "-o", "sim.csv"], work, mem_gb, timeout)
            if sim.returncode != 0:
                last = (sim.stderr.strip().splitlines() or [""])[-1]
                row = f"FLAG {row}; simulate exit {sim.returncode} ({last[:200]})"
        return row
    finally:
        shutil.rmtree(work, ignore_errors=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--every", type=int, default=3, help="every K-th file of a rig")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--mem-gb", type=float, default=8.0)
    ap.add_argument("--timeout", type=float, default=600.0)
    ap.add_argument("--rig", help="only these rigs (comma-separated folder names, or EMPS)")
    a = ap.parse_args()
    todo = files(a.every, set(a.rig.split(",")) if a.rig else None)
    flagged = 0
    with ThreadPoolExecutor(a.jobs) as ex:
        for row in ex.map(lambda it: one(it, a.mem_gb, a.timeout), todo):
            flagged += row.startswith("FLAG")
            print(row, flush=True)
    print(f"\n{flagged} flagged of {len(todo)} files")


if __name__ == "__main__":
    main()
