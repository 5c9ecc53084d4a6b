"""``export --to python-control``: a Python module whose ``make_system(dt)`` returns a
discrete-time ``control.NonlinearIOSystem`` stepping the kernel's exact model.

The module is self-contained (numpy, and python-control for ``make_system``): its physics is the
kernel's own Python source (:func:`pmdcid.export.codegen.python_kernel`: the terms, one internal
step of the stick-slip and LuGre loops, the discretisation, the substep rule; numba's decorators
dropped), run as plain Python; the template is the shell. The discretisation is computed at
``make_system`` time for the dt given; LuGre's bristle deflection z is a state. A sensor delay
is kept as a delay line in the state (the outputs must be a function of the state), and so are
the past inputs a late input (input_delay) needs, with a ``started`` state: from the all-zero
state the first step takes them to be the first input, as simulate and the C export start.
"""

from __future__ import annotations

import textwrap

from pmdcid.export import MARKER, ExportSpec, fill, number, template
from pmdcid.export.codegen import python_kernel
from pmdcid.io.escape import py_text


def render(spec: ExportSpec) -> str:
    """Source text of the generated module."""
    params = "\n".join(f"    {n!r}: {number(v, 'math.inf')}," for n, v in spec.values.items())
    return fill(template("pycontrol.py.tmpl"), {
        "MARKER": MARKER.capitalize(), "SOURCE": py_text(spec.source), "DRIVE": spec.drive,
        "INPUT": "tau" if spec.drive == "tau" else "v",
        "NAMES": textwrap.fill(" ".join(f"{n!r}," for n in spec.values), 96,
                               initial_indent="    ", subsequent_indent="    "),
        "PARAMS": params, "DELAY": number(spec.delay, "math.inf"),
        "OMEGA0": number(spec.omega0, "math.inf"), "KERNEL": python_kernel(),
    })
