"""MQTT input in a cluster: one instance acts on each message, and one answers it.

Every instance's MQTT gateway subscribes to the same broker topics (docs/mqtt.md), so a
pilot's answer to a recommendation, a flight plan, a flight status (start, stop) and an
operator command reach every instance at once. Behind a MAVLink router any of them could
act on it; only one may, and the pilot's station, which waits for one acknowledgement
(:mod:`adapters.mqtt.station`), must hear one answer:

- **the holder acts and answers**: the instance holding the region of the operation the
  message concerns (its departure's; a flight plan's first waypoint's), within its lease
  deadline, carries it out and publishes the outcome as a single instance does (accepted; a
  wrong version, an unknown recommendation of its region, a plan into a geofence refused).
  Operator commands are gated by :mod:`gcs_utm.cluster.commands`; this module only decides
  who answers one that no instance commands.
- **the others ignore it**: nothing is published; a debug line and an audit entry
  (``mqtt_elsewhere``, with the reason) record it.
- **nobody holds the region** (its owner died and the takeover is under way, or no instance
  serves that region), or nothing in the store names the recommendation or the UAS: the
  *arbiter* refuses it, naming why. The pilot sends it again: the station re-sends an answer
  or a command until acknowledged, but a refused one is acknowledged, so the refusal says
  what comes next (the new holder proposes a pending recommendation again; "send it again in
  a few seconds"). A flight plan is refused too ("submit it again in a few seconds"), not held
  until the region has a holder: holding it would need an instance to keep it across its own
  failure, and the pilot would learn of its acceptance at an unknown later time, or never if
  no instance serves the region; refused, the pilot knows at once and decides.

The arbiter is the instance holding the lowest region id among the live leases, read from
the store (the member's read connection) when the message comes: every instance reads the
same lease table and the database's clock decides which leases are live, so they agree on
one instance; a live lease's holder renewed it within ``lease_s`` (a standby holding nothing
cannot be told from a dead instance, so it never arbitrates, and an instance holding no
region answers nothing without reading the store). Two instances both arbitrate only if
the lowest region changes holder between their two reads of one message (milliseconds).
While a dead holder's lease has not expired yet, its region is held, by the dead instance:
nobody answers, and a command or answer re-sent by the station is answered after the
takeover (within ``lease_s + renew_s``); a plan submitted in that window gets no answer.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from adapters.mqtt.codec import FlightPlanSubmission, FlightStatusReport, OperatorCommandRequest
from gcs_utm.clock import Clock
from gcs_utm.cluster import lease as leases_
from gcs_utm.cluster.member import ClusterMember
from gcs_utm.cluster.policy import OwnershipPolicy
from gcs_utm.cluster.regions import RegionMap
from gcs_utm.cluster.resume import departure_region
from gcs_utm.geo import LocalFrame
from gcs_utm.messages import PilotAnswer
from gcs_utm.model import AuditEntry, Operation, OperationId, SysId
from gcs_utm.services.mqtt_gateway import HERE, Route
from gcs_utm.store import StoreBase, StoreError

_log = logging.getLogger(__name__)

# what a lookup in the store tells the arbiter: the region of the message's subject (None:
# nothing in the store names it)
Lookup = Callable[[StoreBase], str | None]


class InboundArbiter:
    """The rule above for one cluster member (an
    :class:`~gcs_utm.services.mqtt_gateway.InboundArbiter`). ``loaded(region)``: the region's
    operations are in this instance's airspace (its takeover finished); ``record``: the
    audit."""

    def __init__(
        self,
        member: ClusterMember,
        policy: OwnershipPolicy,
        frame: LocalFrame,
        *,
        may_act: Callable[[], bool],
        loaded: Callable[[str], bool],
        record: Callable[[object], None],
        clock: Clock,
    ) -> None:
        self._member = member
        self._policy = policy
        self._frame = frame
        self._may_act = may_act
        self._loaded = loaded
        self._record = record
        self._clock = clock
        self.ignored = 0  # messages another instance answers
        self.refused = 0  # messages refused here as the arbiter (or a region being loaded)

    # ---- the three kinds of message ---------------------------------------------------------
    async def pilot_answer(self, a: PilotAnswer, operation_id: OperationId | None) -> Route:
        """``operation_id``: the operation of the recommendation as this instance's USM
        knows it (None: unknown here)."""
        if operation_id is not None and self._policy.owns(operation_id):
            region_id = self._region_of_operation(operation_id)
            if region_id is not None and self._holds(region_id):
                return HERE
        rec_id = a.recommendation_id
        region_map, frame = self._member.map, self._frame
        return await self._elsewhere(
            "answer",
            f"{rec_id} v{a.version}",
            lambda s: _recommendation_region(s, rec_id, frame, region_map),
            unknown=f"unknown recommendation {rec_id!r}: no instance has it",
            unheld=lambda region_id: (
                f"recommendation {rec_id} is for an operation of region {region_id}, held by "
                "no instance now (a takeover under way): its new holder proposes it again"
            ),
        )

    async def flight_plan(self, s: FlightPlanSubmission) -> Route:
        first = s.plan.waypoints[0]
        east_m, north_m = self._frame.point_to_local(first.lat_deg, first.lon_deg)
        region_id = self._member.map.region_of(east_m, north_m)
        if self._holds(region_id):
            if self._loaded(region_id):
                return HERE
            return self._refuse(
                "flight_plan",
                s.operation_id,
                f"operation {s.operation_id} departs in region {region_id}, which this "
                "instance is taking over now: submit it again in a few seconds",
            )
        return await self._elsewhere(
            "flight_plan",
            s.operation_id,
            lambda _s: region_id,
            unknown="",
            unheld=lambda r: (
                f"operation {s.operation_id} departs in region {r}, held by no instance now (a "
                "takeover under way, or no instance serves it): submit it again in a few seconds"
            ),
        )

    async def flight_status(self, s: FlightStatusReport) -> Route:
        """A pilot starts or stops an operation: its owner changes its state (and files it)."""
        op_id = s.operation_id
        if self._policy.owns(op_id):
            region_id = self._region_of_operation(op_id)
            if region_id is not None and self._holds(region_id):
                return HERE
        region_map, frame = self._member.map, self._frame
        return await self._elsewhere(
            "flight_status",
            op_id,
            lambda store: _region_of(_operation(store, op_id), frame, region_map),
            unknown=f"unknown operation {op_id!r}: no instance has it",
            unheld=lambda region_id: (
                f"operation {op_id} belongs to region {region_id}, held by no instance now (a "
                "takeover under way, or no instance serves it): send it again in a few seconds"
            ),
        )

    async def operator_command(self, c: OperatorCommandRequest, gate_reason: str) -> str:
        """An operator command this instance's gate refused as another instance's
        (``gate_reason``): the refusal this instance answers with ("": it answers nothing,
        another instance does)."""
        uas = c.uas
        region_map, frame = self._member.map, self._frame
        route = await self._elsewhere(
            "command",
            uas,
            lambda s: _uas_region(s, uas, frame, region_map),
            unknown=f"unknown UAS {uas!r}: no instance has an operation of that name or system id",
            unheld=lambda region_id: (
                f"{uas} belongs to region {region_id}, held by no instance now (a takeover "
                "under way, or no instance serves it): send it again in a few seconds"
            ),
        )
        return gate_reason if route.here else route.refusal

    # ---- who answers ------------------------------------------------------------------------
    def _holds(self, region_id: str) -> bool:
        return self._member.owns(region_id) and self._may_act()

    def _region_of_operation(self, op_id: OperationId) -> str | None:
        op = self._policy.operations_of().get(op_id)
        if op is None or not op.plan.waypoints:
            return None
        return departure_region(op, self._frame, self._member.map)

    async def _elsewhere(
        self,
        kind: str,
        subject: str,
        lookup: Lookup,
        *,
        unknown: str,
        unheld: Callable[[str], str],
    ) -> Route:
        """Not this instance's by what it holds: the holder of the subject's region in the
        store answers (this instance, if the store says so and it holds the region), else
        the arbiter refuses."""
        if not self._member.owned or not self._may_act():
            why = "this instance holds no region (or its lease deadline passed): not the arbiter"
            return self._ignore(kind, subject, why)
        try:
            found = await self._member.read(lambda s: (leases_.owners(s), lookup(s)))
        except StoreError as exc:  # nobody may know better: the station sends it again
            _log.warning("cluster: %s %s not arbitrated (store: %s)", kind, subject, exc)
            return self._ignore(kind, subject, f"store unreachable: {exc}")
        assert isinstance(found, tuple)
        owners: dict[str, str] = found[0]
        region_id: str | None = found[1]
        me = self._member.holder
        if region_id is not None and region_id in owners:
            if owners[region_id] == me and self._holds(region_id):
                return HERE
            return self._ignore(kind, subject, f"region {region_id} held by {owners[region_id]}")
        if not owners or owners[min(owners)] != me or not self._may_act():
            arbiter = owners[min(owners)] if owners else "nobody"
            return self._ignore(kind, subject, f"nobody holds it; the arbiter is {arbiter}")
        return self._refuse(kind, subject, unheld(region_id) if region_id else unknown)

    def _ignore(self, kind: str, subject: str, why: str) -> Route:
        self.ignored += 1
        _log.debug("cluster: MQTT %s %s answered elsewhere: %s", kind, subject, why)
        self._audit("mqtt_elsewhere", kind, subject, why)
        return Route(here=False)

    def _refuse(self, kind: str, subject: str, reason: str) -> Route:
        self.refused += 1
        _log.info("cluster: MQTT %s %s refused here: %s", kind, subject, reason)
        self._audit("mqtt_refused", kind, subject, reason)
        return Route(here=False, refusal=reason)

    def _audit(self, action: str, kind: str, subject: str, why: str) -> None:
        self._record(
            AuditEntry(
                t_s=self._clock.now_s(),
                actor=self._member.holder,
                action=action,
                subject=subject,
                detail={"message": kind, "why": why},
            )
        )


def _region_of(op: Operation | None, frame: LocalFrame, region_map: RegionMap) -> str | None:
    if op is None or not op.plan.waypoints:
        return None
    return departure_region(op, frame, region_map)


def _operation(store: StoreBase, uas: str) -> Operation | None:
    """The operation ``uas`` names in the store: its id, else a system id (``3``, ``sys3``)
    it flies (the most recently planned), as an instance's operator commands name one."""
    digits = uas.removeprefix("sys")
    sys_id = SysId(int(digits)) if digits.isdigit() else None
    flown: Operation | None = None
    for op in store.load_operations():
        if op.id == uas:
            return op
        later = flown is None or op.plan.created_t_s >= flown.plan.created_t_s
        if sys_id is not None and op.sys_id == sys_id and later:
            flown = op
    return flown


def _uas_region(store: StoreBase, uas: str, frame: LocalFrame, region_map: RegionMap) -> str | None:
    return _region_of(_operation(store, uas), frame, region_map)


def _recommendation_region(
    store: StoreBase, rec_id: str, frame: LocalFrame, region_map: RegionMap
) -> str | None:
    op_id = store.operation_of_recommendation(rec_id)
    return None if op_id is None else _uas_region(store, op_id, frame, region_map)


__all__ = ["InboundArbiter"]
