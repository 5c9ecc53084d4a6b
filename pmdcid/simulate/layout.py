"""Layout of the compiled kernel: its flat parameter vector and its state vector.

Parameters: :data:`NAMES` (slots, checked against the registry at import). States:
:data:`STATES`, the base three (i, omega, theta) then the states owned by catalogue effects
(:data:`STATE_OWNERS`). An effect state is integrated by the kernel only while its effect is on;
off, it stays at its starting value (0) and every other state is bit-for-bit what the 3-state
kernel gave. New parameters and states are APPENDED (never reordered).
"""

import numpy as np

NAMES = (
    "R", "L", "km", "ke", "J", "bv", "bc", "dz", "dz_slope", "dz_offset",
    "fs", "ws", "bq", "tau0", "ca", "cn", "cphi", "vmax", "vb", "dbv",
    "fcw1", "fcw2", "fcw3", "fcw4", "fc1", "fc2", "fc3",
    "latency", "sigma0", "sigma1",
)
(R, L, KM, KE, J, BV, BC, DZ, DZ_SLOPE, DZ_OFFSET,
 FS, WS, BQ, TAU0, CA, CN, CPHI, VMAX, VB, DBV,
 FCW1, FCW2, FCW3, FCW4, FC1, FC2, FC3,
 LATENCY, SIGMA0, SIGMA1) = range(len(NAMES))
#: friction_curve: knot speeds [rad/s] FCW1..FCW4 and the values [N m] FC1..FC3 at the first
#: three (consecutive); the curve is 0 at omega = 0 and at the last knot speed
CURVE_KNOTS = 4
INDEX = {n: k for k, n in enumerate(NAMES)}
#: sensor parameters, applied to the kernel's output (not inside the kernel)
SENSOR_NAMES = ("delay", "omega0")
#: parameter slots the exact linear discretisation (Phi, Gamma) depends on: caches key on them
LINEAR = (R, L, KE, KM, J, BV, DZ_SLOPE, SIGMA0, SIGMA1)

#: the kernel's state vector: armature current [A], speed [rad/s], angle [rad], then effect states
STATES = ("i", "omega", "theta", "z")
I_STATE, OMEGA_STATE, THETA_STATE, Z_STATE = range(len(STATES))
#: state name -> the catalogue effect that owns it (integrated only while the effect is on)
STATE_OWNERS = {"z": "lugre"}
NSTATE = len(STATES)


def state_vector(x0=None) -> np.ndarray:
    """The kernel's full starting state from ``x0`` (default rest): a base-state triple
    (i [A], omega [rad/s], theta [rad]) or a full vector; missing effect states start at 0."""
    x = np.zeros(NSTATE)
    if x0 is not None:
        a = np.asarray(x0, dtype=float).ravel()
        x[:len(a)] = a[:NSTATE]
    return x
