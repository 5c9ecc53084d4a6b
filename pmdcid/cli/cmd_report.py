"""``pmdcid report LOG... -m MODEL -o DIR``."""

from __future__ import annotations

import click

from pmdcid.cli import echo, main, progress_lines
from pmdcid.cli.options import INPUT_FILE, log_options, model_option


@main.command("report")
@click.argument("logs", nargs=-1, required=True, metavar="LOG...", type=INPUT_FILE)
@model_option(updated=False)
@click.option("-o", "--output", "out_dir", required=True, type=click.Path(), metavar="DIR",
              help="Folder for report.html, metrics.json and the figures (created).")
@click.option("--summary", "summary_path", type=INPUT_FILE, default=None,
              metavar="SUMMARY.json", help="A diagnose summary to show on the page.")
@click.option("--before", "before_path", type=INPUT_FILE, default=None,
              metavar="MODEL", help="Model to show as 'before' (default: MODEL without its "
                                    "effects, when it has any).")
@click.option("--force", is_flag=True,
              help="Replace a report.html, metrics.json or figure in DIR that pmdcid did not "
                   "write.")
@log_options
def report_cmd(logs, model_path, out_dir, summary_path, before_path, force, mapping):
    """Compare MODEL with measured LOGs: DIR/report.html, DIR/metrics.json, DIR/*.png."""
    from pmdcid import api

    res = api.report(list(logs), model_path, out_dir, summary=summary_path, before=before_path,
                     progress=progress_lines(), mapping=mapping, force=force)
    echo(f"wrote {res.html_path}")
    echo(f"wrote {res.metrics_path} and {len(res.figures)} figures")
