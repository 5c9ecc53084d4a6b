"""LuGre dynamic friction (catalogue effect ``lugre``, kernel state z) by round trip.

The paper's motor (Table II J, bv, bc) driven by torque, bristles sized for a presliding
displacement of 1 mrad at the breakaway torque (sigma0 = bc / 1e-3 rad). The quasi-static
references follow from dz/dtheta = 1 - sigma0 z sign(omega)/g, friction sigma0 z (inertia,
damping and bv negligible for slow inputs):
- loading from rest to T < g:  theta = -(g/sigma0) ln(1 - T/g)            (~ T/sigma0)
- unloading back to 0:         theta left = -(g/sigma0) ln(1 - (T/g)^2)   (second order)
- a cycle +-T:                 loop area = 4 (g^2/sigma0) (atanh(T/g) - T/g)
"""

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from pmdcid.fit.parameters import Parameters
from pmdcid.fit.simfit import FitOptions, fit_simulation
from pmdcid.io import Log
from pmdcid.model import EFFECTS, load_model
from pmdcid.simulate import neutral_values, param_values, param_vector, simulate_values
from pmdcid.simulate.kernel import run_kernel
from pmdcid.simulate.layout import NSTATE, STATE_OWNERS, STATES, Z_STATE
from pmdcid.simulate.substeps import choose_substeps, lugre_step
from pmdcid.synth import PAPER, truth_model

J, BV, BC = PAPER["J"], PAPER["bv"], PAPER["bc"]
SIGMA0 = BC / 1e-3  # [N m/rad] 1 mrad of presliding at the breakaway torque
SIGMA1 = 0.6 * math.sqrt(SIGMA0 * J)  # [N m s/rad] presliding damping ratio 0.3
BASE = {"J": J, "bv": BV, "bc": BC}
DT = 1e-3


def lugre_vals(**over) -> dict[str, float]:
    return {**neutral_values(), **BASE, "sigma0": SIGMA0, "sigma1": SIGMA1, **over}


def run(u, vals, nsub=None):
    return run_kernel(u, DT, param_vector(vals), True, nsub)


def test_layout_declares_the_bristle_state():
    assert STATES[:3] == ("i", "omega", "theta") and STATES[Z_STATE] == "z"
    assert STATE_OWNERS == {"z": "lugre"} and EFFECTS["lugre"].states == ("z",)
    assert run(np.zeros(5), lugre_vals()).shape == (5, NSTATE)


def test_lugre_off_leaves_the_stick_slip_kernel_unchanged():
    """sigma0 = 0 (neutral): z is not integrated and sigma1 does nothing, so a model listing
    lugre at neutral, or with sigma1 alone, simulates exactly as one without it."""
    t = np.arange(20000) * DT
    u = 2.0 * np.sin(0.7 * t) + 0.5 * np.sign(np.sin(3 * t))
    plain = {**neutral_values(), **PAPER}
    ref = run_kernel(u, DT, param_vector(plain), False)
    for over in ({"sigma0": 0.0, "sigma1": 0.0}, {"sigma0": 0.0, "sigma1": 0.3}):
        got = run_kernel(u, DT, param_vector({**plain, **over}), False)
        np.testing.assert_array_equal(got, ref)
    assert np.all(ref[:, Z_STATE] == 0.0) and np.ptp(ref[:, 2]) > 1.0
    m = truth_model({**PAPER, "sigma0": 0.0}, ["lugre"])
    assert param_values(m)["sigma0"] == 0.0
    # not in the model's effects: its values are held neutral even if the file has them
    assert param_values(truth_model({**PAPER, "sigma0": SIGMA0}))["sigma0"] == 0.0


def test_presliding_displacement_is_torque_over_sigma0_and_reversible():
    t = np.arange(int(12 / DT)) * DT
    T = 0.1 * BC
    u = np.interp(t, [0, 1, 4, 5, 12], [0, T, T, 0, 0])
    x = run(u, lugre_vals(sigma1=2 * math.sqrt(SIGMA0 * J)))  # no ringing after the ramps
    g = BC
    held = x[int(3.9 / DT), 2]
    assert held == pytest.approx(-(g / SIGMA0) * math.log(1 - T / g), rel=1e-3)
    assert held == pytest.approx(T / SIGMA0, rel=0.06)
    # unloaded: springs back but for the second-order part the bristles slid
    assert x[-1, 2] == pytest.approx(-(g / SIGMA0) * math.log(1 - (T / g) ** 2), rel=1e-2)
    assert x[-1, 2] < 0.11 * held
    assert np.all(np.abs(x[:, 1]) < 1e-3)  # presliding, no sliding speed
    # the stick-slip model does not move at all below breakaway
    assert np.all(run(u, lugre_vals(sigma0=0.0))[:, 2] == 0.0)


def test_small_reversal_has_the_lugre_hysteresis_loop():
    t = np.arange(int(60 / DT)) * DT
    r = 0.5
    u = r * BC * np.sin(2 * np.pi * 0.05 * t)
    x = run(u, lugre_vals(sigma1=0.01))
    sel = t >= 20.0  # two whole periods after the first loading
    th = x[sel, 2]
    area = np.sum(0.5 * (u[sel][1:] + u[sel][:-1]) * np.diff(th)) / 2
    assert area == pytest.approx(4 * BC**2 / SIGMA0 * (math.atanh(r) - r), rel=0.03)
    assert np.ptp(th) == pytest.approx(2 * BC / SIGMA0 * math.atanh(r), rel=0.03)


def static_speed(T: float, vals: dict[str, float]) -> float:
    """Root of T = g(omega) sign(omega) + bv omega, g = bc + fs exp(-(omega/ws)^2)."""
    def net(w):
        g = vals["bc"] + vals["fs"] * math.exp(-(w / vals["ws"]) ** 2)
        return T - math.copysign(g, T) - vals["bv"] * w

    return brentq(net, 1e-12 * math.copysign(1, T), 10 * T / vals["bv"])


@pytest.mark.parametrize("T", [1.6 * BC, -6.0 * BC, 20.0 * BC])
def test_steady_state_is_the_static_friction_curve(T):
    vals = lugre_vals(fs=0.5 * BC, ws=0.05)  # with Stribeck friction on the curve
    u = np.full(int(3 / DT), T)
    x = run(u, vals)
    w = static_speed(T, vals)
    assert x[-1, 1] == pytest.approx(w, rel=1e-6)
    assert x[-1, Z_STATE] == pytest.approx(math.copysign(BC + 0.5 * BC * math.exp(
        -(w / 0.05) ** 2), T) / SIGMA0, rel=1e-6)
    assert run(u, {**vals, "sigma0": 0.0})[-1, 1] == pytest.approx(w, rel=1e-6)


def test_voltage_driven_with_dead_zone_reaches_the_same_steady_state():
    """Voltage-driven paper motor with its dead zone: the bristles change the transients, not
    the plateau; below the dead zone no torque passes and the rotor stays put."""
    vals = {**neutral_values(), **PAPER, "sigma0": SIGMA0, "sigma1": SIGMA1}
    for v, moves in ((2.0, True), (0.2, False)):
        u = np.full(int(4 / DT), v)
        lug = run_kernel(u, DT, param_vector(vals), False)
        ref = run_kernel(u, DT, param_vector({**vals, "sigma0": 0.0}), False)
        if moves:
            assert lug[-1, 1] == pytest.approx(ref[-1, 1], rel=1e-6) and ref[-1, 1] > 1.0
        else:
            assert PAPER["km"] * v / PAPER["R"] < PAPER["dz"]
            assert np.all(lug[:, 1] == 0.0) and np.all(ref[:, 1] == 0.0)


def test_stiff_bristles_are_stable_and_converge():
    """Presliding of 0.1 um-rad: the step bound sqrt(J/sigma0)/20 takes many substeps, the
    bristle state is stepped exactly; halving the step changes the result by little."""
    s0 = BC / 1e-7
    vals = lugre_vals(sigma0=s0, sigma1=2 * math.sqrt(s0 * J))
    p = param_vector(vals)
    nsub = choose_substeps(DT, p)
    assert DT / nsub <= lugre_step(p) and nsub > 100
    t = np.arange(int(4 / DT)) * DT
    u = np.where(t < 3.0, 3 * BC, -0.5 * BC)
    a = run(u, vals)
    b = run(u, vals, 2 * nsub)
    assert np.all(np.isfinite(a))
    assert a[int(2.99 / DT), 1] == pytest.approx(static_speed(3 * BC, vals), rel=1e-6)
    assert np.max(np.abs(a[:, 1] - b[:, 1])) < 1e-3 * np.max(np.abs(a[:, 1]))
    assert abs(a[-1, 2] - b[-1, 2]) < 1e-4 * np.ptp(a[:, 2])


def staircase_log(rng, truth, sd, name="stair.csv", seconds=10.0):
    """Torque levels held 0.5 s, within +-1.3 bc (presliding and sliding), angle with noise."""
    t = np.arange(int(seconds / DT)) * DT
    u = np.repeat(rng.uniform(-1.3, 1.3, int(seconds / 0.5)) * BC, int(0.5 / DT))
    sim = simulate_values(t, u, {**neutral_values(), **truth}, True)
    return Log.from_arrays(t, name=name, tau=u, theta=sim.theta + rng.normal(0, sd, len(t)))


@pytest.mark.parametrize("seed", [0, 1])
def test_fit_round_trip_sigma0_sigma1(seed):
    """Angle at 1 kHz with 30 urad noise (a 16-bit encoder's quantisation): sigma0, sigma1 and bc
    from a start 2x off come back within 4 standard errors and 2 %."""
    rng = np.random.default_rng(seed)
    truth = {**BASE, "sigma0": SIGMA0, "sigma1": SIGMA1}
    sd = 3e-5
    log = staircase_log(rng, truth, sd)
    start = {"sigma0": 2 * SIGMA0, "sigma1": 0.5 * SIGMA1, "bc": 1.2 * BC}
    res = fit_simulation([log], truth_model(truth, ["lugre"]), Parameters.of(start, start),
                         signals=("theta",), sigma=[{"theta": sd}],
                         options=FitOptions(initial=False))
    assert res.stats.redchi == pytest.approx(1.0, abs=0.1)
    for name, est in res.estimates.items():
        assert 0 < est.stderr < 0.02 * truth[name]
        assert abs(est.value - truth[name]) < 4 * est.stderr, (name, est)
        assert est.value == pytest.approx(truth[name], rel=0.02)


def test_model_file_round_trip(tmp_path):
    m = truth_model({**BASE, "fs": 0.5 * BC, "ws": 0.05, "sigma0": SIGMA0, "sigma1": SIGMA1},
                    ["stribeck", "lugre"])
    m.save(tmp_path / "m.json")
    back = load_model(tmp_path / "m.json")
    assert back.effects == ["stribeck", "lugre"]
    assert back.value("sigma0") == SIGMA0 and back.value("sigma1") == SIGMA1
    assert param_values(back, True) == param_values(m, True)


def test_export_takes_lugre(tmp_path):
    """The exporters step the bristles themselves (agreement with the kernel:
    tests/export/test_ports.py, tests/system/test_export_native.py): sigma0, sigma1 are in the
    exported
    values and in the generated C."""
    from click.testing import CliRunner

    from pmdcid.cli import main
    from pmdcid.export import spec_of

    m = truth_model({**BASE, "sigma0": SIGMA0, "sigma1": SIGMA1}, ["lugre"])
    vals = spec_of(m).values
    assert vals["sigma0"] == SIGMA0 and vals["sigma1"] == SIGMA1
    m.save(tmp_path / "m.json")
    res = CliRunner().invoke(main, ["export", "-m", str(tmp_path / "m.json"), "--to", "c",
                                    "-o", str(tmp_path / "motor.c")])
    assert res.exit_code == 0, res.output
    assert f"p->sigma0 = {SIGMA0!r};" in (tmp_path / "motor.c").read_text()


@pytest.mark.slow
def test_diagnose_names_lugre_only_when_asked():
    """``--effect lugre`` on presliding logs names it and refits sigma0 near the truth; on the
    same protocol without bristles it adds nothing; by default lugre is not screened."""
    import pmdcid

    assert not EFFECTS["lugre"].screened
    rng = np.random.default_rng(5)
    truth = {**BASE, "sigma0": SIGMA0, "sigma1": SIGMA1}
    logs = [staircase_log(rng, truth, 3e-5, f"stair_{k}.csv") for k in (1, 2)]
    res = pmdcid.diagnose(logs, truth_model(BASE), effects=["lugre"])
    assert res.summary["added"] == ["lugre"]
    s0 = res.model.parameters["sigma0"]
    assert abs(s0.value - SIGMA0) < 4 * s0.stderr and s0.value == pytest.approx(SIGMA0, rel=0.05)
    clean = [staircase_log(rng, BASE, 3e-5, f"stair_{k}.csv") for k in (1, 2)]
    assert pmdcid.diagnose(clean, truth_model(BASE), effects=["lugre"]).summary["added"] == []
    default = pmdcid.diagnose(clean, truth_model(BASE))
    assert default.summary["added"] == []
    assert "lugre" not in [c["effect"] for c in default.summary["candidates"]]


def test_absurd_bristle_stiffness_is_one_clear_error():
    from pmdcid.simulate.substeps import WorkBoundError

    vals = lugre_vals(sigma0=1e12, sigma1=0.0)
    with pytest.raises(WorkBoundError, match="LuGre's bristles"):
        run(np.zeros(100000), vals)
