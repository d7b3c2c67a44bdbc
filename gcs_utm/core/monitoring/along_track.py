"""Along-track timing of conformance: the part of a plan a UAS may be on now.

Conformance compares a UAS's position with the part of its plan flown within
``conformance_time_tolerance_s`` of now. A fixed wing does not keep a schedule by waiting:
it flies its own cruise airspeed anywhere in its envelope (ArduPlane flew its 22 m/s cruise
on a plan filed at 14 m/s), so it is ahead of (or behind) its plan by a time that grows
along the track. Sent back to its schedule it would be non-conformant again at once (a
back-to-plan upload about every 2 s). So for a vehicle that cannot hover the plan is
re-timed to the progress its envelope allows: since the plan's start it may have flown at
any speed from ``min_speed_mps`` to ``max_speed_mps`` relative to the plan's own mean speed,
so the plan time it may be at now lies in

    [t0 + elapsed * min(1, v_min / v_plan) - tol,  t0 + elapsed * max(1, v_max / v_plan) + tol]

and it stays conformant while it is on that part of the track laterally and vertically. A
multirotor (it can hover: it keeps its schedule) keeps ``[t - tol, t + tol]``. Pure.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np

from gcs_utm.core.monitoring.geometry import FloatArray
from gcs_utm.model import FlightPlan, Operation

_MIN_LEG_M = 0.5  # shorter legs are holds, not progress
_EARTH_RADIUS_M = 6_371_008.8


def plan_speed_mps(plan: FlightPlan) -> float | None:
    """The plan's mean speed over its moving legs (3D length / time), None without one."""
    length = duration = 0.0
    for a, b in itertools.pairwise(plan.waypoints):
        lat = math.radians((a.lat_deg + b.lat_deg) / 2.0)
        north = math.radians(b.lat_deg - a.lat_deg) * _EARTH_RADIUS_M
        east = math.radians(b.lon_deg - a.lon_deg) * _EARTH_RADIUS_M * math.cos(lat)
        d = math.sqrt(east * east + north * north + (b.alt_amsl_m - a.alt_amsl_m) ** 2)
        dt = b.t_s - a.t_s
        if d >= _MIN_LEG_M and dt > 0.0:
            length, duration = length + d, duration + dt
    return length / duration if duration > 0.0 else None


def progress_ratios(ops: Sequence[Operation]) -> tuple[FloatArray, FloatArray]:
    """Per operation, the slowest and fastest progress along its plan relative to the plan's
    own timing (1, 1 for a vehicle that can hover or a plan that does not move)."""
    lo = np.ones(len(ops))
    hi = np.ones(len(ops))
    for k, op in enumerate(ops):
        env = op.performance()
        speed = plan_speed_mps(op.plan)
        if env.can_hover or speed is None:
            continue
        lo[k] = min(1.0, env.min_speed_mps / speed)
        hi[k] = max(1.0, env.max_speed_mps / speed)
    return lo, hi


def plan_time_window(
    t_s: FloatArray,
    start_s: FloatArray,
    ratio_lo: FloatArray,
    ratio_hi: FloatArray,
    tolerance_s: float,
) -> tuple[FloatArray, FloatArray]:
    """(earliest, latest) plan time (per row) a UAS may be at at ``t_s``: see the module
    docstring."""
    elapsed = np.maximum(t_s - start_s, 0.0)
    early = np.minimum(start_s + elapsed * ratio_lo, t_s)
    late = np.maximum(start_s + elapsed * ratio_hi, t_s)
    return early - tolerance_s, late + tolerance_s
