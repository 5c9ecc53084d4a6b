"""Typed fit results: value, standard error, unit and fit statistics (not tuples).

Every result (the stages' results, ``identify``'s and ``diagnose``'s) follows one protocol,
:class:`ResultProtocol`: ``str()`` is its table, ``_repr_html_()`` shows it in a notebook,
``to_dict()``/``to_pandas()`` give its parameters (value, stderr, unit), ``apply(model)`` writes
them into a model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pmdcid.fit.covariance import CovarianceInfo
from pmdcid.model.effects import stderr_words, within_range
from pmdcid.model.tables import in_words


class ResultProtocol:
    """The common face of fit results (a mixin). A class provides ``table()`` and
    ``apply(model)``, and either ``estimates`` (name -> :class:`Estimate`) or its own
    :meth:`rows`; the rest follows."""

    def rows(self) -> list[tuple]:
        """(name, value, stderr, unit, interval, caveat) of each estimated parameter
        (:class:`pmdcid.model.tables.Row`)."""
        return [(e.name, e.value, e.stderr, e.unit, e.interval, e.caveat)
                for e in map(shown, getattr(self, "estimates", {}).values())]

    def __str__(self) -> str:
        return self.table()

    def _repr_html_(self) -> str:
        from pmdcid.model.tables import html_table

        return html_table(self.rows(), type(self).__name__, self.table())

    def all_notes(self) -> list:
        """Every warning and note of this result as :class:`~pmdcid.notes.Note`: text, the
        parameters (or log) it concerns, severity, the stage that gave it."""
        return notes_of(self)

    def record_notes(self, model) -> None:
        """Keep this result's notes in ``model`` (:func:`record_notes`)."""
        record_notes(self, model)

    def to_dict(self) -> dict:
        """Parameters (name -> value, stderr, unit), warnings, notes (with what each concerns
        and its severity), fit statistics, the table."""
        from pmdcid.model.tables import rows_dict
        from pmdcid.notes import to_records

        out = {"result": type(self).__name__, "parameters": rows_dict(self.rows()),
               "warnings": list(getattr(self, "warnings", [])),
               "notes": to_records(self.all_notes())}
        stats = getattr(self, "stats", None)
        if isinstance(stats, FitStats):
            out["stats"] = {"ndata": stats.ndata, "nvarys": stats.nvarys,
                            "chisqr": stats.chisqr, "redchi": stats.redchi,
                            "aic": stats.aic, "bic": stats.bic}
        out["table"] = self.table()
        return out

    def to_pandas(self):
        """A DataFrame with columns parameter, value, stderr, unit."""
        from pmdcid.model.tables import rows_frame

        return rows_frame(self.rows())

    def plot(self, logs=None, *, model=None):
        """The fitted model beside the measurements, one panel per log (matplotlib Figure): the
        speed (a blocked rotor's current) measured and simulated from each log's measured
        start, with its NRMSE. ``logs``: default the logs the result was fitted on;
        ``model``: default the model the result makes (:meth:`fitted_model`)."""
        from pmdcid.errors import PmdcidError
        from pmdcid.io.plot import plot_fit
        from pmdcid.simulate.measured import fit_rows

        logs = getattr(self, "_fitted_on", (None, None))[0] if logs is None else logs
        if logs is None:
            raise PmdcidError("this result does not hold the logs it was fitted on: give them, "
                              "result.plot(logs)")
        rows, left = fit_rows(list(logs) if isinstance(logs, list | tuple) else [logs],
                              self.fitted_model() if model is None else model)
        labelled = [(f"{name}: {signal} NRMSE {nrmse_text(nrmse(sim, meas), 3)}", t, signal,
                     meas, sim) for name, t, signal, meas, sim in rows]
        return plot_fit(labelled, type(self).__name__, left)

    def fitted_model(self):
        """The model this result makes: its own ``model`` (identify, diagnose), else the model
        it was fitted from with the result applied (a stage's result)."""
        from pmdcid.errors import PmdcidError
        from pmdcid.model import Model

        own = getattr(self, "model", None)
        if isinstance(own, Model):
            return own
        base = getattr(self, "_fitted_on", (None, None))[1]
        if base is None:
            raise PmdcidError("this result does not hold the model it was fitted from: give "
                              "one, result.plot(logs, model=...)")
        out = base.copy()
        self.apply(out)
        return out

    def fitted_on(self, logs, model) -> None:
        """Keep the logs this result was fitted on and the model it started from (references:
        nothing is copied), for :meth:`plot` and :meth:`fitted_model`."""
        self._fitted_on = (list(logs), model)

    def table(self) -> str:  # pragma: no cover - every result defines its own
        raise NotImplementedError

    def apply(self, model) -> None:  # pragma: no cover - every result defines its own
        raise NotImplementedError

    def _keep_lumped(self, model) -> None:
        """After apply: a result fitted per volt (``per_volt`` marked it) makes ``model``
        lumped too, so that its per-volt values are never read as SI."""
        if getattr(self, "lumped", False):
            from pmdcid.model.lumped import mark_lumped

            mark_lumped(model)


#: the stage each result class reports for (the model file's parameter ``stage`` names)
STAGE_OF = {"ElectricalResult": "fit-electrical", "FreeRunResult": "fit-electrical",
            "MechanicalResult": "fit-mechanical",
            "NonlinearResult": "fit-nonlinear", "InverseDynamicsResult": "fit-nonlinear",
            "IdentifyResult": "identify", "DiagnoseResult": "diagnose"}


def notes_of(result) -> list:
    """Every warning and note of any stage result (``warnings``; a diagnose summary's
    ``warnings`` and ``notes``) as :class:`~pmdcid.notes.Note`, with its stage."""
    from pmdcid.notes import as_note

    stage = STAGE_OF.get(type(result).__name__, type(result).__name__)
    items = [(w, "warning") for w in getattr(result, "warnings", [])]
    summary = getattr(result, "summary", None)  # diagnose's: its notes and drive warnings
    if isinstance(summary, dict):
        items += [(w, "warning") for w in summary.get("warnings", [])]
        items += [(n, "note") for n in summary.get("notes", [])]
    logs = _log_paths(result)
    return [as_note(w, severity=sev, stage=stage, names=known_names(), logs=logs)
            for w, sev in items]


def record_notes(result, model) -> None:
    """Keep ``result``'s notes in ``model`` (the model file's ``"notes"``, one record per
    note), in place of those an earlier run of the same stage left there."""
    from pmdcid.notes import to_records

    got = result.all_notes() if hasattr(result, "all_notes") else notes_of(result)
    mine = to_records(got)
    stages = {r["stage"] for r in mine} | {STAGE_OF.get(type(result).__name__, "")}
    kept = [r for r in model.extra.get("notes", []) if r.get("stage") not in stages]
    model.extra["notes"] = kept + mine


def known_names() -> tuple[str, ...]:
    """Every parameter and effect name (what a note may concern), longest first."""
    from pmdcid.model.effects import EFFECTS
    from pmdcid.model.spec import BASE_PARAMS

    names = set(BASE_PARAMS) | set(EFFECTS)
    names |= {p.name for e in EFFECTS.values() for p in e.params}
    return tuple(sorted(names, key=lambda n: (-len(n), n)))


def _log_paths(result) -> list[str]:
    paths = list(getattr(result, "paths", None) or [])
    for name in ("steps", "logs", "per_log"):
        for item in getattr(result, name, None) or []:
            p = getattr(item, "path", None)
            if isinstance(p, str):
                paths.append(p)
    return sorted(set(paths), key=len, reverse=True)


@dataclass
class Estimate:
    """One estimated parameter [unit], its standard error (NaN if unknown), whether it varied.

    ``interval``: (low, high) when the logs only bound it (``stderr`` NaN, ``value`` a point
    inside); ``caveat``: the words that go with it (why, what to record; a standard error that
    is a lower bound), as :class:`pmdcid.model.params.Parameter`'s."""

    name: str
    value: float
    stderr: float = math.nan
    unit: str = ""
    vary: bool = True
    interval: tuple[float, float] | None = None
    caveat: str = ""

    @property
    def rel_stderr(self) -> float:
        return abs(self.stderr / self.value) if self.value else math.nan

    def __str__(self) -> str:
        if self.interval is not None:
            return f"{self.name}: {in_words(self.interval, self.unit, self.caveat)}"
        seen = shown(self)
        if seen is not self:
            return str(seen)
        se = f" ± {self.stderr:.3g}" if math.isfinite(self.stderr) else ""
        why = f" ({self.caveat})" if self.caveat else ""
        return f"{self.name} = {self.value:.6g}{se} {self.unit}".rstrip() + why


#: the words a fitted parameter carries in place of a standard error when its variance is not
#: positive (:func:`pmdcid.fit.covariance.standard_errors`): its stderr is NaN (``null`` in the
#: model file), never 0
NOT_DETERMINED = "not determined by these logs: its variance is not positive, no standard error"
#: the words of a parameter a fit did not determine, held at the value other data determined
#: while the others were fitted again (:func:`kept_from_elsewhere`)
HELD_ELSEWHERE = (NOT_DETERMINED + "; held at the value other data determined, the others "
                  "fitted again with it")


def fitted(name: str, value: float, stderr: float, unit: str) -> Estimate:
    """A fitted parameter's :class:`Estimate`; a standard error that is not a finite positive
    number (a degenerate variance) is NaN and said in words (:data:`NOT_DETERMINED`). One that
    spans the parameter's whole range is kept here, for the readings that follow the cost (a
    lumped model's share valley, the secant errors), and shown as none (:func:`shown`)."""
    if math.isfinite(stderr) and stderr > 0:
        return Estimate(name, float(value), float(stderr), unit)
    return Estimate(name, float(value), math.nan, unit, caveat=NOT_DETERMINED)


def shown(e: Estimate) -> Estimate:
    """``e`` as it is printed and written: a standard error that spans the parameter's whole
    declared range (:func:`pmdcid.model.effects.range_only`: a bounded parameter whose value
    +-2 standard errors covers every value it may take, the linearisation of a cost flat
    across it) is none (NaN) with the words in its place, as the model file writes it
    (:meth:`pmdcid.model.params.Model.set`); one at a declared bound the interval from the
    bound two standard errors into the range (both: :func:`pmdcid.model.effects.stderr_words`);
    ``e`` itself otherwise. The estimate keeps its number for the readings that follow the
    cost."""
    if e.interval is not None or not e.vary:
        return e
    words, interval = stderr_words(e.name, e.value, e.stderr)
    if not words:
        return e
    return Estimate(e.name, e.value, math.nan, e.unit, e.vary, interval=interval,
                    caveat="; ".join(c for c in (words, e.caveat) if c))


def plus_minus(value: float, stderr: float, fmt: str = ".3g") -> str:
    """``value ± stderr`` for a message, or the value and "(no standard error)" where the
    error is not a finite positive number (:func:`fitted`: not determined): never ``± nan``
    or ``± 0``."""
    if math.isfinite(stderr) and stderr > 0:
        return f"{value:{fmt}} ± {stderr:.2g}"
    return f"{value:{fmt}} (no standard error)"


def bounded(name: str, low: float, high: float, unit: str, caveat: str,
            value: float | None = None) -> Estimate:
    """An :class:`Estimate` the logs only bound to [low, high] (value: the point inside that
    simulations use, default the midpoint), cut to the parameter's own range
    (:func:`pmdcid.model.effects.within_range`)."""
    low, high = within_range(name, low, high)
    v = 0.5 * (low + high) if value is None else value
    return Estimate(name, v, math.nan, unit, interval=(low, high), caveat=caveat)


def write_estimate(model, e: Estimate, stage: str, keep: bool = True) -> None:
    """Write ``e`` into ``model``: an estimate with its standard error, or a bounded one as an
    interval that keeps a value other data determined inside it
    (:meth:`pmdcid.model.params.Model.set_bounded`). An estimate these logs do not determine
    (:data:`NOT_DETERMINED`: no variance) leaves a value other data determined, with its
    standard error, as it was (fuzzing: fit-nonlinear on a log whose input stayed at 0 while
    the rotor turned wrote such bv and bc over fit-mechanical's); ``keep`` False: a fit over
    every log that value came from writes its own (identify's joint fit)."""
    if keep and _keeps_old(e, model):
        return
    if e.interval is not None:
        model.set_bounded(e.name, *e.interval, e.value, unit=e.unit, stage=stage,
                          caveat=e.caveat)
    else:
        model.set(e.name, e.value, e.stderr, e.unit, stage=stage, caveat=e.caveat)


def _keeps_old(e: Estimate, model) -> bool:
    """Whether :func:`write_estimate` leaves ``model``'s value of ``e`` as it was."""
    old = model.parameters.get(e.name)
    return (e.interval is None and e.caveat.startswith(NOT_DETERMINED) and old is not None
            and old.determined and math.isfinite(old.stderr))


def kept_from_elsewhere(estimates: dict[str, Estimate], model) -> list[str]:
    """The parameters of ``estimates`` the fit did not determine whose value in ``model``
    other data determined, where the fit moved them off it: :func:`write_estimate` keeps
    that value, so a fit that wrote the others beside it would leave a model that is no fit's
    (bench/newrigs.py lego seed 23: a back-EMF share of 1e-10 in identify's joint fit, 0.485
    from fit-nonlinear in the file; the held-out sines 0.050, against 0.028 for the joint
    fit's own set). The fit is run again with these held (:data:`HELD_ELSEWHERE`)."""
    return [n for n, e in estimates.items()
            if e.vary and _keeps_old(e, model)
            and abs(e.value - model.value(n)) > 1e-9 * abs(model.value(n))]


def held_elsewhere(model, name: str) -> Estimate:
    """The :class:`Estimate` of a parameter held at ``model``'s value
    (:func:`kept_from_elsewhere`)."""
    par = model.parameters[name]
    return Estimate(name, par.value, math.nan, par.unit, vary=False, caveat=HELD_ELSEWHERE)


@dataclass
class FitStats:
    """Statistics of a least-squares fit (lmfit's MinimizerResult vocabulary)."""

    ndata: int
    nvarys: int
    chisqr: float
    nfev: int = 0
    success: bool = True
    message: str = ""

    @property
    def nfree(self) -> int:
        return max(self.ndata - self.nvarys, 1)

    @property
    def redchi(self) -> float:
        return self.chisqr / self.nfree

    @property
    def aic(self) -> float:
        return self.ndata * math.log(max(self.chisqr, 1e-300) / self.ndata) + 2 * self.nvarys

    @property
    def bic(self) -> float:
        n = self.ndata
        return n * math.log(max(self.chisqr, 1e-300) / n) + math.log(n) * self.nvarys


#: a correlation this far beyond +-1 is no rounding: the covariance is not positive semidefinite
CORR_ROUNDING = 1e-9


def correlations(cov) -> np.ndarray:
    """The correlation matrix of a covariance ``cov`` (n x n, the parameters' units), every
    entry in [-1, 1] or NaN. A parameter whose variance is not finite and positive (a degenerate
    column: the data do not determine it) has a NaN row and column; where the covariance is not
    positive semidefinite (a degenerate column's rounding, a sum with a propagated part), the
    parameter in the most pairs beyond +-1 is taken as degenerate and its row set to NaN, until
    none remains; values within :data:`CORR_ROUNDING` of +-1 are rounding and clipped. The
    diagonal is 1 (NaN for a degenerate parameter)."""
    cov = np.asarray(cov, float)
    var = np.diag(cov).copy()
    bad = ~(np.isfinite(var) & (var > 0))
    sd = np.sqrt(np.where(bad, 1.0, var))
    with np.errstate(invalid="ignore", divide="ignore"):
        r = cov / np.outer(sd, sd)
    while True:
        r[bad, :] = math.nan
        r[:, bad] = math.nan
        over = np.abs(r) > 1.0 + CORR_ROUNDING
        over |= ~np.isfinite(r) & ~(bad[:, None] | bad[None, :])
        if not over.any():
            break
        count = over.sum(axis=1)
        bad[int(np.argmax(count))] = True
    return np.clip(r, -1.0, 1.0)


def _bounded(correl: dict) -> dict:
    """``correl`` (name -> name -> correlation) with every value outside [-1, 1] beyond
    rounding, or not finite, as NaN (undetermined), rounding clipped."""
    out = {}
    for a, row in correl.items():
        out[a] = {}
        for b, v in row.items():
            v = float(v)
            ok = math.isfinite(v) and abs(v) <= 1.0 + CORR_ROUNDING
            out[a][b] = max(-1.0, min(1.0, v)) if ok else math.nan
    return out


@dataclass
class SimFitResult:
    """Result of a simulation-error fit: estimates, correlations, statistics, per-log errors."""

    estimates: dict[str, Estimate]
    stats: FitStats
    correl: dict[str, dict[str, float]] = field(default_factory=dict)
    nrmse: list[dict[str, float]] = field(default_factory=list)  # per log: signal -> NRMSE
    sigma: list[dict[str, float]] = field(default_factory=list)  # per log: signal -> weight std
    #: how the covariance allowed for correlated residuals (None: white-residual formula)
    covariance: CovarianceInfo | None = None
    #: per log: the state (i, omega, theta) it was simulated from (measured or fitted start)
    initial: list = field(default_factory=list)
    #: name -> (mean, std) of the Gaussian prior terms that entered the fit, and the weight
    #: their rows had (``weight (x - mean)/std``: the data's honest information, simfit.py)
    priors: dict = field(default_factory=dict)
    prior_weight: float = 1.0
    #: with an AR noise model: per residual block, the whitening filter's coefficients
    #: (1, a1, ...), or None where the block was left white
    noise_filters: list = field(default_factory=list)
    #: the part of the free parameters' covariance that the held parameters' own errors add
    #: (:func:`pmdcid.fit.covariance.propagated`), in ``estimates``' order; the rest is the
    #: logs' own (None: not formed)
    held_cov: np.ndarray | None = None
    #: the data rows' ``(J'J)^-1`` in ``estimates``' order: the chi-square's own curvature,
    #: inverted (a profile's direction: the others' conditional optimum moves by
    #: ``curvature[:, j] / curvature[j, j]`` per unit of parameter j; None: not formed)
    curvature: np.ndarray | None = None

    def __post_init__(self) -> None:
        # a correlation is a cosine: never outside [-1, 1]; a pair beyond it (a covariance that
        # is not positive semidefinite) is undetermined, NaN (:func:`correlations`)
        self.correl = _bounded(self.correl)

    def values(self) -> dict[str, float]:
        return {k: e.value for k, e in self.estimates.items()}

    def correlation(self, a: str, b: str) -> float:
        """The correlation of ``a`` and ``b`` in [-1, 1]; NaN where either is degenerate (the
        logs do not determine it) or unknown."""
        return self.correl.get(a, {}).get(b, math.nan)


def format_estimates(estimates, width: int = 10) -> list[str]:
    """Table lines ``name  value ± stderr  unit`` (``fixed`` when the parameter did not vary;
    a bounded one in words, ``name  between LOW and HIGH UNIT (why)``)."""
    lines = [f"{'parameter':<{width}} {'value':>13}   {'± stderr':<11} unit"]
    for e in map(shown, estimates):
        if e.interval is not None:
            lines.append(f"{e.name:<{width}} {in_words(e.interval, e.unit, e.caveat)}")
            continue
        if not e.vary:
            se = "(fixed)"
        elif math.isfinite(e.stderr):
            se = f"± {e.stderr:.2g}"
        else:
            se = "± ?"
        why = f"  ({e.caveat})" if e.caveat else ""
        lines.append(f"{e.name:<{width}} {e.value:13.6g}   {se:<11} {e.unit}".rstrip() + why)
    return lines


def nrmse(sim: np.ndarray, meas: np.ndarray) -> float:
    """RMS error divided by the standard deviation of the measurement (docs/report.md); NaN
    where it is undefined: a measurement that never changes (std 0), fewer than 2 samples."""
    ok = np.isfinite(sim) & np.isfinite(meas)
    if ok.sum() < 2:
        return math.nan
    sd = float(np.std(meas[ok]))
    err = float(np.sqrt(np.mean((sim[ok] - meas[ok]) ** 2)))
    return err / sd if sd > 0 else math.nan


#: a measured speed whose correlation with the model's simulated speed is below this on every
#: log runs against it (:func:`speed_against`)
AGAINST = -0.5


def speed_against(pairs) -> str | None:
    """One line when the measured speed runs against the model's on every log that moves:
    ``pairs`` holds (simulated, measured) speed arrays [rad/s] per log. A speed sensor that
    counts the other way (or a motor wired the other way round) gives a correlation near -1;
    a model of the wrong motor still turns the same way as its input. None when any log
    follows the model, or none moves."""
    rs = []
    for sim, meas in pairs:
        ok = np.isfinite(sim) & np.isfinite(meas)
        if ok.sum() >= 3 and np.std(sim[ok]) > 0 and np.std(meas[ok]) > 0:
            rs.append(float(np.corrcoef(sim[ok], meas[ok])[0, 1]))
    if not rs or max(rs) >= AGAINST:
        return None
    lo, hi = f"{min(rs):.2f}", f"{max(rs):.2f}"
    span = lo if lo == hi else f"{lo} to {hi}"
    return (f"the measured speed runs against the model's (their correlation {span}): the speed "
            "sensor counts the other way from the input; map it with -c omega=COLUMN*-1 (and "
            "theta the same way)")


#: what a table says for an NRMSE that is undefined (:func:`nrmse`: NaN)
NRMSE_UNDEFINED = "undefined (the measurement never changes)"


def nrmse_text(value: float | None, digits: int = 4) -> str:
    """An NRMSE as a table prints it: ``digits`` decimals, or :data:`NRMSE_UNDEFINED` in words
    (never ``inf`` or ``nan``)."""
    if value is None or not math.isfinite(value):
        return NRMSE_UNDEFINED
    return f"{value:.{digits}f}"
