"""``pmdcid export -m MODEL --to FORMAT -o FILE``."""

from __future__ import annotations

import click

from pmdcid.cli import main
from pmdcid.cli.options import model_option

FORMATS = ("python-control", "c", "matlab")  # as pmdcid.export.FORMATS (not imported: fast --help)


@main.command("export")
@model_option(updated=False)
@click.option("--to", "fmt", required=True, type=click.Choice(FORMATS), help="Output format.")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), metavar="FILE",
              help="File to write (c: FILE.c, header FILE.h beside it; matlab: FILE.m, "
                   "script run_FILE.m beside it).")
@click.option("--force", is_flag=True,
              help="Overwrite FILE (and its companion) even if pmdcid export did not write it.")
def export_cmd(model_path, fmt, output, force):
    """Write code that steps MODEL exactly as `pmdcid simulate` does (python-control, C, MATLAB)."""
    from pmdcid.export import export_model

    for path in export_model(model_path, fmt, output, force=force):
        click.echo(f"wrote {path}")
