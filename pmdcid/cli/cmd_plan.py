"""``pmdcid plan (-m MODEL | --guess) [...] -o DIR`` and ``pmdcid plan --check LOG... -m MODEL``."""

from __future__ import annotations

import math
import sys

import click

from pmdcid.api import MAX_PLAN_SAMPLES
from pmdcid.cli import echo, main
from pmdcid.cli.options import INPUT_FILE, FiniteFloat, log_options


@main.command("plan")
@click.argument("logs", nargs=-1, metavar="[LOG...]", type=INPUT_FILE)
@click.option("-m", "--model", "model_path", type=INPUT_FILE, metavar="MODEL",
              help="Model file (JSON) the plan is designed for (read only).")
@click.option("--guess", is_flag=True,
              help="No model yet: a short, safe first experiment (small steps, a slow ramp).")
@click.option("--check", is_flag=True,
              help="Check LOGs you already have: which parameters they leave poorly "
                   "determined (> 25 %) and which profile would fix it.")
@click.option("--vmax", type=FiniteFloat(min=0.0, min_open=True), default=None, metavar="V",
              help="Largest voltage the rig may apply [V] (default with -m: 3x the breakaway).")
@click.option("--taumax", type=FiniteFloat(min=0.0, min_open=True), default=None, metavar="T",
              help="Largest torque for a torque-driven rig [N m] (instead of --vmax).")
@click.option("--speed-max", type=FiniteFloat(min=0.0, min_open=True), default=None,
              metavar="W", help="Largest speed the predicted motion may reach [rad/s].")
@click.option("--rate", type=FiniteFloat(min=0.0, min_open=True), default=1000.0,
              show_default=True, metavar="HZ", help="Sampling (and input hold) rate [Hz].")
@click.option("--budget", type=FiniteFloat(min=0.0, min_open=True), default=120.0,
              show_default=True, metavar="S", help="Total recording time [s].")
@click.option("--noise-omega", type=FiniteFloat(min=0.0, min_open=True), default=None,
              metavar="W", help="Speed noise std [rad/s] (default 1 % of the top speed).")
@click.option("--noise-i", type=FiniteFloat(min=0.0, min_open=True), default=None,
              metavar="A", help="Current noise std [A] (default 1 % of the top current).")
@click.option("-o", "--output", "out_dir", type=click.Path(), default=None, metavar="DIR",
              help="Folder for the profiles, plan.json and plan.md (with --check: check.json).")
@click.option("--force", is_flag=True,
              help="Replace a file in DIR that pmdcid plan did not write (a profile's name, "
                   "plan.json, plan.md, check.json).")
@log_options
def plan_cmd(logs, model_path, guess, check, vmax, taumax, speed_max, rate, budget, noise_omega,
             noise_i, out_dir, force, mapping):
    """Input profiles to record, and the standard error each parameter will have."""
    from pathlib import Path

    from pmdcid import api

    if vmax is not None and taumax is not None:
        raise click.UsageError("give --vmax or --taumax, not both")
    if guess and (model_path or check):
        raise click.UsageError("--guess plans without a model: drop -m / --check")
    if not guess and not model_path:
        raise click.UsageError("give -m MODEL, or --guess for a first experiment without one")
    if logs and not check:
        raise click.UsageError("LOG arguments go with --check")
    if check and not logs:
        raise click.UsageError("--check needs the LOGs to check")
    if not check and not out_dir:
        raise click.UsageError("give -o DIR for the profiles and plan.json")
    if guess and vmax is None and taumax is None:
        raise click.UsageError("--guess needs --vmax (or --taumax): the largest input your rig "
                               "may take")
    if budget * rate > MAX_PLAN_SAMPLES:
        raise click.UsageError(f"--budget {budget:g} s at --rate {rate:g} Hz is "
                               f"{budget * rate:.3g} samples per profile set: at most "
                               f"{MAX_PLAN_SAMPLES:.0e} (a shorter --budget or a lower --rate)")
    options = dict(vmax=vmax, taumax=taumax, speed_max=speed_max, rate=rate, budget=budget,
                   noise_omega=noise_omega, noise_i=noise_i)
    if check:
        res = api.check_plan(logs, model_path, out_dir, mapping=mapping, force=force, **options)
        for line in res.lines():
            echo(line)
        if out_dir:
            echo(f"wrote {Path(out_dir) / 'check.json'}")
        return
    plan = api.plan(None if guess else model_path, out_dir, **options,
                    command="pmdcid plan " + " ".join(sys.argv[2:]), force=force)
    echo(f"wrote {len(plan.profiles)} profiles ({plan.seconds:.1f} s) and plan.json, "
               f"plan.md into {out_dir}")
    for note in plan.notes:
        echo(f"note: {note}", err=True)
    for n in plan.names:
        se = plan.stderr[n]
        rel = plan.relative()[n]
        echo(f"  {n:<8} {plan.values[n]:12.5g} ± {se:.3g}"
                   f"{f'  ({100 * rel:.2g} %)' if math.isfinite(rel) else ''}")

