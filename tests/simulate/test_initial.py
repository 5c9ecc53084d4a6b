"""The start a simulation takes from a log (pmdcid/simulate/initial.py) is one rule for the
fits, diagnose, the report and `simulate --x0 measured`: the model a user simulates from a
moving start reproduces what diagnose judged, sensor effects included."""

from __future__ import annotations

import numpy as np

from pmdcid.diagnose.residuals import error_table
from pmdcid.files import simulate_file
from pmdcid.fit.problem import Problem
from pmdcid.io import read_log, write_log
from pmdcid.simulate import param_values
from pmdcid.synth import NoiseSpec, synth_log, truth_model

VALS = {"R": 1.0, "L": 2e-3, "km": 0.05, "ke": 0.05, "J": 5e-4, "bv": 1e-5, "bc": 2e-3,
        "dz": 3e-3, "delay": 0.02, "omega0": 3.0}
EFFECTS = ["back_emf", "sensor_delay", "speed_offset"]


def test_simulate_from_measured_start_reproduces_diagnose(tmp_path):
    rng = np.random.default_rng(5)
    model = truth_model(VALS, EFFECTS)
    model_path = tmp_path / "m.json"
    model.save(model_path)
    vals = param_values(model)
    t = np.arange(0.0, 3.0, 1e-3)
    u = np.where(t >= 1.0, 12.0, 6.0)
    w0 = 6.0 * 0.05 / (0.05 * 0.05 + 1e-5)  # turning at the first sample
    cols, _ = synth_log(t, u, vals, NoiseSpec(i=0.01, omega=0.3), rng,
                        x0=np.array([0.0, w0, 0.0]))
    write_log(tmp_path / "log.csv", t, cols)
    log = read_log(tmp_path / "log.csv")
    problem = Problem([log], 0.6, 20000, ["fit"])
    judged = error_table(problem, problem.simulate_all(vals))[0]
    simulate_file(tmp_path / "log.csv", model_path, tmp_path / "sim.csv", x0="measured")
    sim = read_log(tmp_path / "sim.csv")
    meas = log["omega"]
    nrmse = float(np.sqrt(np.mean((sim["omega"] - meas) ** 2)) / np.std(meas))
    assert abs(nrmse - judged["omega"]) <= 0.02 * judged["omega"], (nrmse, judged)
    # the speed sensor's bias is in the reading, not in the rotor: the start is taken back by it
    assert abs(sim["omega"][0] - np.mean(meas[:5])) < 0.5
