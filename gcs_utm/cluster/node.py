"""A serving instance as a cluster member (``serve --cluster``): the member task's regions
drive what this instance's airspace holds.

- start: the airspace holds the active geofences and no operation; operations come with the
  regions this instance gains;
- region gained (its configured region at start, or an orphan taken over): the region's
  operations, the active geofences and its pending recommendations are loaded from the store
  (:mod:`gcs_utm.cluster.resume`); each pending recommendation is proposed again as the next
  version in this life, so its pilot prompt goes on where the dead owner left it;
- region lost (the lease could not be renewed in time, or another instance holds it): this
  instance stops (fail-stop, exit code 3). It cannot know what the new owner has decided
  since, and a clean restart re-joins as a standby; carrying on would risk two instances
  deciding for the same operations.
- traffic: the tracks of the operations it owns go out on their regions' MQTT topics; the
  tracks of other instances' operations inside the halo of its regions come in
  (:mod:`gcs_utm.cluster.exchange`): such an operation is loaded from the store as *foreign*
  with its system id (unique across the cluster: behind a MAVLink router this instance hears
  the vehicle too, and both feed one track) and its tracks are fed to the tracker as its
  measurements; a vehicle this instance hears is filed as an operation here only when its
  mission departs in a region it holds (:meth:`ClusterNode.files`), else the operation its
  owner filed for its system id (whatever that operation is called) is loaded as foreign
  (:meth:`ClusterNode.watch_heard`), so even a standby holding nothing tracks it as that
  operation, not as an intruder; foreign plans and the active geofences are refreshed from
  the store every ``renew_s``;
- decisions: who decides is :mod:`gcs_utm.cluster.policy`; what crosses instances goes
  through the store (:mod:`gcs_utm.cluster.decisions`): a recommendation another life filed
  for an operation this instance owns is adopted (proposed again as a new version allocated
  in this life, :mod:`gcs_utm.store.versions`), like a pending one at takeover, and a
  command decided for it is sent to its vehicle here;
- MQTT input (answers, flight plans, operator commands reach every instance): carried out
  and answered by the holder of the region concerned, one refusal from one instance when
  nobody holds it (:mod:`gcs_utm.cluster.inbound`);
- fencing: the writes of this instance's regions' rows carry the lease generation it gained
  them with (:mod:`gcs_utm.cluster.fence`); a refused write is audited and stops the
  instance, like a lost lease.
Every gain and loss is audited (actor: this instance's lease holder name).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Protocol

from gcs_utm.clock import Clock
from gcs_utm.cluster.config import ClusterConfig
from gcs_utm.cluster.decisions import DecisionRelay, EmergencyPort, UsmPort
from gcs_utm.cluster.exchange import RegionExchange, RemoteTrack
from gcs_utm.cluster.fence import LeaseFence, Refusal
from gcs_utm.cluster.inbound import InboundArbiter
from gcs_utm.cluster.lease import Lease
from gcs_utm.cluster.member import ClusterMember
from gcs_utm.cluster.policy import OwnershipPolicy
from gcs_utm.cluster.resume import RegionState, departure_region, load_region
from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    AuditEntry,
    FlightPlan,
    Geofence,
    Measurement,
    MeasurementSource,
    Operation,
    OperationId,
    OperationState,
    Recommendation,
    SysId,
    Track,
    TrackId,
)
from gcs_utm.store import StoreBase, StoreError, is_postgres, versions

_log = logging.getLogger(__name__)


class AirspacePort(Protocol):
    @property
    def operations(self) -> Mapping[OperationId, Operation]: ...

    def load(self, operations: Iterable[Operation], geofences: Iterable[Geofence]) -> None: ...

    def geofences(self, *, active_at_s: float | None = None) -> tuple[Geofence, ...]: ...


class TrackingPort(Protocol):
    def set_operations(self, operations: Iterable[Operation]) -> None: ...


# how often the node publishes its own tracks to the region topics
PUBLISH_PERIOD_S = 0.5


class ClusterNode:
    """Connects a :class:`ClusterMember` to one runtime's airspace, tracking and USM."""

    def __init__(
        self,
        location: str | Path,
        config: ClusterConfig,
        *,
        instance: str,
        epoch: int,
        frame: LocalFrame,
        clock: Clock,
        airspace: AirspacePort,
        tracking: TrackingPort,
        usm: UsmPort,
        record: Callable[[object], None],
        on_fail: Callable[[str], None],
        policy: OwnershipPolicy | None = None,
        exchange: RegionExchange | None = None,
        tracks: Callable[[], Mapping[TrackId, Track]] | None = None,
        emergency: EmergencyPort | None = None,
        heard: Callable[[], Iterable[SysId]] | None = None,
    ) -> None:
        self.member = ClusterMember(
            location,
            config,
            instance=instance,
            epoch=epoch,
            on_gained=self._gained,
            on_lost=self._lost,
        )
        self._frame = frame
        self._clock = clock
        self._airspace = airspace
        self._tracking = tracking
        self._usm = usm
        self._record = record
        self._on_fail = on_fail
        self.resumed: dict[str, RegionState] = {}
        self.policy = policy or OwnershipPolicy()
        self.policy.operations_of = lambda: airspace.operations
        self.exchange = exchange
        self._tracks = tracks
        self._loading: set[OperationId] = set()
        # the MAVLink system ids of the vehicles heard here (behind a router: every vehicle);
        # one flying no operation of the airspace is looked for in the store (watch_heard)
        self._heard = heard
        self.foreign_measurements = 0
        self._regions_of_ops: dict[OperationId, str] = {}
        self._failed = False
        try:
            self._loop: asyncio.AbstractEventLoop | None = asyncio.get_running_loop()
        except RuntimeError:
            self._loop = None
        self.fence = LeaseFence(
            self.member.holder,
            self._region_of,
            self._refused,
            share_lock=is_postgres(location),
        )
        self.decisions = DecisionRelay(
            member=self.member,
            policy=self.policy,
            usm=usm,
            clock=clock,
            record=record,
            fence=self.fence,
            emergency=emergency,
        )
        self.policy.filer = self.decisions.file
        self.policy.may_act = self.may_act
        # MQTT answers, plans and commands: one instance acts, one answers (the gateway's)
        self.inbound = InboundArbiter(
            self.member,
            self.policy,
            frame,
            may_act=self.may_act,
            loaded=lambda region_id: region_id in self.resumed,
            record=record,
            clock=clock,
        )

    # ---- self-fencing on the local clock (gcs_utm.cluster.member, .selffence) ---------------
    def may_act(self) -> bool:
        """True while every region held is within its lease deadline (a local check, no
        I/O) and the instance was not fenced out; the first expired deadline found stops the
        instance (fail-stop, exit code 3)."""
        if self._failed:
            return False
        expired = self.member.expired() or self.member.lost
        if not expired:
            return True
        self._failed = True
        text = (
            f"lease of {', '.join(expired)} expired or lost before a renewal was confirmed: "
            "this instance stops (self-fenced)"
        )
        _log.error("cluster: %s", text)
        self._usm.log_event("cluster", text)
        for region_id in expired:
            self._record(
                AuditEntry(
                    t_s=self._clock.now_s(),
                    actor=self.member.holder,
                    action="lease_expired",
                    subject=region_id,
                )
            )
        self._on_fail(text)
        return False

    # ---- lease fencing (gcs_utm.cluster.fence) ----------------------------------------------
    def _region_of(self, op_id: str) -> str | None:
        """The region of one of the airspace's operations (called on the store's threads)."""
        oid = OperationId(op_id)
        region_id = self._regions_of_ops.get(oid)
        if region_id is None:
            op = self._airspace.operations.get(oid)
            if op is None or not op.plan.waypoints:
                return None
            region_id = departure_region(op, self._frame, self.member.map)
            self._regions_of_ops[oid] = region_id
        return region_id

    def _refused(self, refusal: Refusal) -> None:
        """A write refused by the fence (on a store thread): audited and fail-stop, on the
        loop."""
        if self._loop is not None:
            self._loop.call_soon_threadsafe(self._fenced_out, refusal)

    def _fenced_out(self, refusal: Refusal) -> None:
        text = refusal.text(self.member.holder)
        _log.error("cluster: %s", text)
        self._usm.log_event("cluster", text)
        self._record(
            AuditEntry(
                t_s=self._clock.now_s(),
                actor=self.member.holder,
                action="write_fenced",
                subject=refusal.operation_id,
                detail={
                    "region": refusal.region_id,
                    "generation": refusal.generation,
                    "current_generation": refusal.current_generation,
                    "current_holder": refusal.current_holder,
                },
            )
        )
        if not self._failed:
            self._failed = True
            self._on_fail(f"region {refusal.region_id} taken over: this instance stops (fenced)")

    async def _gained(self, region_id: str, lease: Lease | None) -> None:
        region_map = self.member.map
        epoch = self.member.epoch
        try:
            state = await self.member.read(
                lambda s: load_region(s, region_id, region_map, self._frame, epoch)
            )
        except StoreError as exc:
            # nothing of the region is installed yet: hand it back, a later round retries
            text = f"region {region_id} not taken: loading it failed ({exc}); handed back"
            _log.warning("cluster: %s", text)
            self._usm.log_event("cluster", text)
            self.member.drop(region_id)
            return
        assert isinstance(state, RegionState)
        self.resumed[region_id] = state
        for op in state.operations:
            self.policy.foreign.discard(op.id)
            self._regions_of_ops[op.id] = region_id  # the fence's map, filled ahead of writes
        if self.exchange is not None:
            self.exchange.watch(self.member.owned)
        known = set(self._airspace.operations)
        self._airspace.load(state.operations, state.geofences)
        self._tracking.set_operations(self._airspace.operations.values())
        generation = lease.generation if lease is not None else 0
        self.fence.gained(region_id, generation)
        for rec in state.pending:
            try:
                await self.decisions.adopt(
                    rec,
                    f"resumed by {self.member.holder} (region {region_id}, lease "
                    f"generation {generation})",
                )
            except StoreError as exc:  # a fenced write stops the instance (_fenced_out)
                _log.warning("cluster: %s v%d not resumed: %s", rec.id, rec.version, exc)
        self.decisions.continue_after(state.highest)
        new_ops = [op.id for op in state.operations if op.id not in known]
        watched = [op.id for op in state.operations if op.id in known]
        text = (
            f"region {region_id} held (generation {generation}): {len(new_ops)} operations, "
            f"{len(state.geofences)} geofences, {len(state.pending)} pending recommendations"
        )
        _log.info("cluster: %s", text)
        self._usm.log_event("cluster", text)
        self._record(
            AuditEntry(
                t_s=self._clock.now_s(),
                actor=self.member.holder,
                action="region_gained",
                subject=region_id,
                detail={
                    "generation": generation,
                    "operations": [str(op.id) for op in state.operations],
                    "were_watched": [str(i) for i in watched],
                    "pending": [f"{r.id} v{r.version}" for r in state.pending],
                },
            )
        )

    async def _lost(self, region_id: str, _lease: Lease | None) -> None:
        self._record(
            AuditEntry(
                t_s=self._clock.now_s(),
                actor=self.member.holder,
                action="region_lost",
                subject=region_id,
            )
        )
        if not self._failed:
            self._failed = True
            self._on_fail(f"region {region_id} lost: this instance stops (fail-stop)")

    # ---- traffic of other instances -------------------------------------------------------
    def _in_halo(self, t: RemoteTrack) -> bool:
        east_m, north_m = self._frame.point_to_local(t.lat_deg, t.lon_deg)
        return bool(self.member.map.regions_near(east_m, north_m) & set(self.member.owned))

    async def on_remote_tracks(self, tracks: list[RemoteTrack]) -> None:
        """Feed the tracks of other instances' operations inside this instance's halo."""
        now_s = self._clock.now_s()
        for t in tracks:
            op_id = t.operation_id
            if self.policy.owns(op_id) or not self._in_halo(t):
                continue  # our own echo, or traffic far from our regions
            if op_id not in self.policy.foreign and not await self._load_foreign(op_id):
                continue
            ve, vn, vu = t.vel_enu_mps
            self._usm.on_measurement(
                Measurement(
                    source=MeasurementSource.MQTT,
                    capture_t_s=t.t_s,
                    receipt_t_s=now_s,
                    lat_deg=t.lat_deg,
                    lon_deg=t.lon_deg,
                    alt_amsl_m=t.alt_amsl_m,
                    vel_ned_mps=(vn, ve, -vu),
                    eph_m=t.position_sigma_m,
                    operation_id=op_id,
                    link=f"cluster:{t.region_id}",
                )
            )
            self.foreign_measurements += 1

    async def _load_foreign(self, op_id: OperationId) -> bool:
        if op_id in self._loading:
            return False
        self._loading.add(op_id)
        try:
            found = await self.member.read(lambda s: _operation(s, op_id))
        except StoreError as exc:
            # the database is away or cut this connection (a restart): the operation's next
            # traffic message tries again; it must not end the exchange, and the process
            _log.warning("cluster: %s of another instance not loaded: %s", op_id, exc)
            return False
        finally:
            self._loading.discard(op_id)
        if not isinstance(found, Operation):
            return False  # not filed (yet): its owner saves it first
        self.policy.foreign.add(op_id)
        self._install_foreign([found])
        self._usm.log_event("cluster", f"watching {op_id} of another instance (halo)")
        return True

    def _install_foreign(self, ops: list[Operation]) -> None:
        """A foreign operation keeps its system id and ICAO address (unique across the
        cluster): behind a MAVLink router this instance hears the vehicle itself, and its
        telemetry then feeds the same track as the exchanged one, not an intruder."""
        self._airspace.load(ops, ())
        self._tracking.set_operations(self._airspace.operations.values())

    def files(self, op_id: OperationId, plan: FlightPlan | None) -> bool:
        """Whether this instance files or changes the operation of a vehicle it hears
        (gcs_utm.services.vehicle_ops): one it owns, or a new one departing in a region it
        holds."""
        if op_id in self._airspace.operations:
            return self.policy.owns(op_id)
        if plan is None or not plan.waypoints:
            return False
        first = plan.waypoints[0]
        east_m, north_m = self._frame.point_to_local(first.lat_deg, first.lon_deg)
        # another instance's vehicle: watched once filed there (watch_heard)
        return self.member.owns(self.member.map.region_of(east_m, north_m))

    async def watch_heard(self) -> None:
        """The vehicles heard here (their system ids, as the hub names them) that fly no
        operation of this airspace: the operation another instance filed for that system id
        becomes a foreign operation here, whatever it is called (``sys<n>`` from the
        vehicle's mission, an id filed over MQTT or from a scenario with its ``sys_id``), so
        the vehicle's telemetry feeds a vehicle track of that operation rather than an
        intruder ``sysid:<n>@<address>``; one not filed yet is looked for again on the next
        call."""
        if self._heard is None:
            return
        here = self._airspace.operations
        flown = {op.sys_id for op in here.values() if op.sys_id is not None}
        wanted = {SysId(s) for s in self._heard()} - flown
        if not wanted:
            return
        found = await self.member.read(lambda s: _flown_by(s, wanted))
        assert isinstance(found, list)
        ops = [op for op in found if op.id not in here and not self._held(op)]
        if not ops:
            return
        self.policy.foreign.update(op.id for op in ops)
        self._install_foreign(ops)
        for op in ops:
            self._usm.log_event("cluster", f"watching {op.id} of another instance (heard)")

    def _held(self, op: Operation) -> bool:
        """An operation of a region this instance holds: its own (loaded with the region)."""
        return bool(op.plan.waypoints) and self.member.owns(
            departure_region(op, self._frame, self.member.map)
        )

    async def refresh(self) -> None:
        """Foreign operations' plans and the active geofences as filed in the store (their
        owners change them), and recommendations other lives filed for our operations."""
        foreign = set(self.policy.foreign)
        epoch = self.member.epoch
        snap = await self.member.read(lambda s: _refresh_view(s, foreign, epoch))
        assert isinstance(snap, tuple)
        ops, fences, open_recs, touched = snap
        await self.decisions.relay(touched)
        current = self._airspace.operations
        changed = [op for op in ops if (c := current.get(op.id)) is None or c.plan != op.plan]
        if changed:
            self._install_foreign(changed)
        known = {g.id for g in self._airspace.geofences()}
        new_fences = [g for g in fences if g.id not in known]
        if new_fences:
            self._airspace.load((), new_fences)
        await self.decisions.take(open_recs)

    def publish(self) -> None:
        if self.exchange is None or self._tracks is None:
            return
        own = [
            t
            for t in self._tracks().values()
            if t.operation_id is not None and self.policy.owns(t.operation_id)
        ]
        if own:
            self.exchange.publish(own, self._clock.now_s())

    async def run(self) -> None:
        """The member task, the exchange and the periodic refresh/publication."""
        self._loop = asyncio.get_running_loop()
        async with asyncio.TaskGroup() as tg:
            tg.create_task(self.member.run())
            if self.exchange is not None:
                tg.create_task(self.exchange.run())
            tg.create_task(self._periodic())

    async def _periodic(self) -> None:
        next_refresh = 0.0
        loop = asyncio.get_running_loop()
        while True:
            due = loop.time() >= next_refresh
            if due:
                next_refresh = loop.time() + self.member.config.renew_s
            try:
                if due:
                    await self.watch_heard()  # a standby too: it hears every vehicle
                if self.member.owned:
                    self.publish()
                    if due:
                        await self.refresh()
            except StoreError as exc:
                _log.warning("cluster: refresh from the store failed: %s", exc)
            await asyncio.sleep(PUBLISH_PERIOD_S)


def _operation(store: StoreBase, op_id: OperationId) -> Operation | None:
    for op in store.load_operations():
        if op.id == op_id:
            return op
    return None


def _flown_by(store: StoreBase, sys_ids: set[SysId]) -> list[Operation]:
    """The operation each of ``sys_ids`` flies as filed in the store (not ended; the most
    recently planned when a vehicle has flown several)."""
    latest: dict[SysId, Operation] = {}
    for op in store.load_operations():
        if op.sys_id is None or op.sys_id not in sys_ids or op.state is OperationState.ENDED:
            continue
        seen = latest.get(op.sys_id)
        if seen is None or op.plan.created_t_s >= seen.plan.created_t_s:
            latest[op.sys_id] = op
    return list(latest.values())


def _refresh_view(
    store: StoreBase, foreign: set[OperationId], epoch: int
) -> tuple[
    list[Operation],
    list[Geofence],
    list[tuple[Recommendation, int]],
    list[tuple[str, int, str, int]],
]:
    ops = [op for op in store.load_operations() if op.id in foreign] if foreign else []
    return (
        ops,
        store.load_geofences(active_only=True),
        versions.open_with_lives(store),
        store.versions_touched_by(epoch),
    )


__all__ = ["ClusterNode"]
