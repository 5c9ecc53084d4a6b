"""Layout of the flat parameter vector the compiled kernel reads."""

NAMES = (
    "R", "L", "km", "ke", "J", "bv", "bc", "dz", "dz_slope", "dz_offset",
    "fs", "ws", "bq", "tau0", "ca", "cn", "cphi", "vmax", "vb", "dbv",
    "fcw1", "fcw2", "fcw3", "fcw4", "fc1", "fc2", "fc3",
    "latency",
)
(R, L, KM, KE, J, BV, BC, DZ, DZ_SLOPE, DZ_OFFSET,
 FS, WS, BQ, TAU0, CA, CN, CPHI, VMAX, VB, DBV,
 FCW1, FCW2, FCW3, FCW4, FC1, FC2, FC3,
 LATENCY) = range(len(NAMES))
#: friction_curve: knot speeds [rad/s] FCW1..FCW4 and the values [N m] FC1..FC3 at the first
#: three (consecutive); the curve is 0 at omega = 0 and at the last knot speed
CURVE_KNOTS = 4
#: read by the caller, not by the compiled kernel: the input is delayed before it (simulate/drive)
INPUT_NAMES = ("latency",)
INDEX = {n: k for k, n in enumerate(NAMES)}
#: sensor parameters, applied to the kernel's output (not inside the kernel)
SENSOR_NAMES = ("delay", "omega0")
