"""Text table of a diagnose run: candidates, evidence, chosen effects, errors before and after."""

from __future__ import annotations

import math
import os

from pmdcid.model.tables import in_words


def _f(x, fmt: str = ".4g") -> str:
    return "-" if x is None or not math.isfinite(x) else format(x, fmt)


def _short(path: str, width: int = 28) -> str:
    name = os.path.basename(path) or path
    return name if len(name) <= width else "..." + name[-(width - 3):]


def _added_lines(res) -> list[str]:
    """Each added effect with its parameters; then what the logs only bound, in words."""
    from pmdcid.model import EFFECTS

    lines = []
    for e in res.summary["added"]:
        pars = []
        for p in EFFECTS[e].param_names:
            par = res.model.parameters.get(p)
            if par is not None and par.interval is None:
                pars.append(_with_error(p, par))
        lines.append(f"  {e}: " + "; ".join(pars))
    for name, par in res.model.parameters.items():
        if par.interval is not None:
            lines.append(f"{name}: {in_words(par.interval, par.unit, par.caveat)}")
    return lines


def _with_error(name: str, par) -> str:
    """``name = value ± stderr unit``; without a standard error, what stands in its place in
    words (the parameter's caveat), never a bare value that reads as exact."""
    if math.isfinite(par.stderr):
        return f"{name} = {par.value:.5g} ± {par.stderr:.2g} {par.unit}".rstrip()
    why = par.caveat or "no standard error"
    return f"{name} = {par.value:.5g} {par.unit}".rstrip() + f" ({why})"


def format_table(res) -> str:
    """Candidates (screen gain, ΔBIC, held-out check), chosen effects, per-log NRMSE."""
    lines = ["diagnose: candidate effects (ΔBIC < -10 and a held-out gain needed to add one)", ""]
    lines.append(f"{'effect':<20} {'round':>5} {'screen Δχ²':>12} {'ΔBIC':>12} "
                 f"{'held-out':>10} {'omega NRMSE':>12}  chosen")
    for c in res.candidates:
        lines.append(f"{c.effect:<20} {c.round:>5} {_f(c.screen_gain, '.4g'):>12} "
                     f"{_f(c.delta_bic, '.1f'):>12} {_f(c.heldout, '.1f'):>10} "
                     f"{_f(c.omega_nrmse):>12}  {'yes' if c.chosen else ''}")
        if c.reason:
            lines.append(f"{'':<20}   {c.reason}")
    s = res.summary
    lines.append("")
    lines.append("added: " + (", ".join(s["added"]) if s["added"] else "nothing"))
    lines += _added_lines(res)
    for u in s.get("untestable", []):
        lines.append(f"possible, not testable with these logs: {u['effect']} (record "
                     f"{u['record']})")
    for note in s.get("notes", []):
        lines.append(f"note: {note}")
    for warning in s.get("warnings", []):
        lines.append(f"warning: {warning}")
    for f in s.get("repeatability", []):
        lines.append(f"repeatability floor of {f['protocol']} ({len(f['logs'])} runs): speed "
                     f"NRMSE {_f(f['floor'])} (each run against the mean of the others)")
    if s["unexplained"]:
        lines.append("unexplained: the residual still has structure no catalogue effect explains")
        for sh in s.get("residual_shape", []):
            lines.append(f"  residual shape: {sh['description']}")
    lines.append("")
    lines.append("NRMSE before -> after (RMS error / std of the measurement)")
    lines.append(f"{'log':<28} {'i':>17} {'omega':>17} {'theta':>17}")
    for path, b, a in zip(res.paths, res.before, res.after, strict=True):
        cells = [f"{_f(b.get(sig))} -> {_f(a.get(sig))}" if sig in b else "-"
                 for sig in ("i", "omega", "theta")]
        lines.append(f"{_short(path):<28} " + " ".join(f"{c:>17}" for c in cells))
    pb, pa = s["before"], s["after"]
    cells = [f"{_f(pb.get(f'{sig}_nrmse'))} -> {_f(pa.get(f'{sig}_nrmse'))}"
             for sig in ("i", "omega", "theta")]
    lines.append(f"{'mean':<28} " + " ".join(f"{c:>17}" for c in cells))
    if s.get("heldout"):
        lines.append("")
        lines.append("logs held out whole (base and effects refitted without them): omega NRMSE")
        for h in s["heldout"]:
            lines.append(f"{_short(h['log']):<28} {_f(h['before'].get('omega'))} -> "
                         f"{_f(h['after'].get('omega'))}")
    return "\n".join(lines)
