"""A restarted serve at a speed factor resumes its clock from the store's latest time.

Measured on the nuisance soak (speed 3): serve's clock started from the wall clock at each
start, so after a kill -9 and a restart 2 s later the new life's times were about 45 s behind
the previous life's last ones (the store's plans, threats and track history interleaved, and
the previous life's plans for the vehicles in the air read 45 s early)."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

from gcs_utm.app.serve import _service_clock
from gcs_utm.clock import RealClock
from gcs_utm.model import AuditEntry
from gcs_utm.scenario import load_scenario
from gcs_utm.store import open_store
from tests.store.test_store import UC1, _threat


def test_the_latest_time_is_that_of_the_audit_plans_and_threats(db: str | Path) -> None:
    with open_store(db) as s:
        assert s.latest_t_s() is None  # an empty store: the wall clock
        s.audit(AuditEntry(t_s=2000.0, actor="usm", action="event", subject="vehicle"))
        op = load_scenario(UC1).operations[0]
        s.save_operation(replace(op, plan=replace(op.plan, created_t_s=2050.0)))
        s.save_threat(replace(_threat(), detected_at_s=2020.0))
        assert s.latest_t_s() == 2050.0


def test_a_scaled_clock_resumes_ahead_of_the_wall_clock_never_behind_it() -> None:
    ahead_s = time.time() + 45.0  # where the previous life at speed 3 left the store
    clock = _service_clock(3.0, ahead_s)
    assert ahead_s <= clock.now_s() < ahead_s + 5.0
    behind = _service_clock(3.0, time.time() - 3600.0)  # an old store: the wall clock
    assert abs(behind.now_s() - time.time()) < 5.0
    assert abs(_service_clock(3.0, None).now_s() - time.time()) < 5.0
    assert isinstance(_service_clock(1.0, ahead_s), RealClock)  # at speed 1 the wall clock
