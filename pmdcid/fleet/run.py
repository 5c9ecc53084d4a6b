"""``pmdcid fleet``: every unit of a manifest identified on a Dask cluster, then the population.

1. :func:`plan`: read the manifest, hash every log, key each measurement (:mod:`.journal`);
   a measurement whose log cannot be read is an error row at once.
2. The measurements the journal does not hold run as Dask tasks (:mod:`.cluster`,
   :mod:`.task`), each result committed to the journal as it lands; no cluster is started when
   every measurement is already done.
3. :func:`analyse`: robust statistics, outliers, population priors (:mod:`.population`),
   drift (:mod:`.drift`), limits (:mod:`.limits`).
4. ``units.parquet``, ``outliers.csv`` and ``fleet.html`` written atomically.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

from pmdcid.errors import LogError, PmdcidError
from pmdcid.fleet import journal
from pmdcid.fleet.manifest import Measurement, read_manifest
from pmdcid.fleet.table import is_units_parquet
from pmdcid.runtime.outputs import check_folder_outputs, starts_with

#: the files a fleet writes into DIR (besides the journal folder)
OUTPUTS = ("units.parquet", "outliers.csv", "fleet.html")
#: how a fleet recognises each of them as its own (another file there is kept unless --force)
OURS = {"units.parquet": is_units_parquet,
        "outliers.csv": lambda p: starts_with(p, b"unit,parameter,value,reason\n", 28),
        "fleet.html": lambda p: starts_with(p, b"<title>pmdcid fleet</title>")}


class FleetError(PmdcidError):
    """Nothing of the fleet could run. ``result``: the :class:`FleetResult` when the fleet ran
    and every unit failed (its outputs, the record of why, are written), else None."""

    result: FleetResult | None = None


@dataclass
class FleetResult:
    """A fleet's rows (one per measurement, manifest order) and what the population says."""

    manifest: str
    out_dir: str
    rows: list[dict]
    ran: int = 0  # measurements identified by this run
    resumed: int = 0  # measurements taken from the journal
    stats: dict = field(default_factory=dict)
    outliers: list = field(default_factory=list)
    drifts: list = field(default_factory=list)
    borrowing: dict = field(default_factory=dict)  # parameter -> units borrowing it
    limits: dict | None = None
    warnings: list[str] = field(default_factory=list)

    @property
    def errors(self) -> list[dict]:
        return [r for r in self.rows if r["status"] != "ok"]

    def table(self) -> str:
        """A few lines for the terminal."""
        n_units = len({r["unit"] for r in self.rows})
        lines = [f"fleet: {len(self.rows)} measurements of {n_units} units: "
                 f"{len(self.rows) - len(self.errors)} identified, {len(self.errors)} failed "
                 f"({self.ran} run now, {self.resumed} from earlier runs)"]
        lines += [f"outlier: {o.unit}: {o.reason}" for o in self.outliers]
        lines += [f"drift: {d.unit}: {d.describe()}" for d in self.drifts if d.significant]
        if self.limits is not None:
            passed = sum(bool(r["pass"]) for r in self.rows)
            lines.append(f"limits: {passed} of {len(self.rows)} measurements pass")
        lines += [f"error: {r['unit']}: {r['error']}" for r in self.errors]
        return "\n".join(lines)


def options_of(km, diagnose: bool, mapping) -> dict:
    """The options a measurement's result depends on (part of its journal key)."""
    import pmdcid

    return {"km": km, "diagnose": bool(diagnose),
            "mapping": repr(mapping) if mapping else None, "version": pmdcid.__version__}


def _time_text(m: Measurement) -> str | None:
    return m.time.isoformat(timespec="microseconds") if m.time is not None else None


def plan(measurements: list[Measurement], options: dict, mapping=None):
    """(jobs, rows of measurements that cannot run): each job keyed by its logs' content."""
    from pmdcid.errors import one_line

    jobs, bad = [], []
    for m in measurements:
        base = {"unit": m.unit, "time": _time_text(m), "logs": list(m.logs), "attrs": m.attrs}
        try:
            hashes = [journal.file_hash(p) for p in m.logs]
        except OSError as exc:
            msg = one_line(f"{exc.filename}: cannot read the log ({exc.strerror or exc})")
            bad.append({**base, "key": f"unread-{len(bad)}", "hashes": [], "status": "error",
                        "error": msg, "params": {}, "journal": False})
            continue
        key = journal.measurement_key(m.unit, base["time"], hashes, options)
        jobs.append({**base, "key": key, "hashes": hashes, "km": options["km"],
                     "diagnose": options["diagnose"], "mapping": mapping})
    return jobs, bad


def _run(todo: list[dict], out_dir: str, scheduler, workers, bar_stream) -> list[dict]:
    """Run ``todo`` on the cluster, committing each result to the journal as it lands."""
    from pmdcid.fleet.cluster import Bar, client_for, run_jobs
    from pmdcid.fleet.task import run_unit

    if not todo:
        return []
    got = []
    bar = Bar(len(todo), bar_stream)
    with client_for(scheduler, workers) as client:
        for row in run_jobs(client, [_wire(j) for j in todo], run_unit):
            if row.get("journal"):
                journal.commit(out_dir, row)
            got.append(row)
            bar.update(row)
    return got


def _wire(job: dict) -> dict:
    """The job as sent to a worker (the attributes stay with the caller)."""
    return {k: v for k, v in job.items() if k != "attrs"}


def run_fleet(manifest, out_dir, *, scheduler: str | None = None, workers: int | None = None,
              km: float | None = None, limits: str | None = None, diagnose: bool = True,
              mapping=None, bar_stream=None, force: bool = False) -> FleetResult:
    """``pmdcid fleet`` (module doc). ``scheduler``: a Dask scheduler's address (default: a
    local cluster of ``workers`` processes); ``km`` [N m/A]: the datasheet torque constant
    every unit uses; ``limits``: a limits file (:mod:`.limits`); ``bar_stream``: where the
    progress bar goes when it is a terminal (default stderr); ``force``: replace a file under
    an output's name in DIR that a fleet did not write (refused before any work otherwise).
    Returns a :class:`FleetResult`; raises :class:`FleetError` when nothing could run: no log
    of the manifest could be read (nothing written), or every unit failed (DIR's outputs are
    written, the record of why, and the error's ``result`` is the :class:`FleetResult`)."""
    from pmdcid.fleet.limits import read_limits

    if os.path.isdir(str(out_dir)):
        check_folder_outputs(out_dir, OUTPUTS, force, ours=OURS)
    measurements = read_manifest(manifest)
    lim = read_limits(limits) if limits is not None else None
    jobs, bad = plan(measurements, options_of(km, diagnose, mapping), mapping)
    if not jobs:
        raise FleetError(f"no unit's logs could be read (first: {bad[0]['error']})",
                         str(manifest))
    _make_dir(out_dir)
    _check_inputs(out_dir, [str(manifest), *([limits] if limits else []),
                            *(p for m in measurements for p in m.logs)])
    with journal.exclusive(out_dir):
        done = journal.load(out_dir, [j["key"] for j in jobs])
        fresh = _run([j for j in jobs if j["key"] not in done], out_dir, scheduler, workers,
                     bar_stream)
        by_key = {**done, **{r["key"]: r for r in fresh}}
        rows = [{**by_key[j["key"]], "attrs": j["attrs"]} for j in jobs] + bad
        res = FleetResult(str(manifest), str(out_dir), _ordered(rows, measurements),
                          ran=len(fresh), resumed=len(done), limits=lim)
        analyse(res)
        write_outputs(res)
    if res.rows and not any(r["status"] == "ok" for r in res.rows):
        raise _all_failed(res)
    return res


def _all_failed(res: FleetResult) -> FleetError:
    """The one line of a fleet that ran with no unit identified (its result attached)."""
    first = res.rows[0]
    exc = FleetError(f"no unit could be identified: all {len(res.rows)} failed "
                     "(units.parquet says why); first: "
                     f"{str(first['unit'])[:40]}: {first['error']}")
    exc.result = res
    return exc


def _ordered(rows: list[dict], measurements: list[Measurement]) -> list[dict]:
    rank = {(m.unit, _time_text(m)): k for k, m in enumerate(measurements)}
    return sorted(rows, key=lambda r: rank.get((r["unit"], r.get("time")), len(rank)))


def _make_dir(out_dir) -> None:
    """DIR and its journal folder (kept whatever happens: see :mod:`.journal`)."""
    p = str(out_dir)
    if os.path.exists(p) and not os.path.isdir(p):
        raise LogError("is a file, not a folder: give -o a folder for the fleet", p)
    try:
        os.makedirs(journal.results_dir(p), exist_ok=True)
    except OSError as exc:
        raise LogError(f"cannot create the output folder ({exc.strerror or exc})", p) from None


def _check_inputs(out_dir, inputs: list[str]) -> None:
    """Refuse a DIR whose outputs would overwrite an input (the manifest, limits, a log)."""
    from pmdcid.runtime.outputs import input_at

    for o in [os.path.join(str(out_dir), n) for n in OUTPUTS]:
        inp = input_at(o, inputs)
        if inp is not None:
            raise LogError(f"the fleet's output would overwrite the input {inp}; choose "
                           "another -o", o)


def analyse(res: FleetResult) -> None:
    """Fill ``res`` with the population (statistics, outliers, priors), drift and limits, and
    mark each row: ``pooled``, ``borrowed``, ``outlier``, ``drifting``, ``pass``/``failed``."""
    from pmdcid.fleet import drift, limits, population

    pop = _comparable(res)
    res.stats = population.stats(pop)
    res.outliers = population.outliers(pop, res.stats)
    res.drifts = drift.drifts(pop)
    now = {id(r) for r in population.latest(pop)}
    flagged: dict[str, list[str]] = {}
    for o in res.outliers:
        flagged.setdefault(o.unit, []).append(o.parameter)
    moving: dict[str, list[str]] = {}
    for d in res.drifts:
        if d.significant:
            moving.setdefault(d.unit, []).append(d.parameter)
    _drift_reasons(res, pop)
    same = {id(r) for r in pop}
    for r in res.rows:
        r.update(pooled={}, borrowed=[])
        if id(r) in same:
            _pool_row(r, res)
        r["outlier"] = flagged.get(r["unit"], []) if id(r) in now else []
        r["drifting"] = moving.get(r["unit"], [])
        if res.limits is not None:
            r["pass"], r["failed"] = limits.check(r, res.limits)
    versions = {r.get("version") for r in res.rows if r.get("version")}
    if len(versions) > 1:
        res.warnings.append("the units ran on different pmdcid versions: "
                            + ", ".join(sorted(versions)))


def _drift_reasons(res: FleetResult, pop: list[dict]) -> None:
    """An outlier that drifted there says so in its reason (worn, not born so), and one whose
    model holds other effects than most units' says which (its parameters mean other things)."""
    from collections import Counter

    from pmdcid.fleet.population import latest

    now = {r["unit"]: r for r in latest(pop)}
    usual = Counter(tuple(r.get("effects", [])) for r in now.values()).most_common(1)
    usual = list(usual[0][0]) if usual else []
    lines = {(d.unit, d.parameter): d for d in res.drifts if d.significant}
    for o in res.outliers:
        d = lines.get((o.unit, o.parameter))
        if d is not None:
            o.reason += f"; it drifted {100 * d.change:+.1f} % since its first measurement"
        mine = list(now[o.unit].get("effects", [])) if o.unit in now else usual
        if mine != usual:
            o.reason += (f"; its model adds [{', '.join(mine)}] where most units' add "
                         f"[{', '.join(usual)}]")


def _comparable(res: FleetResult) -> list[dict]:
    """The rows whose parameters are in the same units as most: SI, or per volt (lumped: no
    current and no km); the others are left out of the population, said in the warnings."""
    ok = [r for r in res.rows if r["status"] == "ok"]
    lumped = sum(bool(r.get("lumped")) for r in ok)
    if lumped in (0, len(ok)):
        return res.rows
    keep = lumped > len(ok) - lumped
    res.warnings.append(f"{lumped} of {len(ok)} measurements were identified per volt (lumped: "
                        "no current or no km) and the others in SI: the population statistics "
                        f"use the {'lumped' if keep else 'SI'} ones only; give --km")
    return [r for r in res.rows if bool(r.get("lumped")) == keep or r["status"] != "ok"]


def _pool_row(r: dict, res: FleetResult) -> None:
    from pmdcid.fleet.population import BORROW, pool, pool_bounded

    if r["status"] != "ok":
        return
    for name, st in res.stats.items():
        if name not in r["params"]:
            continue
        got = r["params"][name]
        if len(got) > 3:  # only bounded: the prior within the interval
            v, se, weight = pool_bounded(float(got[3]), float(got[4]), st)
        else:
            v, se, weight = pool(float(got[0]) if got[0] is not None else float("nan"),
                                 float(got[1]) if got[1] is not None else float("nan"), st)
        r["pooled"][name] = [v, se, weight]
        if weight >= BORROW:
            r["borrowed"].append(name)
            res.borrowing[name] = res.borrowing.get(name, 0) + 1


def write_outputs(res: FleetResult) -> None:
    """units.parquet, outliers.csv and fleet.html into DIR, each atomically."""
    from pmdcid.fleet import figures, page, table
    from pmdcid.fleet.population import param_names
    from pmdcid.runtime.outputs import atomic_write, atomic_write_text

    names = param_names(res.rows)
    attrs = list(dict.fromkeys(a for r in res.rows for a in r.get("attrs", {})))
    pooled = [n for n, st in res.stats.items() if math.isfinite(st.tau)]
    cols = table.columns(res.rows, names, pooled, attrs, res.limits is not None)
    data = table.parquet_bytes(cols)
    out = res.out_dir
    atomic_write(os.path.join(out, "units.parquet"), lambda fh: fh.write(data), binary=True)
    atomic_write_text(os.path.join(out, "outliers.csv"), table.outliers_csv(res.outliers))
    html = page.render(res, figures.distributions(res.rows, res.stats, res.outliers),
                       figures.drift_figure(res.rows, res.drifts))
    atomic_write_text(os.path.join(out, "fleet.html"), html)


__all__ = ["OUTPUTS", "FleetError", "FleetResult", "analyse", "options_of", "plan",
           "run_fleet", "write_outputs"]
