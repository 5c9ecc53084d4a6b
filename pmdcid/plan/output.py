"""Write a plan: one CSV per profile, DIR/plan.json and DIR/plan.md."""

from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path

from pmdcid.errors import LogError
from pmdcid.io.kinds import canonical
from pmdcid.io.logs import write_log
from pmdcid.model.effects import unit_of
from pmdcid.plan.design import Plan
from pmdcid.runtime.outputs import atomic_write_text, check_folder_outputs, json_object, starts_with

GENERATOR = "pmdcid plan"
#: a profile's file name (``NN_KIND.csv``): what a plan may write besides plan.json and plan.md
PROFILE_NAME = re.compile(r"\d\d_\w+\.csv")


def _num(x: float):
    return float(x) if math.isfinite(x) else None


def plan_json(plan: Plan) -> dict:
    """The contract's plan.json: profiles (file, purpose, seconds) and predicted stderr."""
    out = {
        "profiles": [{"file": f"{p.name}.csv", "purpose": p.purpose,
                      "seconds": round(p.seconds, 6), "kind": canonical(p.kind),
                      "units": round(p.units, 3),
                      "blocked_rotor": p.blocked} for p in plan.profiles],
        "predicted_stderr": {n: _num(plan.stderr[n]) for n in plan.names},
        "values": {n: plan.values[n] for n in plan.names},
        "relative_stderr": {n: _num(r) for n, r in plan.relative().items()},
        "units": {n: unit_of(n) for n in plan.names},
        "noise": plan.noise,
        "input": {"column": plan.drive.column, "limit": plan.umax,
                  "limit_default": plan.umax_default,
                  "speed_max": _num(plan.speed_max)},
        "effects": [{**r, "size": _num(r["size"]), "stderr": _num(r["stderr"])}
                    for r in plan.effects],
        "guess": plan.guess,
        "notes": plan.notes,
    }
    return out


def _fmt(x: float) -> str:
    return f"{x:.3g}" if math.isfinite(x) else "not determined"


def plan_markdown(plan: Plan, command: str = "") -> str:
    """DIR/plan.md: what each profile is for, its length, the predicted standard errors."""
    unit = "V" if plan.drive.column == "v" else "N m"
    lines = ["# Identification plan", ""]
    if command:
        lines += [f"Made by `{command}`.", ""]
    lim = f"input within ±{plan.umax:.3g} {unit}"
    if plan.umax_default:
        lim += " (default: 3x the breakaway input; give --vmax/--taumax for your rig)"
    if math.isfinite(plan.speed_max):
        lim += f", predicted speed within ±{plan.speed_max:.3g} rad/s"
    lines += [f"Total {plan.seconds:.1f} s of recording, {lim}.", "",
              "| file | seconds | what it is for |", "|---|---:|---|"]
    for p in plan.profiles:
        extra = " **Hold the rotor.**" if p.blocked else ""
        lines.append(f"| `{p.name}.csv` | {p.seconds:.1f} | {p.purpose}{extra} |")
    if plan.names:
        noise = ", ".join(f"{k} {v:.3g} {'rad/s' if k == 'omega' else 'A'}"
                          for k, v in plan.noise.items()
                          if k == "omega" or plan.drive.electrical)
        lines += ["", f"## Predicted standard errors (noise std: {noise})", "",
                  "| parameter | value | predicted stderr | relative |", "|---|---:|---:|---:|"]
        rel = plan.relative()
        for n in plan.names:
            lines.append(f"| {n} [{unit_of(n)}] | {plan.values[n]:.4g} | "
                         f"{_fmt(plan.stderr[n])} | {100 * rel[n]:.2g} % |")
    if plan.effects:
        lines += ["", "## Catalogue effects the model does not have yet", "",
                  "Predicted standard error of each effect's main parameter if it were present "
                  "at the stated small size (diagnose's probe size), fitted jointly with the "
                  "parameters above. An effect is detectable by this plan when its size is "
                  "several standard errors.", "",
                  "| effect | parameter | size | predicted stderr | size / stderr | note |",
                  "|---|---|---:|---:|---:|---|"]
        for r in plan.effects:
            ratio = (r["size"] / r["stderr"] if math.isfinite(r["size"])
                     and math.isfinite(r["stderr"]) and r["stderr"] > 0 else math.nan)
            size = f"{r['size']:.3g} {r['unit']}" if math.isfinite(r["size"]) else ""
            lines.append(f"| {r['effect']} | {r['parameter']} | {size} | "
                         f"{_fmt(r['stderr']) if math.isfinite(r['size']) else ''} | "
                         f"{f'{abs(ratio):.3g}' if math.isfinite(ratio) else ''} | {r['note']} |")
    if plan.notes:
        lines += ["", "## Notes", ""] + [f"- {n}" for n in plan.notes]
    return "\n".join(lines) + "\n"


def _is_plan_json(path: str) -> bool:
    obj = json_object(path)
    return obj is not None and {"profiles", "predicted_stderr"} <= set(obj)


def _is_check_json(path: str) -> bool:
    obj = json_object(path)
    return obj is not None and {"logs", "threshold", "parameters"} <= set(obj)


def _is_plan_md(path: str) -> bool:
    return (starts_with(path, b"# Identification plan\n", 22)
            and starts_with(path, b"\n| file | seconds | what it is for |\n"))


#: what a plan writes under each name (by suffix for the profiles): how it recognises its own
OURS = {"plan.json": _is_plan_json, "check.json": _is_check_json, "plan.md": _is_plan_md,
        ".csv": lambda p: starts_with(p, f"# generator: {GENERATOR}\n".encode(), 400)}


def check_out_dir(folder: str | os.PathLike, names=None, force: bool = False) -> None:
    """Refuse (before any work) an output folder that is a file or lies under one, and a file
    in it that the plan would replace and pmdcid plan did not write (unless ``force``).
    ``names``: the files the command writes (default: a plan's plan.json, plan.md and every
    ``NN_KIND.csv`` in the folder, since the profiles are only known after the work)."""
    p = Path(folder).absolute()
    for q in [p, *p.parents]:
        if q.exists():
            if not q.is_dir():
                raise LogError("is a file, not a folder: choose another -o", str(folder))
            break
    if names is None:
        names = ["plan.json", "plan.md"]
        if p.is_dir():
            names += sorted(f for f in os.listdir(p) if PROFILE_NAME.fullmatch(f))
    check_folder_outputs(folder, names, force, ours=OURS)


def write_plan(plan: Plan, folder: str | os.PathLike, command: str = "",
               force: bool = False) -> list[str]:
    """Write the profiles, plan.json and plan.md into ``folder`` (created); a file there that
    pmdcid plan did not write is refused unless ``force``. Returns the paths."""
    from pmdcid.runtime.outputs import output_folder

    d = Path(folder)
    check_out_dir(d, [f"{p.name}.csv" for p in plan.profiles] + ["plan.json", "plan.md"], force)
    written = []
    with output_folder(d):  # removed again if a write fails
        for p in plan.profiles:
            meta = {"generator": GENERATOR,
                    "kind": "blocked-rotor" if p.blocked else canonical(p.kind),
                    "purpose": p.purpose, "units": f"{p.units:.3g}", **p.meta}
            path = d / f"{p.name}.csv"
            write_log(path, p.t, {plan.drive.column: p.u}, meta)
            written.append(str(path))
        atomic_write_text(d / "plan.json", json.dumps(plan_json(plan), indent=2) + "\n")
        atomic_write_text(d / "plan.md", plan_markdown(plan, command))
    return written + [str(d / "plan.json"), str(d / "plan.md")]


__all__ = ["check_out_dir", "plan_json", "plan_markdown", "write_plan"]
