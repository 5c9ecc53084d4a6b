"""``export --to fmu``: an FMI 2.0 co-simulation FMU (a zip) stepping the kernel's exact model.

Inside: ``modelDescription.xml`` (input ``v`` or ``tau``, outputs ``i``, ``omega``, ``theta`` as
the sensors read them, every kernel parameter as a ``fixed`` parameter), ``sources/`` (the C99
port of the kernel written by :mod:`pmdcid.export.c_source`, the FMI wrapper
``templates/fmi2.c.tmpl`` and the three standard FMI 2.0 headers, BSD-2, Modelica Association:
``templates/FMI2_LICENSE.txt``) and ``binaries/<platform>/<id>.so`` compiled at export time by
the system C compiler (``cc`` or ``gcc``; ``$CC`` first). Each ``fmi2DoStep`` of size h is one
``pmdc_step`` at sample period h, so a communication step equal to a log's sample period steps
exactly as ``pmdcid simulate``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path
from xml.sax.saxutils import quoteattr

from pmdcid.export import MARKER, ExportError, ExportSpec, fill, number, template
from pmdcid.export.c_source import render as render_c

HEADERS = ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")
#: the wrapper's value references: the input, the outputs, then the parameters from PARAM_VR
INPUT_VR, OUTPUT_VRS, PARAM_VR = 0, {"i": 1, "omega": 2, "theta": 3}, 10
#: parameters of the electrical path, left out of a torque-driven or lumped FMU (not stepped)
ELECTRICAL = ("R", "L", "km", "ke", "vmax", "vb")
#: a zip entry's date: fixed, so the same model gives the same archive
ZIP_DATE = (1980, 1, 1, 0, 0, 0)
_NOT_XML = re.compile("[^\t\n\r\x20-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")


def model_identifier(stem: str) -> str:
    """A C identifier for the FMU's binary and functions, from the output file's stem."""
    ident = re.sub(r"[^A-Za-z0-9_]", "_", stem)[:64]
    return ident if re.match(r"[A-Za-z_]", ident or "0") else "pmdc_" + ident


def c_comment(text: str) -> str:
    """``text`` safe inside a C block comment (no ``*/``, printable ASCII) and in a template
    (no ``@@``)."""
    text = "".join(ch if " " <= ch <= "~" else "?" for ch in text)
    for bad, good in (("*/", "* /"), ("/*", "/ *"), ("@@", "@ @")):
        while bad in text:
            text = text.replace(bad, good)
    return text


def c_string(text: str) -> str:
    """``text`` as a C string literal (UTF-8 bytes; quotes, backslashes, others escaped)."""
    out = []
    for b in text.encode("utf-8"):
        ch = chr(b)
        if ch in '"\\':
            out.append("\\" + ch)
        elif " " <= ch <= "~" and ch != "?":  # '?' escaped: no trigraphs
            out.append(ch)
        else:
            out.append(f"\\{b:03o}")
    return '"' + "".join(out) + '"'


def xml_attr(text: str) -> str:
    """``text`` as a quoted XML attribute value (escaped; characters XML cannot hold as ``?``)."""
    return quoteattr(_NOT_XML.sub("?", text))


def parameters(spec: ExportSpec) -> dict[str, float]:
    """The FMU's parameters, in value-reference order (from :data:`PARAM_VR`)."""
    vals = dict(spec.values, delay=spec.delay, omega0=spec.omega0)
    if spec.torque_path:
        vals = {n: v for n, v in vals.items() if n not in ELECTRICAL}
    return vals


def _describe(name: str, spec: ExportSpec) -> str:
    from pmdcid.model.effects import param_spec

    ps = param_spec(name)
    unit = ps.unit
    if spec.drive == "lumped" and name not in ("delay", "omega0", "latency", "ws", "cphi"):
        unit += " (per-volt model: N m read as V)"
    return f"{ps.doc} [{unit}]"


def _variable(name: str, vr: int, attrs: str, start: float | None, desc: str) -> str:
    real = "<Real/>" if start is None else f"<Real start={xml_attr(number(start, 'INF'))}/>"
    return (f'    <ScalarVariable name={xml_attr(name)} valueReference="{vr}" {attrs} '
            f"description={xml_attr(desc)}>{real}</ScalarVariable>")


def model_description(spec: ExportSpec, ident: str, guid: str, sources: list[str]) -> str:
    """The text of modelDescription.xml."""
    inp = "tau" if spec.drive == "tau" else "v"
    in_desc = {"v": "armature voltage [V]", "tau": "motor torque [N m]",
               "lumped": "voltage [V] (lumped per-volt model)"}[spec.drive]
    out_desc = {"i": "armature current [A]" + (" (not simulated: NaN)" if spec.torque_path
                                               else ""),
                "omega": "speed as the sensor reads it [rad/s]",
                "theta": "angle as the sensor reads it [rad]"}
    rows = [_variable(inp, INPUT_VR, 'causality="input" variability="continuous"', 0.0, in_desc)]
    rows += [_variable(n, vr, 'causality="output" variability="continuous" initial="calculated"',
                       None, out_desc[n]) for n, vr in OUTPUT_VRS.items()]
    rows += [_variable(n, PARAM_VR + k, 'causality="parameter" variability="fixed" '
                       'initial="exact"', v, _describe(n, spec))
             for k, (n, v) in enumerate(parameters(spec).items())]
    files = "\n".join(f"      <File name={xml_attr(f)}/>" for f in sources)
    outputs = "\n".join(f'      <Unknown index="{k}"/>' for k in (2, 3, 4))
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<!-- {MARKER} from {_NOT_XML.sub("?", spec.source).replace("--", "- -").rstrip("-")} -->
<fmiModelDescription fmiVersion="2.0" modelName={xml_attr(ident)} guid={xml_attr(guid)}
  description="Permanent-magnet DC motor identified by pmdcid (exact model of pmdcid simulate)"
  generationTool="pmdcid export" variableNamingConvention="flat" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier={xml_attr(ident)} canHandleVariableCommunicationStepSize="true"
    canBeInstantiatedOnlyOncePerProcess="false" canNotUseMemoryManagementFunctions="true"
    canGetAndSetFMUstate="false" canSerializeFMUstate="false"
    providesDirectionalDerivative="false">
    <SourceFiles>
{files}
    </SourceFiles>
  </CoSimulation>
  <DefaultExperiment startTime="0" stepSize="0.001"/>
  <ModelVariables>
{chr(10).join(rows)}
  </ModelVariables>
  <ModelStructure>
    <Outputs>
{outputs}
    </Outputs>
    <InitialUnknowns>
{outputs}
    </InitialUnknowns>
  </ModelStructure>
</fmiModelDescription>
"""


def wrapper(spec: ExportSpec, ident: str, guid: str) -> str:
    """The FMI 2.0 wrapper's C source."""
    refs = "\n".join(f"    case {PARAM_VR + k}: return &p->{n};"
                     for k, n in enumerate(parameters(spec)))
    return fill(template("fmi2.c.tmpl"), {"MARKER": MARKER.capitalize(),
                                          "SOURCE": c_comment(spec.source), "ID": ident,
                                          "GUID": c_string(guid), "PARAM_REFS": refs})


def sources(spec: ExportSpec, ident: str, guid: str) -> dict[str, str]:
    """sources/ of the FMU: file name -> text."""
    safe = dataclasses.replace(spec, source=c_comment(spec.source))
    model_c, model_h = render_c(safe, "pmdc_model.h")
    out = {"fmi2.c": wrapper(spec, ident, guid), "pmdc_model.c": model_c,
           "pmdc_model.h": model_h}
    out.update({h: template(h) for h in HEADERS})
    out["FMI2_LICENSE.txt"] = template("FMI2_LICENSE.txt")
    return out


def platform_folder() -> tuple[str, str]:
    """(binaries/ folder name, shared library suffix) of this machine (FMI 2.0 names)."""
    bits = "64" if sys.maxsize > 2**32 else "32"
    if sys.platform.startswith("linux"):
        return "linux" + bits, ".so"
    if sys.platform == "darwin":
        return "darwin" + bits, ".dylib"
    raise ExportError(f"building an FMU binary on {platform.system()} is not supported "
                      "(linux and macOS are)")


def compiler() -> str:
    """The system C compiler: $CC, cc or gcc (ExportError when none is found)."""
    for name in (os.environ.get("CC", ""), "cc", "gcc"):
        found = shutil.which(name) if name else None
        if found:
            return found
    raise ExportError("no C compiler found (cc or gcc, or $CC): the FMU's binary is compiled "
                      "at export time; install one (e.g. apt install gcc)")


def compile_binary(files: dict[str, str], ident: str, suffix: str) -> bytes:
    """The shared library built from ``files`` by the system C compiler."""
    cc = compiler()
    with tempfile.TemporaryDirectory(prefix="pmdcid-fmu-") as tmp:
        for name, text in files.items():
            Path(tmp, name).write_text(text)
        lib = Path(tmp, ident + suffix)
        cmd = [cc, "-std=c99", "-O2", "-shared", "-fPIC", "-fvisibility=hidden", "-o", str(lib),
               "fmi2.c", "pmdc_model.c", "-lm"]
        try:
            res = subprocess.run(cmd, cwd=tmp, capture_output=True, text=True, timeout=300)
        except (OSError, subprocess.TimeoutExpired) as exc:
            raise ExportError(f"the C compiler {cc} could not run: {exc}") from None
        if res.returncode != 0:
            first = (res.stderr.strip().splitlines() or ["no message"])[0]
            raise ExportError(f"the C compiler {cc} failed on the FMU's sources: {first}")
        return lib.read_bytes()


def guid_of(spec: ExportSpec, ident: str) -> str:
    """A GUID from the model's content: the same model and name give the same GUID."""
    h = hashlib.sha256(repr((sorted(parameters(spec).items()), spec.drive, ident)).encode())
    d = h.hexdigest()
    return f"{{{d[:8]}-{d[8:12]}-{d[12:16]}-{d[16:20]}-{d[20:32]}}}"


def _entry(name: str) -> zipfile.ZipInfo:
    info = zipfile.ZipInfo(name, date_time=ZIP_DATE)
    info.external_attr = 0o644 << 16
    return info


def build(spec: ExportSpec, stem: str) -> bytes:
    """The FMU's bytes. modelDescription.xml is its first entry, stored uncompressed, so the
    file starts with the generated-by line (how export recognises a file it may overwrite)."""
    ident = model_identifier(stem)
    guid = guid_of(spec, ident)
    folder, suffix = platform_folder()
    files = sources(spec, ident, guid)
    binary = compile_binary(files, ident, suffix)
    desc = model_description(spec, ident, guid, ["fmi2.c", "pmdc_model.c"])
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        zf.writestr(_entry("modelDescription.xml"), desc, compress_type=zipfile.ZIP_STORED)
        for name, text in files.items():
            zf.writestr(_entry("sources/" + name), text, compress_type=zipfile.ZIP_DEFLATED)
        lib = _entry(f"binaries/{folder}/{ident}{suffix}")
        lib.external_attr = 0o755 << 16
        zf.writestr(lib, binary, compress_type=zipfile.ZIP_DEFLATED)
    return buf.getvalue()
