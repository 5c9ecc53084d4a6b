"""``pmdcid simulate INPUT -m MODEL -o OUT.csv`` (or ``INPUT... -m MODEL -o DIR``)."""

from __future__ import annotations

import click

from pmdcid.cli import main
from pmdcid.cli.options import FiniteFloat, log_options, model_option, parse_x0


@main.command("simulate")
@click.argument("input_logs", nargs=-1, required=True, metavar="INPUT...",
                type=click.Path(dir_okay=False))
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
@click.option("--blocked", is_flag=True, help="Rotor blocked (blocked-rotor test): omega = 0.")
@click.option("--force", is_flag=True, help="Overwrite OUT.csv if it exists.")
@click.option("--x0", "x0", callback=parse_x0, default=None,
              metavar="measured|omega=VAL,i=VAL,theta=VAL",
              help="Initial state (SI; any subset, the rest 0), or 'measured': INPUT's own "
                   "measured omega, theta, i at its first sample. Default: rest.")
@log_options
def simulate_cmd(input_logs, model_path, output, noise_i, noise_omega, encoder, seed, blocked,
                 force, x0, mapping):
    """Predict what the sensors read for INPUT's t and v (or tau), from rest unless --x0."""
    import os

    from pmdcid.synth import NoiseSpec, simulate_file, simulate_files

    opts = dict(mapping=mapping, noise=NoiseSpec(noise_i, noise_omega, encoder), seed=seed,
                blocked=blocked, force=force, x0=x0)
    if len(input_logs) == 1:
        if os.path.isdir(output):
            raise click.BadParameter(f"{output!r} is a folder: with one INPUT, -o names the "
                                     "output file", param_hint="'-o' / '--output'")
        click.echo(f"wrote {simulate_file(input_logs[0], model_path, output, **opts)}")
        return
    names = [os.path.basename(p) for p in input_logs]
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup:
        raise click.BadParameter(f"two INPUTs are named {dup!r}: their outputs in {output} "
                                 "would collide; simulate them in separate calls",
                                 param_hint="INPUT...")
    simulate_files(list(input_logs), model_path, output, echo=click.echo, **opts)
