"""``pmdcid identify LOG... -m MODEL [-o DIR] [--no-diagnose] [--km X]``: a whole rig."""

from __future__ import annotations

import click

from pmdcid.cli import echo, main, progress_lines
from pmdcid.cli.options import (
    INPUT_FILE,
    controller_option,
    km_type,
    log_options,
    model_option,
)


@main.command("identify")
@click.argument("logs", nargs=-1, required=True, metavar="LOG...", type=INPUT_FILE)
@model_option()
@click.option("-o", "--output", "out_dir", type=click.Path(), default=None, metavar="DIR",
              help="Write the report (report.html, metrics.json, figures) into DIR.")
@click.option("--no-diagnose", is_flag=True, help="Skip the effect search after the joint fit.")
@click.option("--km", type=km_type(), default=None, metavar="X",
              help="Torque constant [N m/A] (datasheet); default: km from MODEL.")
@click.option("--no-prior", is_flag=True,
              help="Later stages use their own logs alone (default: combined with what the "
                   "earlier stages determined).")
@click.option("--force", is_flag=True,
              help="Write the model even when the plausibility checks refuse the logs' units, "
                   "and replace a report file in DIR that pmdcid did not write.")
@controller_option("Closed-loop logs: the controller that ran them (see fit-nonlinear); the "
                   "rich logs' fits simulate the loop from the logged reference.")
@log_options
def identify_cmd(logs, model_path, out_dir, no_diagnose, km, no_prior, force, controller,
                 mapping):
    """A whole rig: sort the logs, run every stage that applies, a joint fit, diagnose, and
    the report into DIR."""
    from pmdcid import api
    from pmdcid.cli.notes import echo_notes

    res = api.identify(list(logs), model_path, km=km, diagnose=not no_diagnose,
                       priors=not no_prior, progress=progress_lines(), controller=controller,
                       mapping=mapping, update=True, out_dir=out_dir, force=force)

    echo(res.table())
    echo_notes(res.all_notes(), in_table=("identify", "diagnose"))
    echo(f"updated {model_path}")
    if res.report_dir:
        echo(f"wrote {res.report_dir}/report.html")
