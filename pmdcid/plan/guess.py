"""A first experiment without a model: small steps and a slow ramp, safe at any motor.

Inputs stay at fractions of the rig's limit (steps at 10, 20 and 30 %, a ramp to 50 %), each held
long enough for an unknown mechanical time constant up to about a second to settle. The logs
give a first model (fit-electrical, fit-mechanical, fit-nonlinear); plan with it for the full
experiment.
"""

from __future__ import annotations

import math

from pmdcid.plan import fisher as fi
from pmdcid.plan import profiles as pr
from pmdcid.plan.design import Plan, Settings

#: step amplitudes (fractions of the input limit), hold [s]; ramp top (fraction), length [s]
STEP_FRACTIONS = (0.1, 0.2, 0.3)
STEP_HOLD = 2.0
RAMP_TOP = 0.5
RAMP_SECONDS = 20.0
#: blocked-rotor step: fraction of the limit, electrical time constant assumed [s]
BLOCKED_FRACTION = 0.3
BLOCKED_TE = 0.01
#: --guess never records more than this [s]
GUESS_BUDGET = 45.0


def guess_plan(settings: Settings) -> Plan:
    """Profiles of a short, safe first experiment; nothing predicted (no model yet)."""
    drive = fi.drive_of(None, settings.taumax)
    umax, rate = float(settings.umax), settings.rate
    budget = min(settings.budget, GUESS_BUDGET)
    profiles = []
    if drive.electrical:
        u = pr.blocked_step(BLOCKED_FRACTION * umax, BLOCKED_TE, rate)
        profiles.append(pr.make("01_blocked", "blocked", u, rate, blocked=True))
    hold = min(STEP_HOLD, budget / (4 * len(STEP_FRACTIONS) + 1 + 2 * RAMP_SECONDS / STEP_HOLD))
    u = pr.small_steps([f * umax for f in STEP_FRACTIONS], hold, rate)
    profiles.append(pr.make(f"{len(profiles) + 1:02d}_small_steps", "small_steps", u, rate))
    ramp_s = max(min(RAMP_SECONDS, budget - sum(p.seconds for p in profiles)), 2.0)
    u = pr.ramp(RAMP_TOP * umax, ramp_s, rate)
    profiles.append(pr.make(f"{len(profiles) + 1:02d}_ramp", "ramp", u, rate))
    notes = ["no model: nothing is predicted. Record these, fit a first model "
             "(fit-electrical, fit-mechanical, fit-nonlinear) and run plan -m MODEL"]
    if math.isfinite(settings.speed_max):
        notes.append("--speed-max cannot be checked without a model: the inputs are fractions "
                     "of the limit (at most 50 %); watch the speed on the first run")
    return Plan(profiles, drive, [], {}, {}, {}, umax, False, settings.speed_max, notes=notes,
                guess=True)


__all__ = ["guess_plan"]
