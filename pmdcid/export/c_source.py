"""``export --to c``: dependency-free C99 source and header stepping the kernel's exact model,
with a friction and dead-zone compensator (feed-forward, see docs/export.md).

The physics in the source is generated from the kernel's one source
(:func:`pmdcid.export.codegen.c_kernel`: the same terms, substep rule, discretisation, stick-slip
events and LuGre loop); the template ``model.c.tmpl`` is the shell: the public API, a late
input's past inputs in a fixed line inside the model struct (no allocation), the compensator.
The header's parameter struct is the kernel's vector in layout order. The sensor delay is not
applied (the state is the rotor's); omega0 is added by ``pmdc_measured_omega``.
"""

from __future__ import annotations

import re
from pathlib import Path

from pmdcid.export import MARKER, ExportError, ExportSpec, fill, number, template
from pmdcid.export.codegen import c_kernel
from pmdcid.io.escape import c_comment, c_include

_DRIVE_CHAR = {"v": "v", "tau": "t", "lumped": "l"}
#: what the shell does with a parameter, beside its declaration's words
SHELL_NOTES = {"latency": "applied by pmdc_step; needs latency/dt <= PMDC_INPUT_LINE",
               "omega0": "added by pmdc_measured_omega",
               "delay": "NOT applied here: read the state that many samples late"}


def header_path(source: Path) -> Path:
    """The header beside ``source``: FILE.c -> FILE.h (FILE -> FILE.h)."""
    if source.suffix == ".h":
        raise ExportError("give the C source file to -o (e.g. motor.c); its header is written "
                          "beside it", str(source))
    return source.with_suffix(".h") if source.suffix else source.with_name(source.name + ".h")


def fields(names) -> str:
    """The parameter struct's members, one a line, each with its meaning and unit."""
    from pmdcid.model.effects import param_spec

    rows = []
    for n in names:
        ps = param_spec(n)
        note = f"; {SHELL_NOTES[n]}" if n in SHELL_NOTES else ""
        rows.append(f"    double {n}; /* {c_comment(ps.doc)} [{ps.unit}]{note} */")
    return "\n".join(rows)


def render(spec: ExportSpec, header_name: str) -> tuple[str, str]:
    """(source text, header text)."""
    values = dict(spec.values, omega0=spec.omega0, delay=spec.delay)
    params = "\n".join(f"    p->{n} = {number(v, 'INFINITY')};" for n, v in values.items())
    guard = "PMDC_" + re.sub(r"[^A-Za-z0-9]", "_", header_name).upper()
    common = {"MARKER": MARKER.capitalize(), "SOURCE": c_comment(spec.source)}
    header = fill(template("model.h.tmpl"), dict(
        common, GUARD=guard, DRIVE_CHAR=_DRIVE_CHAR[spec.drive],
        TORQUE_PATH="1" if spec.torque_path else "0", FIELDS=fields(values)))
    source = fill(template("model.c.tmpl"), dict(
        common, HEADER=c_include(header_name), CNAME=c_comment(Path(header_name).stem + ".c"),
        PARAMS=params, KERNEL=c_kernel()))
    return source, header
