"""Operator commands in a cluster: only the owner of a UAS's region commands its vehicle.

An operator's hold / land / rtl / resume (:mod:`gcs_utm.services.operator_commands`) reaches
whichever instance the operator uses: its dashboard or line prompt, or, over MQTT, every
instance at once (each gateway subscribes to the same broker topics). Behind a MAVLink router
every instance has a link to every vehicle, so any of them *could* send it; only the holder
of the region the UAS's operation belongs to (its departure's) may, like every other command
and decision (:mod:`gcs_utm.cluster.policy`, :mod:`gcs_utm.cluster.selffence`).

Non-owners refuse the command, naming the region and the instance holding it, instead of
routing it there: over MQTT the owner received the same message from the broker and answers
it itself (a non-owner's refusal is marked ``elsewhere`` and not published, so the station
hears one answer); a local channel (dashboard, line prompt) is that instance's operator, who
is told where the UAS is commanded. Routing through the store, as decisions for another
instance's UAS travel (:mod:`gcs_utm.cluster.decisions`), would delay a command by up to a
refresh period and leave its confirmation (the vehicle's mode, read within seconds) to
another instance. The owner itself commands only within its lease deadline.
"""

from __future__ import annotations

from collections.abc import Callable

from gcs_utm.cluster.member import ClusterMember
from gcs_utm.cluster.policy import OwnershipPolicy
from gcs_utm.cluster.resume import departure_region
from gcs_utm.geo import LocalFrame
from gcs_utm.model import Operation


class CommandGate:
    """``gate(uas, op)``: why this instance may not command ``op``'s vehicle ("" when it
    may); ``op`` is the operation ``uas`` names here (None: not in this instance's
    airspace)."""

    def __init__(
        self,
        member: ClusterMember,
        policy: OwnershipPolicy,
        frame: LocalFrame,
        may_act: Callable[[], bool],
    ) -> None:
        self._member = member
        self._policy = policy
        self._frame = frame
        self._may_act = may_act
        self.refused = 0

    def __call__(self, uas: str, op: Operation | None) -> str:
        reason = self._why_not(uas, op)
        if reason:
            self.refused += 1
        return reason

    def _why_not(self, uas: str, op: Operation | None) -> str:
        if op is None:
            return (
                f"unknown UAS {uas!r} here: not in a region {self._member.holder} holds "
                f"({', '.join(sorted(self._member.owned)) or 'none'})"
            )
        if not op.plan.waypoints:
            return f"{op.id} has no plan: its region is not known"
        region_id = departure_region(op, self._frame, self._member.map)
        if not self._policy.owns(op.id) or not self._member.owns(region_id):
            holder = self._member.holders.get(region_id)
            if holder is None or holder == self._member.holder:
                return (
                    f"{op.id} belongs to region {region_id}, held by no instance now "
                    "(a takeover under way): send it again in a few seconds"
                )
            return (
                f"{op.id} belongs to region {region_id}, held by instance {holder}: "
                "only that instance commands it"
            )
        if not self._may_act():
            return f"region {region_id}: this instance's lease has expired (self-fenced)"
        return ""


__all__ = ["CommandGate"]
