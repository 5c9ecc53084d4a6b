"""``pmdcid demo [-o DIR]``."""

from __future__ import annotations

import click

from pmdcid.cli import echo, main


@main.command("demo")
@click.option("-o", "--output", "out_dir", default="demo-output", show_default=True,
              type=click.Path(), metavar="DIR", help="Folder for the models and the report.")
def demo_cmd(out_dir):
    """Run the whole pipeline on the bundled example logs and write a report."""
    from pmdcid import api

    api.run_demo(out_dir, echo=echo)
