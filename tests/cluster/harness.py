"""Two cluster members in one process on one store, each a real :class:`ClusterNode` (member,
lease fence, decision relay) with its own store writer and life, around recording fakes of
the USM, the EM, the airspace and tracking. Lease rounds and refreshes are stepped by the
test (no background task), so a test can also stall one member past its lease expiry."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from gcs_utm.app.wiring import Persistence
from gcs_utm.clock import RealClock
from gcs_utm.cluster.config import ClusterConfig
from gcs_utm.cluster.decisions import EmergencyPort, UsmPort
from gcs_utm.cluster.node import AirspacePort, ClusterNode
from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    Command,
    Geofence,
    Measurement,
    Operation,
    OperationId,
    Recommendation,
    RecommendationId,
    SysId,
)
from gcs_utm.scenario import load_scenario
from gcs_utm.store import StoreConfig, StoreWriter, open_store
from tests.store.test_store import UC1


class FakeAirspace:
    def __init__(self) -> None:
        self.ops: dict[OperationId, Operation] = {}

    @property
    def operations(self) -> Mapping[OperationId, Operation]:
        return self.ops

    def load(self, operations: Iterable[Operation], geofences: Iterable[Geofence]) -> None:
        for op in operations:
            self.ops[op.id] = op

    def geofences(self, *, active_at_s: float | None = None) -> tuple[Geofence, ...]:
        return ()


class FakeTracking:
    def set_operations(self, operations: Iterable[Operation]) -> None:
        return None


class FakeUsm:
    """Records what reaches the pilot and the vehicle; files proposals like the USM does."""

    def __init__(self, store: Persistence, *, command_ok: bool = True) -> None:
        self.store = store
        self.proposed: list[Recommendation] = []
        self.commands: list[Command] = []
        self.events: list[str] = []
        self.command_ok = command_ok

    async def on_recommendation(self, rec: Recommendation) -> None:
        self.proposed.append(rec)
        self.store.record(rec)

    async def execute_command(self, command: Command, *, reason: str = "") -> bool:
        self.commands.append(command)
        return self.command_ok

    def log_event(self, kind: str, text: str) -> None:
        self.events.append(text)

    def on_measurement(self, m: Measurement) -> None:
        return None

    # what apply_decision also calls
    async def add_geofences(self, geofences: object) -> None:
        return None

    async def on_superseded(self, rec_id: RecommendationId) -> None:
        return None

    async def escalate(self, text: str) -> None:
        self.events.append(text)


class FakeEm:
    def __init__(self) -> None:
        self.answers: list[tuple[str, int, bool]] = []
        self.outcomes: list[tuple[str, int, bool]] = []
        self.renumbered: list[tuple[str, int]] = []

    async def submit_answer(self, rec_id: RecommendationId, version: int, accepted: bool) -> None:
        self.answers.append((rec_id, version, accepted))

    async def submit_outcome(
        self, rec_id: RecommendationId, version: int, applied: bool, reason: str
    ) -> None:
        self.outcomes.append((rec_id, version, applied))

    def renumber(self, rec_id: RecommendationId, version: int) -> bool:
        self.renumbered.append((rec_id, version))
        return False

    def continue_after(self, rec_id: RecommendationId, version: int) -> None:
        return None


@dataclass
class Member:
    node: ClusterNode
    writer: StoreWriter
    store: Persistence
    usm: FakeUsm
    em: FakeEm
    airspace: FakeAirspace
    failed: list[str] = field(default_factory=list)

    async def step(self) -> list[str]:
        """One lease round (on a thread, as the member does), its gains handled here."""
        events = await asyncio.to_thread(self.node.member.round)
        for kind, region_id, lease in events:
            if kind == "gained":
                await self.node._gained(region_id, lease)
            else:
                await self.node._lost(region_id, lease)
        return [f"{kind} {region_id}" for kind, region_id, _ in events]

    async def step_until(self, wanted: str, timeout_s: float = 10.0) -> list[str]:
        """Lease rounds every ``renew_s`` (as the lease thread makes them: a member that
        skips renewals for ``lease_s`` fences itself) until ``wanted`` happens."""
        seen: list[str] = []
        deadline = time.monotonic() + timeout_s
        while wanted not in seen:
            if time.monotonic() > deadline:
                raise AssertionError(f"{wanted!r} not within {timeout_s} s: {seen}")
            seen += await self.step()
            if wanted not in seen:
                await asyncio.sleep(self.node.member.config.renew_s)
        return seen

    def flush(self) -> None:
        self.writer.flush(10.0)

    async def close(self) -> None:
        await self.node.member.close()
        lease_db = self.node.member._lease_db
        if lease_db is not None:
            lease_db.close()
        self.writer.close()


def frame() -> LocalFrame:
    return load_scenario(UC1).frame


def config(instance: str, region: str, *, standby: bool, lease_s: float = 30.0) -> ClusterConfig:
    """UAS1 departs in c0r0, UAS2 in c1r0 (the border halfway between their departures)."""
    sc = load_scenario(UC1)
    (e1, _), (e2, _) = (
        sc.frame.point_to_local(op.plan.waypoints[0].lat_deg, op.plan.waypoints[0].lon_deg)
        for op in sc.operations
    )
    border_m = (e1 + e2) / 2
    return ClusterConfig(
        instance=instance,
        region=region,
        standby=standby,
        west_m=border_m - 2000.0,
        south_m=-5000.0,
        cell_m=2000.0,
        columns=2,
        rows=1,
        halo_m=200.0,
        lease_s=lease_s,
        renew_s=lease_s / 4,
    )


def file_airspace(location: str | Path) -> list[Operation]:
    """An earlier life files UC1's two operations."""
    ops = list(load_scenario(UC1).operations)
    with open_store(location) as s:
        s.begin_life()
        for op in ops:
            s.save_operation(op)
    return ops


async def member(
    location: str | Path,
    cfg: ClusterConfig,
    *,
    fenced: bool = True,
    command_ok: bool = True,
    services: Callable[[Persistence], tuple[UsmPort, AirspacePort]] | None = None,
    emergency: EmergencyPort | None = None,
    store_config: StoreConfig | None = None,
    heard: Callable[[], Iterable[SysId]] | None = None,
) -> Member:
    """A member; ``services``: makes a real USM and airspace on the member's store instead
    of the fakes (the fakes are still returned, unused); ``emergency``: a real EM service
    instead of the fake (likewise); ``store_config``: its writer's settings; ``heard``: the
    system ids of the vehicles it hears."""
    writer = StoreWriter(location, store_config)
    store = Persistence(writer)
    usm_port, airspace_port = services(store) if services is not None else (None, None)
    usm = FakeUsm(store, command_ok=command_ok)
    em = FakeEm()
    airspace = FakeAirspace()
    failed: list[str] = []
    node = ClusterNode(
        location,
        cfg,
        instance=cfg.instance,
        epoch=writer.epoch,
        frame=frame(),
        clock=RealClock(),
        airspace=airspace_port or airspace,
        tracking=FakeTracking(),
        usm=usm_port or usm,
        record=store.record,
        on_fail=failed.append,
        emergency=emergency or em,
        heard=heard,
    )
    if fenced:
        writer.set_fence(node.fence).result(10.0)
    await node.member.start()
    return Member(node, writer, store, usm, em, airspace, failed)


__all__ = ["FakeUsm", "Member", "config", "file_airspace", "frame", "member"]
