"""``pmdcid simulate INPUT -m MODEL -o OUT.csv``."""

from __future__ import annotations

import click

from pmdcid.cli import main
from pmdcid.cli.options import FiniteFloat, log_options, model_option, parse_x0


@main.command("simulate")
@click.argument("input_log", metavar="INPUT", type=click.Path(dir_okay=False))
@model_option()
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), metavar="OUT.csv")
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
def simulate_cmd(input_log, model_path, output, noise_i, noise_omega, encoder, seed, blocked,
                 force, x0, mapping):
    """Predict what the sensors read for INPUT's t and v (or tau), from rest unless --x0."""
    from pmdcid.synth import NoiseSpec, simulate_file

    path = simulate_file(input_log, model_path, output, mapping=mapping,
                         noise=NoiseSpec(noise_i, noise_omega, encoder), seed=seed,
                         blocked=blocked, force=force, x0=x0)
    click.echo(f"wrote {path}")

