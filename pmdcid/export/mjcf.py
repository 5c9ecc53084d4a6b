"""``export --to mujoco``: an MJCF model (MuJoCo's XML) of the identified motor.

One body ``rotor`` (inertia J about z) on one hinge joint ``shaft`` (axis z, damping = bv,
frictionloss = bc), driven by one actuator named ``motor`` whose control is the voltage [V] (the
torque [N m] for a torque-driven model, the per-volt input for a lumped one):

- a voltage model with back-EMF (ke > 0): MuJoCo's ``dcmotor`` (cogging, LuGre, ctrlrange =
  +-vmax). dcmotor has one motor constant K for torque and back-EMF (two given: their geometric
  mean), so the motor is written in its exact equivalent with K = ke: resistance R ke/km,
  inductance L ke/km, its current ``data.act`` = (km/ke) i, which gives torque K (km/ke) i = km i
  and the back-EMF ke omega. Before, "km ke" gave K = sqrt(km ke) for both: exact only for
  km = ke, and a lumped model with a lag (km = 1, ke the back-EMF's share of bv per volt, 0.03)
  ran 7 times too slow in MuJoCo;
- a voltage model without back-EMF (the paper's): a ``general`` actuator with exact first-order
  dynamics (``filterexact``, time constant L/R) and gain km/R, because ``dcmotor`` always adds a
  back-EMF (its K is sqrt(Kt Ke), or the one given); its activation is R i [V];
- torque-driven and lumped models: a ``general`` actuator of gain 1 (torque = control).

Cogging and LuGre of a model that has no ``dcmotor`` go on a passive ``dcmotor`` named ``load``
(``input="none"``, no electrical branch); a constant load torque on a ``general`` actuator named
``torque_offset`` (gain 0, bias -tau0: its control is unused). What MuJoCo cannot represent is
mapped to its nearest element and listed by :func:`approximations` (an XML comment in the file,
lines on stdout). The XML is built with :mod:`xml.etree.ElementTree`, which escapes every
attribute; comment text is made safe for XML comments by :func:`comment_text`.
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET

from pmdcid.export import MARKER, ExportSpec
from pmdcid.simulate import neutral_values, param_vector
from pmdcid.simulate.substeps import max_step, substeps_for

#: MuJoCo options of the exported model: implicit damping, friction made hard by the no-slip
#: pass (measured: a stick at a reversal is held instead of creeping, docs/export.md)
INTEGRATOR = "implicitfast"
NOSLIP_ITERATIONS = 20
#: the friction constraint's time constant, in timesteps: the stiffest MuJoCo keeps stable (its
#: default 20 ms let a light rotor slide on through a stop: 8x the speed error measured on a
#: +-12 V sine; docs/export.md)
FRICTION_TIMECONST_STEPS = 2
#: the delay buffers (input and sensor delay) hold enough samples for a timestep down to this
#: fraction of the one written (MuJoCo reads the oldest sample when the buffer is too short)
FINEST_STEP = 1 / 64
_NOT_XML = re.compile("[^\t\n\r\x20-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")


def num(x: float) -> str:
    """A float attribute that reads back exactly."""
    return repr(float(x))


def xml_text(text: str) -> str:
    """``text`` with the characters XML 1.0 cannot hold (control characters) replaced by ``?``;
    ElementTree escapes the rest (``<``, ``&``, quotes) in attributes."""
    return _NOT_XML.sub("?", text)


def comment_text(text: str) -> str:
    """``text`` as the body of an XML comment: no ``--`` (forbidden), no trailing ``-``."""
    text = xml_text(text.replace("\r", " ").replace("\n", " "))
    while "--" in text:
        text = text.replace("--", "- -")
    return " " + text.rstrip("-") + " "


def timestep(spec: ExportSpec) -> float:
    """The kernel's internal step at a 1 ms sample [s]: min(1 ms, tau_mech/50), LuGre's bound."""
    vals = dict(neutral_values(), **spec.values)
    vals.update({n: 1.0 for n in ("R", "L", "km") if not math.isfinite(vals[n])})
    return 1e-3 / substeps_for(1e-3, max_step(param_vector(vals)))


def _on(spec: ExportSpec, *names: str) -> bool:
    neutral = neutral_values()
    return any(spec.values.get(n, neutral[n]) != neutral[n] for n in names)


def uses_dcmotor(spec: ExportSpec) -> bool:
    """The motor is MuJoCo's ``dcmotor``: a voltage model with a back-EMF."""
    return spec.drive == "v" and spec.values["ke"] > 0


def approximations(spec: ExportSpec) -> list[str]:
    """What the MJCF does not carry exactly, one line each (nearest element and what is lost)."""
    v = spec.values
    out = []
    if _on(spec, "dz", "dz_offset") or (_on(spec, "dz_slope") and uses_dcmotor(spec)):
        unit = "V (per-volt model)" if spec.per_volt else "N m"
        out.append(f"dead_zone: MuJoCo has no dead zone on the motor torque; omitted (torque "
                   f"below dz = {v['dz']:.4g} {unit} passes, not zero)")
    if _on(spec, "fs") and not _on(spec, "sigma0"):
        out.append("stribeck: no speed-dependent friction on a joint; frictionloss carries "
                   "the sliding level bc (the static peak bc + fs is lost)")
    out += _unrepresented(spec)
    if _on(spec, "cn") and _on(spec, "ca") and v["cn"] != round(v["cn"]):
        out.append(f"cogging: MuJoCo's poles are an integer: {v['cn']:.6g} rounded")
    if spec.delay > 0:
        out.append(f"sensor_delay: qpos/qvel are the rotor's; the sensors omega and theta "
                   f"read them {spec.delay:.6g} s late")
    if spec.omega0 != 0:
        out.append(f"speed_offset: not added: the speed sensor reads qvel + {spec.omega0:.6g}")
    return out


_OMITTED = {
    "bq": "quadratic_drag: no quadratic damping on a joint; omitted",
    "dbv": "viscous_asymmetry: no direction-dependent damping on a joint; omitted",
    "vb": "brush_drop: no voltage drop in dcmotor; omitted",
    "fcw4": "friction_curve: no speed-dependent friction on a joint; omitted "
            "(frictionloss carries bc)",
}


def _unrepresented(spec: ExportSpec) -> list[str]:
    return [line for name, line in _OMITTED.items() if _on(spec, name)]


def _motor(spec: ExportSpec) -> ET.Element:
    v = spec.values
    if uses_dcmotor(spec):
        scale = v["ke"] / v["km"]   # current scaled by km/ke: K = ke for both (module doc)
        el = ET.Element("dcmotor", name="motor", joint="shaft", resistance=num(v["R"] * scale),
                        motorconst=num(v["ke"]), inductance=f"{num(v['L'] * scale)} 0")
        el.attrib.update(_load_attrs(spec))
    elif spec.drive == "v":
        el = ET.Element("general", name="motor", joint="shaft", dyntype="filterexact",
                        dynprm=num(v["L"] / v["R"]),
                        gainprm=num(v["dz_slope"] * v["km"] / v["R"]))
    else:
        el = ET.Element("general", name="motor", joint="shaft", gainprm=num(v["dz_slope"]))
    if math.isfinite(v["vmax"]) and spec.drive == "v":
        el.attrib.update(ctrllimited="true", ctrlrange=f"{num(-v['vmax'])} {num(v['vmax'])}")
    if v["latency"] > 0:
        el.attrib.update(delay=num(v["latency"]), interp="zoh",
                         nsample=_nsample(v["latency"], spec))
    return el


def _nsample(delay: float, spec: ExportSpec) -> str:
    """History samples a delay of ``delay`` [s] needs at the finest timestep allowed."""
    return str(math.ceil(delay / (timestep(spec) * FINEST_STEP)) + 2)


def _load_attrs(spec: ExportSpec) -> dict[str, str]:
    """dcmotor's cogging and LuGre attributes (cogging is a load: MuJoCo adds it, sign flipped)."""
    v = spec.values
    out = {}
    if _on(spec, "ca"):
        out["cogging"] = f"{num(-v['ca'])} {round(v['cn'])} {num(v['cphi'])}"
    if _on(spec, "sigma0"):
        out["lugre"] = " ".join(num(x) for x in (v["sigma0"], v["sigma1"], v["bc"],
                                                 v["bc"] + v["fs"], v["ws"]))
    return out


def _actuators(spec: ExportSpec) -> ET.Element:
    acts = ET.Element("actuator")
    acts.append(_motor(spec))
    load = _load_attrs(spec)
    if load and not uses_dcmotor(spec):
        acts.append(ET.Element("dcmotor", name="load", joint="shaft", input="none",
                               resistance="1", motorconst="0 0", **load))
    if _on(spec, "tau0"):
        acts.append(ET.Element("general", name="torque_offset", joint="shaft", gainprm="0",
                               biastype="affine", biasprm=f"{num(-spec.values['tau0'])} 0 0"))
    return acts


def _sensors(spec: ExportSpec) -> ET.Element:
    sensors = ET.Element("sensor")
    for kind, name in (("jointvel", "omega"), ("jointpos", "theta")):
        el = ET.SubElement(sensors, kind, name=name, joint="shaft")
        if spec.delay > 0:
            el.attrib.update(delay=num(spec.delay), interp="linear",
                             nsample=_nsample(spec.delay, spec))
    return sensors


def _header(spec: ExportSpec, notes: list[str]) -> str:
    lines = [f"{MARKER.capitalize()} from {spec.source}.",
             "Permanent-magnet DC motor: body rotor (inertia J about z), hinge joint shaft "
             "(damping bv, frictionloss bc), actuator motor: data.ctrl[0] = "
             + {"v": "voltage [V]", "tau": "torque [N m]",
                "lumped": "voltage [V] (lumped per-volt model)"}[spec.drive] + ".",
             "Set option timestep to the log's sample period divided by an integer "
             "(the error is first order in it).",
             "Approximated (MuJoCo has no element for it):" if notes else "Nothing approximated."]
    lines += ["  " + n for n in notes]
    return "\n".join(comment_text(x) for x in lines)


def render(spec: ExportSpec) -> tuple[str, list[str]]:
    """(MJCF text, the approximation lines)."""
    v, notes = spec.values, approximations(spec)
    root = ET.Element("mujoco", model=xml_text(spec.source))
    root.append(ET.Comment("\n" + _header(spec, notes) + "\n"))
    ET.SubElement(root, "option", timestep=num(timestep(spec)), integrator=INTEGRATOR,
                  gravity="0 0 0", noslip_iterations=str(NOSLIP_ITERATIONS))
    body = ET.SubElement(ET.SubElement(root, "worldbody"), "body", name="rotor")
    ET.SubElement(body, "inertial", pos="0 0 0", mass="1",
                  diaginertia=" ".join([num(v["J"])] * 3))
    lugre = _on(spec, "sigma0")
    ET.SubElement(body, "joint", name="shaft", type="hinge", axis="0 0 1",
                  damping=num(v["bv"]), frictionloss=num(0.0 if lugre else v["bc"]),
                  solreffriction=f"{num(FRICTION_TIMECONST_STEPS * timestep(spec))} 1")
    root.append(_actuators(spec))
    root.append(_sensors(spec))
    ET.indent(root)
    text = ET.tostring(root, encoding="unicode")
    return f"<!-- {MARKER} -->\n" + text + "\n", notes
