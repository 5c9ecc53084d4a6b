"""``pmdcid diagnose`` on files: read logs and model, diagnose, write NEW_MODEL and the summary."""

from __future__ import annotations

import json
import math
import os

from pmdcid.errors import LogError, ModelError


def _same(a: str, b: str) -> bool:
    if os.path.exists(a) and os.path.exists(b):
        return os.path.samefile(a, b)
    return os.path.abspath(a) == os.path.abspath(b)


def _clean(obj):
    """JSON-safe: non-finite floats become null."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    return obj


def diagnose_logs(logs, model, effects=None, **opts):
    """Diagnose ``model`` on ``logs`` as the command does: a lumped model's logs seen as
    torque-driven (:func:`~pmdcid.simulate.logs_for`), the new model lumped too."""
    from pmdcid.diagnose.loop import diagnose
    from pmdcid.model.lumped import is_lumped, mark_lumped
    from pmdcid.simulate import logs_for

    res = diagnose(logs_for(logs, model), model, effects=effects, **opts)
    if is_lumped(model):
        mark_lumped(res.model)
    return res


def run_diagnose(paths, model_path, out_path, summary_path=None, mapping=None, effects=None,
                 force=False, **opts):
    """Diagnose ``model_path`` on the logs ``paths``; write ``out_path`` (and the summary).

    Neither output may be an input log; the summary may not be a model file. ``model_path`` is
    only rewritten when ``out_path`` is the same file. Both writes are atomic, after the whole
    analysis succeeded.
    """
    from pmdcid.identify.plausibility import gate
    from pmdcid.io import read_logs
    from pmdcid.model import load_model, save_model
    from pmdcid.runtime.outputs import atomic_write_text, check_overwrite, locked
    from pmdcid.simulate.substeps import bounded_for

    for p in paths:
        if _same(p, out_path):
            raise LogError(f"NEW_MODEL would overwrite the input log {p}; choose another -o",
                           out_path)
        if summary_path and _same(p, summary_path):
            raise LogError(f"the summary would overwrite the input log {p}; choose another "
                           "--summary", summary_path)
    if summary_path and (_same(summary_path, model_path) or _same(summary_path, out_path)):
        raise ModelError("the summary would overwrite a model file; choose another --summary",
                         summary_path)
    check_overwrite(out_path, "model", force)
    if summary_path:
        check_overwrite(summary_path, "summary", force, "--summary")
    model = load_model(model_path)
    logs = read_logs(paths, mapping, defer=True)

    def value(name):
        return model.parameters[name].value if name in model.parameters else None

    gate(logs, force, value("km"), value("R"))
    with bounded_for(model_path):
        res = diagnose_logs(logs, model, effects=effects, **opts)
    res.record_notes(res.model)  # the model file keeps diagnose's notes and warnings
    with locked(out_path):
        save_model(res.model, out_path)
    if summary_path:
        atomic_write_text(summary_path, json.dumps(_clean(res.summary), indent=2) + "\n")
    return res


__all__ = ["diagnose_logs", "run_diagnose"]
