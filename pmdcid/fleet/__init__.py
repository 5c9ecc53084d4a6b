"""Fleets: every unit of a production line or a robot fleet identified on a Dask cluster,
then the population: robust statistics, outliers, drift, limits and population priors.

``manifest.py`` (which logs are which unit, when), ``journal.py`` (content keys, per-unit
result files committed atomically: resumable runs), ``task.py`` (one unit on a worker: the
``identify`` of :mod:`pmdcid.pipeline`), ``cluster.py`` (dask.distributed: a local cluster or
a scheduler's address), ``population.py`` (median, MAD, correlations, outliers, empirical
Bayes priors), ``drift.py``, ``limits.py``, ``table.py`` (units.parquet, outliers.csv),
``figures.py`` and ``page.py`` (fleet.html), ``run.py`` (:func:`run_fleet`). docs/fleet.md.

dask.distributed and pyarrow are the optional extra ``fleet``, imported only when a fleet runs.
"""

from __future__ import annotations


def run_fleet(*args, **kwargs):
    """:func:`pmdcid.fleet.run.run_fleet` (imported on first call)."""
    from pmdcid.fleet.run import run_fleet as run

    return run(*args, **kwargs)


__all__ = ["run_fleet"]
