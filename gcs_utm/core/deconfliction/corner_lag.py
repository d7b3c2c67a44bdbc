"""A multirotor's plan as flown late: the time each corner costs, added up.

A mission carries no time: the autopilot flies each leg at its speed and changes its
velocity at each waypoint with a bounded horizontal acceleration ``A``. Changing the velocity
by ``dv`` (``|V_out - V_in|``, horizontal: ``2 v sin(a / 2)`` for a turn by ``a`` at a
constant speed ``v``, ``v`` to brake for a hold) at a constant acceleration takes ``dv / A``
and costs about half of it, ``dv / (2 A)``, against a plan that turns on the point; the
vehicle never makes it up. The envelope's tracking tolerance (5 m for a multirotor) covers
one sharp corner; the lag adds up corner after corner: on a lateral deformation at 9.3-10.4
m/s with turns of 27, 54 and 27 degrees the built-in multirotor flew 12.8 m behind its plan
after the first turn and 23 m from it in the second, and passed another UAS at 48.8 m that
the plan kept at 60.8 m (minimum 50 m plus both tolerances). Its plan delayed by these
losses (1.0 s, then 1.9 s more, at ``A`` = 2.5 m/s^2) stays within 4-11 m of its track and
comes 48.5 m from the other UAS.

:func:`lagged` gives that delayed plan (same points, each waypoint later by the losses of
the corners before it) for TD to verify besides the plan itself. Pure.
"""

from __future__ import annotations

import numpy as np

from gcs_utm.core.deconfliction.geometry import LocalPlan

MIN_LAG_S = 0.1
"""A plan that loses less than this in all is flown on time: nothing more to check."""


def corner_losses_s(lp: LocalPlan, accel_mps2: float) -> np.ndarray:
    """Per waypoint of ``lp``: the time lost at it (0 at the first and the last)."""
    out = np.zeros(len(lp))
    if len(lp) < 3 or accel_mps2 <= 0.0:
        return out
    dt = np.maximum(np.diff(lp.t), 1e-9)
    vel = np.column_stack((np.diff(lp.e) / dt, np.diff(lp.n) / dt))  # per leg, m/s
    dv = np.hypot(*(vel[1:] - vel[:-1]).T)
    out[1:-1] = dv / (2.0 * accel_mps2)
    return out


def lagged(lp: LocalPlan, accel_mps2: float) -> LocalPlan | None:
    """``lp`` with each waypoint later by the losses of the corners before it and at it (see
    the module doc); None when it loses less than :data:`MIN_LAG_S` in all."""
    delay = np.cumsum(corner_losses_s(lp, accel_mps2))
    if len(lp) < 3 or float(delay[-1]) < MIN_LAG_S:
        return None
    return LocalPlan(lp.e, lp.n, lp.z, lp.t + delay)
