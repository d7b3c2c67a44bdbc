"""The lease deadline of self-fencing: measured on the local monotonic clock from the moment
the renewal was *sent* (the database stamps its expiry later), checked locally before every
act, and a region past it is given up by the next round whatever the database answers."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest

from gcs_utm.cluster import lease as leases_
from gcs_utm.cluster.lease import Lease
from gcs_utm.cluster.member import ClusterMember
from gcs_utm.cluster.selffence import REFUSED, FencedVehicles
from gcs_utm.messages import HazardReport
from gcs_utm.model import Command, CommandKind, OperationId, SysId, ThreatKind
from tests.cluster.harness import config

LEASE_S = 2.0


async def _none(_region: str, _lease: Lease | None) -> None:
    return None


def _member(db: Path) -> ClusterMember:
    return ClusterMember(
        db,
        config("A", "c0r0", standby=False, lease_s=LEASE_S),
        instance="A",
        epoch=1,
        on_gained=_none,
        on_lost=_none,
    )


def test_the_deadline_is_measured_from_before_the_renewal_is_sent(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from gcs_utm.store import open_store

    db = tmp_path / "db.sqlite3"
    open_store(db).close()
    m = _member(db)
    real_acquire = leases_.acquire
    sent: list[float] = []
    slow_s = 0.3

    def slow_acquire(*args: object, **kwargs: object) -> Lease | None:
        sent.append(time.monotonic())
        time.sleep(slow_s)  # the renewal takes a while to come back
        return real_acquire(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(leases_, "acquire", slow_acquire)
    before = time.monotonic()
    assert [e[:2] for e in m.round()] == [("gained", "c0r0")]
    deadline = m.deadline_mono("c0r0")
    assert deadline is not None
    # from the moment before the request, not from its answer (slow_s later)
    assert before + LEASE_S <= deadline <= sent[0] + LEASE_S
    assert m.expired(deadline - 0.01) == [] and m.expired(deadline) == ["c0r0"]
    # a round after the deadline gives the region up even though the renewal would succeed
    assert m.expired(time.monotonic() + LEASE_S) == ["c0r0"]
    m._renewed_mono = {"c0r0": time.monotonic() - LEASE_S - 0.1}  # a stall past the deadline
    assert [e[:2] for e in m.round()] == [("lost", "c0r0"), ("gained", "c0r0")]
    m._pool.shutdown(wait=True)
    if m._lease_db is not None:
        m._lease_db.close()
    if m._read_db is not None:
        m._read_db.close()


def test_a_member_past_its_deadline_may_not_act() -> None:
    from gcs_utm.cluster.policy import OwnershipPolicy

    allowed = threading.Event()
    policy = OwnershipPolicy()
    policy.may_act = allowed.is_set
    hazard = HazardReport(
        kind=ThreatKind.COMMUNICATION_FAILURE, t_s=0.0, message="no position", source="tracking"
    )
    assert policy.filter_threats([]) == [] and not policy.admits_hazard(hazard)
    assert policy.dropped_stale == 1
    allowed.set()
    assert policy.admits_hazard(hazard)


class _Vehicles:
    def __init__(self) -> None:
        self.sent: list[Command] = []

    async def upload_plan(self, *args: object, **kwargs: object) -> object:
        raise AssertionError("no upload in this test")

    async def send_command(self, sys_id: SysId, command: Command) -> object:
        self.sent.append(command)
        return type("Ok", (), {"ok": True, "error": ""})()


async def test_no_command_reaches_a_vehicle_past_the_deadline() -> None:
    allowed = threading.Event()
    vehicles = _Vehicles()
    fenced = FencedVehicles(vehicles, allowed.is_set)  # type: ignore[arg-type]
    hold = Command(operation_id=OperationId("UAS1"), kind=CommandKind.HOLD)
    refused = await fenced.send_command(SysId(1), hold)
    assert (refused.ok, refused.error, vehicles.sent, fenced.refused) == (False, REFUSED, [], 1)
    allowed.set()
    assert (await fenced.send_command(SysId(1), hold)).ok and vehicles.sent == [hold]
