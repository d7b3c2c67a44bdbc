"""A plan filed into an active geofence is found at filing, with the operation, the fence,
the waypoint and a proposed fix (gcs_utm/core/monitoring/filing.py, services/strategic.py)."""

from __future__ import annotations

import re
import sys
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from helpers import FRAME, cylinder, operation, polygon

from gcs_utm.core.monitoring import MonitoringConfig
from gcs_utm.core.monitoring.filing import plan_in_fences
from gcs_utm.core.monitoring.strategic import plan_vs_geofences
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.strategic import FilingCheck

T0 = 1.7e9


def test_a_destination_inside_a_fence_is_named_with_a_fix_that_clears_it() -> None:
    op = operation("A", [(-500, 0, 100, T0), (0, 0, 100, T0 + 50)])
    fire = cylinder("fire", (30.0, 0.0), 100.0)
    (f,) = plan_in_fences(op.plan, op, [fire], FRAME)
    assert (f.operation_id, f.geofence_id, f.waypoint, f.destination, f.inside) == (
        "A",
        "fire",
        1,
        True,
        True,
    )
    msg = f.message()
    assert msg.startswith("operation A plan v1: waypoint 1 (the destination) lies inside")
    assert "geofence fire" in msg and "fix: move waypoint 1 to" in msg
    # The proposed point is outside the fence and its volume: the plan ending there is clean.
    lat, lon = (float(x) for x in re.search(r"to (-?[\d.]+), (-?[\d.]+)", msg).groups())  # type: ignore[union-attr]
    moved = replace(op.plan.waypoints[1], lat_deg=lat, lon_deg=lon)
    fixed = replace(op.plan, waypoints=(op.plan.waypoints[0], moved))
    assert plan_in_fences(fixed, op, [fire], FRAME) == []
    assert plan_vs_geofences(fixed, op, [fire], FRAME, MonitoringConfig()) == []


def test_a_leg_through_a_fence_a_waypoint_inside_a_polygon_and_inactive_fences() -> None:
    op = operation("A", [(-500, 0, 100, T0), (500, 0, 100, T0 + 100), (500, 300, 100, T0 + 130)])
    square = polygon("sq", [(-50, -50), (50, -50), (50, 50), (-50, 50)])
    (f,) = plan_in_fences(op.plan, op, [square], FRAME)
    assert (f.waypoint, f.inside, f.destination) == (1, False, False)
    assert "the leg from waypoint 0 to 1 enters active geofence sq" in f.message()
    assert "reroute the leg around the fence" in f.message()
    # A polygon that holds the middle waypoint: that waypoint, moved out by the fix.
    corner = polygon("c", [(450, -50), (600, -50), (600, 50), (450, 50)])
    (g,) = plan_in_fences(op.plan, op, [corner], FRAME)
    assert (g.waypoint, g.inside, g.destination) == (1, True, False)
    # A fence over before the plan starts, one above it, one that exempts A: nothing.
    over = polygon("over", [(-50, -50), (50, -50), (50, 50), (-50, 50)], end=T0 - 10)
    high = polygon("high", [(-50, -50), (50, -50), (50, 50), (-50, 50)], zlo=150, zhi=300)
    exempt = replace(square, exempt=(op.id,))
    assert plan_in_fences(op.plan, op, [over, high, exempt], FRAME) == []


def test_the_filing_check_logs_a_plan_into_a_fence() -> None:
    events: list[tuple[str, str]] = []
    fire = cylinder("fire", (0.0, 0.0), 100.0)
    airspace = Airspace()
    airspace.load([], [fire])
    check = FilingCheck(
        FRAME,
        MonitoringConfig(),
        operations=lambda: airspace.operations,
        log_event=lambda kind, text: events.append((kind, text)),
        geofences=airspace.geofences,
    )
    airspace._on_operation = check.on_operation  # what the app wires
    airspace.add_operation(operation("B", [(-500, 0, 100, T0), (0, 0, 100, T0 + 50)]))
    assert [f.waypoint for f in check.fence_findings["B"]] == [1]
    assert events == [("strategic", check.fence_findings["B"][0].message())]
    airspace.add_operation(operation("C", [(-500, 300, 100, T0), (500, 300, 100, T0 + 100)]))
    assert check.fence_findings["C"] == []
    # TD's plan out of the fence starts inside it: TD verified it from the exit on.
    b = airspace.operation("B")
    airspace.replace_plan(replace(b.plan, version=2, reason="TD hold"))
    assert check.fence_findings["B"] == [] and len(events) == 1
