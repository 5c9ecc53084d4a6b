"""``pmdcid export -m MODEL --to FORMAT -o FILE``."""

from __future__ import annotations

import click

from pmdcid.cli import echo, main
from pmdcid.cli.options import model_option

#: as pmdcid.export.FORMATS (not imported: fast --help)
FORMATS = ("python-control", "c", "matlab", "mujoco", "fmu")


@main.command("export")
@model_option(updated=False)
@click.option("--to", "fmt", required=True, type=click.Choice(FORMATS), help="Output format.")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), metavar="FILE",
              help="File to write (c: FILE.c, header FILE.h beside it; matlab: FILE.m, "
                   "script run_FILE.m beside it; mujoco: an MJCF model FILE.xml; fmu: an FMI 2.0 "
                   "co-simulation FMU FILE.fmu).")
@click.option("--force", is_flag=True,
              help="Overwrite FILE (and its companion) even if pmdcid export did not write it.")
def export_cmd(model_path, fmt, output, force):
    """Write code that steps MODEL exactly as `pmdcid simulate` does (python-control, C, MATLAB,
    an FMI 2.0 FMU), or a MuJoCo model carrying its parameters (what MuJoCo cannot represent is
    approximated and said)."""
    from pmdcid import api

    for path in api.export(model_path, fmt, output, force=force, note=echo):
        echo(f"wrote {path}")
