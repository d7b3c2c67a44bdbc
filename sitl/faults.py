"""Faults of a simulated vehicle: scheduled (VehicleSpec.faults) or injected
(MAV_CMD_INJECT_FAILURE, :meth:`Faults.inject_fault`): GNSS jamming, spoofing, battery
drain/drop, motor failure, link loss, packet loss, latency.

Jamming: the reported position drifts from the true one at the fault's rate (m/s, default
1 m/s) times the jamming level (0.1 .. 1 over the first 10 s), per simulated second
(:meth:`Faults._drift_jam`, called from every physics step), whatever the number of
messages sent; the drift's direction wanders slowly (a random walk of 0.1 rad per sqrt(s)).
"""

from __future__ import annotations

import logging
import math

from sitl._mav import Inbound, const
from sitl.core import (
    LAND,
    R_ACCEPTED,
    R_UNSUPPORTED,
    SEV_CRITICAL,
    SEV_EMERGENCY,
    SEV_INFO,
    FaultState,
)
from sitl.flight import Flight
from sitl.links import Link
from sitl.spec import (
    DEFAULT_FAULT_VALUE,
    FaultKind,
    FaultSpec,
)

_log = logging.getLogger(__name__)

JAM_DIR_WANDER_RAD = 0.1  # random walk of the drift direction, rad per sqrt(simulated s)


class Faults(Flight):
    """Fault state and its effects (see the module docstring)."""

    def inject_fault(
        self, kind: FaultKind, *, duration_s: float | None = None, value: float | None = None
    ) -> None:
        """Start a fault now (the "on command" path of fault injection)."""
        self._faults.append(
            FaultState(FaultSpec(kind=kind, at_s=self._t, duration_s=duration_s, value=value))
        )
        self._update_faults()

    def _update_faults(self) -> None:
        t = self._t
        jam = False
        spoof = 0.0
        drain = 0.0
        link_loss = False
        ploss = 0.0
        latency = 0.0
        jam_rate = DEFAULT_FAULT_VALUE[FaultKind.GNSS_JAMMING]
        for f in self._faults:
            s = f.spec
            end = math.inf if s.duration_s is None else s.at_s + s.duration_s
            now_active = not f.done and s.at_s <= t < end
            value = s.value if s.value is not None else DEFAULT_FAULT_VALUE[s.kind]
            if now_active and not f.active:
                self._fault_started(s.kind, value)
            if f.active and not now_active:
                f.done = True
                self._fault_ended(s.kind)
            f.active = now_active
            if not now_active:
                continue
            if s.kind == FaultKind.GNSS_JAMMING:
                jam = True
                jam_rate = value
            elif s.kind == FaultKind.SPOOFING:
                spoof += value
            elif s.kind == FaultKind.BATTERY_DRAIN:
                drain += value
            elif s.kind == FaultKind.LINK_LOSS:
                link_loss = True
            elif s.kind == FaultKind.PACKET_LOSS:
                ploss = max(ploss, value)
            elif s.kind == FaultKind.LATENCY:
                latency = max(latency, value)
        if jam and self._jam_since is None:
            self._jam_since = t
        if not jam:
            self._jam_since = None
            self._jam_offset = (0.0, 0.0)
        self._jam_rate = jam_rate
        self._spoof_north_m = spoof
        self._drain_pct_s = drain
        self._link_loss = link_loss
        self._packet_loss = min(1.0, max(0.0, ploss))
        self._latency_s = max(0.0, latency)

    def _fault_started(self, kind: FaultKind, value: float) -> None:
        _log.info("sysid %d: fault %s starts (value %s)", self.sys_id, kind.name, value)
        if kind == FaultKind.GNSS_JAMMING:
            self.statustext(SEV_CRITICAL, "GNSS jamming detected: position degraded")
        elif kind == FaultKind.BATTERY_DROP:
            self.battery_pct = min(self.battery_pct, value)
        elif kind == FaultKind.MOTOR_FAILURE:
            self._motor_failed = True
            self.statustext(SEV_EMERGENCY, "Motor failure detected! Emergency landing")
            if self._armed and not self._landed:
                self._enter_mode(LAND)
        elif kind == FaultKind.LINK_LOSS:
            self.counters["link_loss_events"] = self.counters.get("link_loss_events", 0) + 1

    def _fault_ended(self, kind: FaultKind) -> None:
        _log.info("sysid %d: fault %s ends", self.sys_id, kind.name)
        if kind == FaultKind.GNSS_JAMMING:
            self.statustext(SEV_INFO, "GNSS recovered")

    def _cmd_inject_failure(self, _l: Link, _m: Inbound, p: list[float]) -> int:
        unit, ftype = int(p[0]), int(p[1])
        off = ftype == const("FAILURE_TYPE_OFF")
        kinds = {
            const("FAILURE_UNIT_SENSOR_GPS"): FaultKind.GNSS_JAMMING,
            const("FAILURE_UNIT_SYSTEM_MOTOR"): FaultKind.MOTOR_FAILURE,
            const("FAILURE_UNIT_SYSTEM_BATTERY"): FaultKind.BATTERY_DROP,
            const("FAILURE_UNIT_SYSTEM_MAVLINK_SIGNAL"): FaultKind.LINK_LOSS,
        }
        kind = kinds.get(unit)
        if kind is None:
            return R_UNSUPPORTED
        if ftype == const("FAILURE_TYPE_OK"):
            for f in self._faults:
                if f.spec.kind == kind and f.active:
                    f.done = True
            return R_ACCEPTED
        if not off and kind != FaultKind.GNSS_JAMMING:
            return R_UNSUPPORTED
        self.inject_fault(kind, duration_s=None if kind != FaultKind.LINK_LOSS else 10.0)
        return R_ACCEPTED

    def _drift_jam(self, dt_s: float) -> None:
        """Advance the jamming drift of the reported position by ``dt_s`` simulated s."""
        if self._jam_since is None:
            return
        step_m = self._jam_rate * self._jam_level() * dt_s
        self._jam_dir += self._rng.gauss(0.0, JAM_DIR_WANDER_RAD * math.sqrt(dt_s))
        self._jam_offset = (
            self._jam_offset[0] + step_m * math.cos(self._jam_dir),
            self._jam_offset[1] + step_m * math.sin(self._jam_dir),
        )
