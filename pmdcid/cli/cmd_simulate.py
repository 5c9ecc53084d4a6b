"""``pmdcid simulate INPUT -m MODEL -o OUT.csv`` (or ``INPUT... -m MODEL -o DIR``)."""

from __future__ import annotations

import click

from pmdcid.cli import echo, main
from pmdcid.cli.options import (
    INPUT_FILE,
    FiniteFloat,
    controller_option,
    log_options,
    model_option,
    parse_x0,
)


@main.command("simulate")
@click.argument("input_logs", nargs=-1, required=True, metavar="INPUT...",
                type=INPUT_FILE)
@model_option(updated=False)
@click.option("-o", "--output", required=True, type=click.Path(), metavar="OUT.csv|DIR",
              help="The simulated log (one INPUT), or the folder for one log per INPUT, each "
                   "named as its INPUT (several INPUTs; created if missing).")
@click.option("--noise-i", type=FiniteFloat(min=0.0), default=0.0, show_default=True,
              help="Current noise std [A].")
@click.option("--noise-omega", type=FiniteFloat(min=0.0), default=0.0, show_default=True,
              help="Speed noise std [rad/s].")
@click.option("--encoder", type=click.IntRange(min=0), default=0, show_default=True,
              help="Quantise the angle to this many counts per revolution (0: off).")
@click.option("--seed", type=click.IntRange(min=0), default=None,
              help="Seed of the noise generator.")
@click.option("--blocked", is_flag=True,
              help="Rotor blocked (blocked-rotor test): omega = 0. Also when INPUT says "
                   "'# kind: blocked-rotor' (a plan's blocked-rotor profile).")
@click.option("--force", is_flag=True, help="Overwrite OUT.csv if it exists.")
@click.option("--x0", "x0", callback=parse_x0, default=None,
              metavar="measured|omega=VAL,i=VAL,theta=VAL",
              help="Initial state (SI; any subset, the rest 0), or 'measured': INPUT's own "
                   "measured omega, theta, i at its first sample. Default: rest.")
@controller_option("Simulate the closed loop of this controller (JSON file or inline "
                   "type=PI,kp=..; docs/cli.md) from INPUT's reference column: the output's "
                   "input column is the simulated controller's, --noise-omega is fed back.")
@log_options
def simulate_cmd(input_logs, model_path, output, noise_i, noise_omega, encoder, seed, blocked,
                 force, x0, controller, mapping):
    """Predict what the sensors read for INPUT's t and v (or tau), from rest unless --x0."""
    import os

    from pmdcid import api

    if controller is not None:
        echo(f"closed loop: {controller.describe()}")
    if len(input_logs) == 1 and os.path.isdir(output):
        raise click.BadParameter(f"{output!r} is a folder: with one INPUT, -o names the "
                                 "output file", param_hint="'-o' / '--output'")
    names = [os.path.basename(p) for p in input_logs]
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup:
        raise click.BadParameter(f"two INPUTs are named {dup!r}: their outputs in {output!r} "
                                 "would collide; simulate them in separate calls",
                                 param_hint="INPUT...")
    for path in api.simulate_to(list(input_logs), model_path, output, x0=x0, noise_i=noise_i,
                                noise_omega=noise_omega, encoder=encoder, seed=seed,
                                blocked=blocked, controller=controller, mapping=mapping,
                                force=force):
        echo(f"wrote {path}")
