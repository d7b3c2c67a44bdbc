"""The safety floor does not refuse a plan for where its UAS already is. A fixed wing sent
down to the floor (descend in place) flies it within its tracking error, a few centimetres
below; every plan then made for it starts there and was dropped ("waypoint 0 at 685.0 m
AMSL, below the safety floor 685.0 m"), so a geofence conflict got no alternative at all
(enc_7_0010_crossing, UAS4)."""

from __future__ import annotations

import numpy as np

from gcs_utm.core.deconfliction.geometry import LocalPlan
from gcs_utm.core.deconfliction.safety import floor_flags

FILED = LocalPlan(
    np.array([0.0, 1000.0]), np.array([0.0, 0.0]), np.array([740.0, 740.0]), np.array([0.0, 50.0])
)


def _plan(*z: float) -> LocalPlan:
    k = len(z)
    return LocalPlan(
        np.linspace(200.0, 400.0, k), np.full(k, 50.0), np.array(z), np.linspace(10.0, 30.0, k)
    )


def test_a_plan_starting_just_below_the_floor_may_stay_there() -> None:
    assert floor_flags(_plan(684.97, 684.97, 684.97), FILED, 685.0, lands=False) == []
    assert floor_flags(_plan(684.97, 700.0, 720.0), FILED, 685.0, lands=False) == []


def test_a_plan_going_lower_than_its_start_and_the_floor_is_refused() -> None:
    flags = floor_flags(_plan(684.97, 680.0, 684.97), FILED, 685.0, lands=False)
    assert flags and "waypoint 1 at 680.0 m AMSL" in flags[0]
    flags = floor_flags(_plan(700.0, 690.0, 684.0), FILED, 685.0, lands=False)
    assert flags and "waypoint 2" in flags[0]


def test_a_plan_starting_well_below_the_floor_is_still_refused() -> None:
    """The allowance is the tracking error only: a reroute 5 m under the floor (home 95 m,
    floor 105 m, flying at 100 m) is refused, as before."""
    flags = floor_flags(_plan(680.0, 680.0, 680.0), FILED, 685.0, lands=False)
    assert flags and "below the safety floor 685.0 m" in flags[0]
