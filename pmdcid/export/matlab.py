"""``export --to matlab``: a function file simulating the model at a fixed sample period (same
discretisation, substeps and events as the kernel) and a script ``run_FILE.m`` that runs it.

Works in MATLAB and GNU Octave. The physics is generated from the kernel's source
(:func:`pmdcid.export.codegen.matlab_kernel`, local functions at the end of the file); the
template ``model.m.tmpl`` is the shell: the sample loop, the late input (input_delay, from the
input array) and the sensor effects (speed offset, delay by linear interpolation), applied like
``pmdcid simulate``; with LuGre the bristle deflection is an optional fourth output.
"""

from __future__ import annotations

import re
from pathlib import Path

from pmdcid.export import MARKER, ExportError, ExportSpec, fill, number, template
from pmdcid.export.codegen import matlab_kernel
from pmdcid.io.escape import m_comment
from pmdcid.simulate.layout import NAMES

_IDENT = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,62}")


def function_name(path: Path) -> str:
    """The function's name: the file's stem, which MATLAB requires to be an identifier."""
    if path.suffix != ".m" or not _IDENT.fullmatch(path.stem):
        raise ExportError("a MATLAB function file must be NAME.m with NAME a letter followed by "
                          "letters, digits or _ (e.g. motor.m)", str(path))
    return path.stem


def script_path(path: Path) -> Path:
    """The script beside the function file: FILE.m -> run_FILE.m."""
    return path.with_name(f"run_{function_name(path)}.m")


def render(spec: ExportSpec, func: str) -> tuple[str, str]:
    """(function file text, script text)."""
    params = "\n".join(f"p({k + 1}) = {number(v, 'Inf')};  % {n}"
                       for k, (n, v) in enumerate(spec.values.items()))
    input_doc = {"v": "voltage [V]", "tau": "torque [N m]", "lumped": "voltage [V]"}[spec.drive]
    common = {"MARKER": MARKER.capitalize(), "SOURCE": m_comment(spec.source), "FUNC": func,
              "INPUT_DOC": input_doc}
    fn = fill(template("model.m.tmpl"), dict(
        common, TORQUE_PATH="true" if spec.torque_path else "false", PARAMS=params,
        NPARAMS=str(len(NAMES)), LATENCY_SLOT=str(NAMES.index("latency") + 1),
        KERNEL=matlab_kernel(),
        DELAY=number(spec.delay, "Inf"), OMEGA0=number(spec.omega0, "Inf")))
    step = 1.0 if spec.drive != "tau" else max(2.0 * spec.values["bc"], 1e-3)
    script = fill(template("run.m.tmpl"), dict(common, STEP=repr(step)))
    return fn, script
