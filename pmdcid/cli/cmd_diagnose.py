"""``pmdcid diagnose LOG... -m MODEL -o NEW_MODEL [--summary SUMMARY.json]``."""

from __future__ import annotations

import click

from pmdcid.cli import echo, main, progress_lines
from pmdcid.cli.options import INPUT_FILE, log_options, model_option


@main.command("diagnose")
@click.argument("logs", nargs=-1, required=True, metavar="LOG...", type=INPUT_FILE)
@model_option(updated=False)
@click.option("-o", "--output", "out_path", required=True, type=click.Path(dir_okay=False),
              metavar="NEW_MODEL", help="Where to write the model with the effects found "
                                        "(MODEL itself is only changed if this is MODEL).")
@click.option("--summary", "summary_path", type=click.Path(dir_okay=False), default=None,
              metavar="SUMMARY.json", help="Write the summary (added, candidates, before, "
                                           "after, unexplained) as JSON.")
@click.option("--effect", "effects", multiple=True, metavar="NAME",
              help="Search only this catalogue effect (repeatable; default: all but "
                   "lugre, searched only when named).")
@click.option("--force", is_flag=True,
              help="Overwrite NEW_MODEL / SUMMARY even when they are not pmdcid files, and "
                   "write the model even when the logs look implausible (then a warning).")
@log_options
def diagnose_cmd(logs, model_path, out_path, summary_path, effects, force, mapping):
    """Find the catalogue effects MODEL lacks on LOGs, add them, refit, report before/after."""
    from pmdcid import api
    from pmdcid.model import EFFECTS

    unknown = [e for e in effects if e not in EFFECTS]
    if unknown:
        raise click.BadParameter(f"unknown effect {unknown[0]!r} (known: {', '.join(EFFECTS)})",
                                 param_hint="'--effect'")

    res = api.diagnose(list(logs), model_path, effects=list(effects) or None,
                       progress=progress_lines(), mapping=mapping, output=out_path,
                       summary=summary_path, force=force)
    echo(res.table())
    echo(f"wrote {out_path}")
    if summary_path:
        echo(f"wrote {summary_path}")
