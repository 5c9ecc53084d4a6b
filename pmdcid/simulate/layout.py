"""Layout of the flat parameter vector the compiled kernel reads."""

NAMES = (
    "R", "L", "km", "ke", "J", "bv", "bc", "dz", "dz_slope", "dz_offset",
    "fs", "ws", "bq", "tau0", "ca", "cn", "cphi", "vmax", "vb", "dbv",
    "latency",
)
(R, L, KM, KE, J, BV, BC, DZ, DZ_SLOPE, DZ_OFFSET,
 FS, WS, BQ, TAU0, CA, CN, CPHI, VMAX, VB, DBV,
 LATENCY) = range(len(NAMES))
#: read by the caller, not by the compiled kernel: the input is delayed before it (simulate/drive)
INPUT_NAMES = ("latency",)
INDEX = {n: k for k, n in enumerate(NAMES)}
#: sensor parameters, applied to the kernel's output (not inside the kernel)
SENSOR_NAMES = ("delay", "omega0")
