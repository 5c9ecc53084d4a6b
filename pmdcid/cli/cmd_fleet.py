"""``pmdcid fleet MANIFEST -o DIR [--scheduler ADDRESS] [--workers N] [--km X] [--limits FILE]``:
every unit of a fleet identified on a Dask cluster (docs/fleet.md)."""

from __future__ import annotations

import click

from pmdcid.cli import echo, main
from pmdcid.cli.options import INPUT_FILE, km_type, log_options


@main.command("fleet")
@click.argument("manifest", type=INPUT_FILE, metavar="MANIFEST")
@click.option("-o", "--output", "out_dir", type=click.Path(), required=True, metavar="DIR",
              help="Folder for units.parquet, outliers.csv, fleet.html (and the results/ "
                   "journal a rerun resumes from).")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Run on the existing Dask cluster of this scheduler (tcp://HOST:PORT); "
                   "default: a local cluster started and stopped here.")
@click.option("--workers", type=click.IntRange(min=1, max=4096), default=None, metavar="N",
              help="Worker processes of the local cluster (default: the CPUs).")
@click.option("--km", type=km_type(), default=None, metavar="X",
              help="Torque constant [N m/A] (datasheet) every unit uses.")
@click.option("--limits", "limits_path", type=INPUT_FILE, default=None,
              metavar="FILE", help='End-of-line limits, JSON {"R": [min, max], ...}: adds '
                                   "pass and failed to units.parquet.")
@click.option("--no-diagnose", is_flag=True,
              help="Skip each unit's effect search after its joint fit (faster).")
@click.option("--force", is_flag=True,
              help="Replace a units.parquet, outliers.csv or fleet.html in DIR that pmdcid "
                   "did not write.")
@log_options
def fleet_cmd(manifest, out_dir, scheduler, workers, km, limits_path, no_diagnose, force,
              mapping):
    """Identify every unit of a fleet on a Dask cluster: DIR/units.parquet, DIR/outliers.csv,
    DIR/fleet.html."""
    from pmdcid import api
    from pmdcid.fleet.run import FleetError

    if scheduler is not None and workers is not None:
        raise click.UsageError("--workers sizes the local cluster; with --scheduler the "
                               "cluster's own workers run the units")
    try:
        res = api.run_fleet(manifest, out_dir, scheduler=scheduler, workers=workers, km=km,
                            limits=limits_path, diagnose=not no_diagnose,
                            mapping=mapping or None, force=force)
    except FleetError as exc:
        if exc.result is not None:  # every unit failed: DIR's record of why is kept, exit 1
            from pmdcid.runtime.outputs import keep_written

            _summary(exc.result, out_dir)
            keep_written()
        raise
    _summary(res, out_dir)


def _summary(res, out_dir) -> None:
    echo(res.table())
    for w in res.warnings:
        echo(f"warning: {w}", err=True)
    echo(f"wrote {out_dir}/units.parquet, outliers.csv, fleet.html")
