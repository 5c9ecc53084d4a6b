"""``pmdcid channels FILE``: the signals a log file holds (name, samples, rate, unit)."""

from __future__ import annotations

import click

from pmdcid.cli import echo, main
from pmdcid.cli.options import INPUT_FILE


@main.command("channels")
@click.argument("log_file", metavar="FILE", type=INPUT_FILE)
@click.option("--json", "as_json", is_flag=True,
              help="Print a JSON list of {name, samples, rate_hz, unit} instead of a table.")
def channels_cmd(log_file, as_json):
    """List the signals FILE holds (any format pmdcid reads): name, samples, rate, unit.

    The names are the ones -c CANON=SOURCE takes: topic.field (MCAP), the entry name
    (wpilog), group/channel (TDMS, MDF: the channel name where unique), variable or
    struct.field (.mat), the column (CSV, Parquet)."""
    from pmdcid import api
    from pmdcid.io.formats import format_channels

    chans = api.channels(log_file)
    if as_json:
        import json

        echo(json.dumps([{"name": c.name, "samples": c.samples, "rate_hz": c.rate,
                                "unit": c.unit} for c in chans], indent=1))
        return
    echo(format_channels(chans))
