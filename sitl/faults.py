"""Faults of a simulated vehicle: scheduled (VehicleSpec.faults) or injected
(MAV_CMD_INJECT_FAILURE, :meth:`Faults.inject`): GNSS jamming, spoofing, battery drain/drop,
motor failure, link loss, packet loss, latency; and the GNSS quality they leave (fix type,
jamming level).

:class:`Faults` holds the fault state; the other parts read it (the flight model the motor
and the battery drain, the transport the link faults, telemetry the reported position). A
fault that acts on the flight (battery drop, motor failure) does so through the
:class:`FaultTarget` passed to :meth:`Faults.update`.

Jamming: the reported position drifts from the true one at the fault's rate (m/s, default
1 m/s) times the jamming level (0.1 .. 1 over the first 10 s), per simulated second
(:meth:`Faults.drift_jam`, called from every physics step), whatever the number of
messages sent; the drift's direction wanders slowly (a random walk of 0.1 rad per sqrt(s)).
"""

from __future__ import annotations

import logging
import math
import random
from dataclasses import dataclass
from typing import Protocol

from sitl.core import SEV_CRITICAL, SEV_EMERGENCY, SEV_INFO, Announcer, Timeline
from sitl.spec import DEFAULT_FAULT_VALUE, FaultKind, FaultSpec, VehicleSpec

_log = logging.getLogger(__name__)

JAM_DIR_WANDER_RAD = 0.1  # random walk of the drift direction, rad per sqrt(simulated s)


@dataclass(slots=True)
class FaultState:
    spec: FaultSpec
    active: bool = False
    done: bool = False


class FaultTarget(Protocol):
    """What a starting fault does to the flight."""

    def drop_battery(self, pct: float) -> None:
        """The battery falls to at most ``pct`` percent."""
        ...

    def land_now(self) -> None:
        """Motor failure: land at once if flying."""
        ...


class Faults:
    """Fault state and its effects (see the module docstring)."""

    def __init__(
        self,
        *,
        spec: VehicleSpec,
        time: Timeline,
        rng: random.Random,
        counters: dict[str, int],
        announce: Announcer,
    ) -> None:
        self._spec = spec
        self._time = time
        self._rng = rng
        self._counters = counters
        self._announce = announce
        self.faults = [FaultState(f) for f in spec.faults]
        self._jam_rate = DEFAULT_FAULT_VALUE[FaultKind.GNSS_JAMMING]
        self._jam_since: float | None = None
        self.jam_offset = (0.0, 0.0)  # (north, east) m of the reported position
        self._jam_dir = rng.uniform(0.0, 2.0 * math.pi)
        self.spoof_north_m = 0.0
        self.drain_pct_s = 0.0
        self.link_loss = False
        self.packet_loss = 0.0
        self.latency_s = 0.0
        self.motor_failed = False

    def inject(
        self,
        kind: FaultKind,
        target: FaultTarget,
        *,
        duration_s: float | None = None,
        value: float | None = None,
    ) -> None:
        """Start a fault now (the "on command" path of fault injection)."""
        self.faults.append(
            FaultState(
                FaultSpec(kind=kind, at_s=self._time.t_s, duration_s=duration_s, value=value)
            )
        )
        self.update(target)

    def clear(self, kind: FaultKind) -> None:
        """End every active fault of ``kind`` (MAV_CMD_INJECT_FAILURE with FAILURE_TYPE_OK)."""
        for f in self.faults:
            if f.spec.kind == kind and f.active:
                f.done = True

    def update(self, target: FaultTarget) -> None:
        """Start and end faults at the current simulated time and sum their effects."""
        t = self._time.t_s
        jam = False
        spoof = 0.0
        drain = 0.0
        link_loss = False
        ploss = 0.0
        latency = 0.0
        jam_rate = DEFAULT_FAULT_VALUE[FaultKind.GNSS_JAMMING]
        for f in self.faults:
            s = f.spec
            end = math.inf if s.duration_s is None else s.at_s + s.duration_s
            now_active = not f.done and s.at_s <= t < end
            value = s.value if s.value is not None else DEFAULT_FAULT_VALUE[s.kind]
            if now_active and not f.active:
                self._started(s.kind, value, target)
            if f.active and not now_active:
                f.done = True
                self._ended(s.kind)
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
            self.jam_offset = (0.0, 0.0)
        self._jam_rate = jam_rate
        self.spoof_north_m = spoof
        self.drain_pct_s = drain
        self.link_loss = link_loss
        self.packet_loss = min(1.0, max(0.0, ploss))
        self.latency_s = max(0.0, latency)

    def _started(self, kind: FaultKind, value: float, target: FaultTarget) -> None:
        _log.info("sysid %d: fault %s starts (value %s)", self._spec.system_id, kind.name, value)
        if kind == FaultKind.GNSS_JAMMING:
            self._announce.statustext(SEV_CRITICAL, "GNSS jamming detected: position degraded")
        elif kind == FaultKind.BATTERY_DROP:
            target.drop_battery(value)
        elif kind == FaultKind.MOTOR_FAILURE:
            self.motor_failed = True
            self._announce.statustext(SEV_EMERGENCY, "Motor failure detected! Emergency landing")
            target.land_now()
        elif kind == FaultKind.LINK_LOSS:
            self._counters["link_loss_events"] = self._counters.get("link_loss_events", 0) + 1

    def _ended(self, kind: FaultKind) -> None:
        _log.info("sysid %d: fault %s ends", self._spec.system_id, kind.name)
        if kind == FaultKind.GNSS_JAMMING:
            self._announce.statustext(SEV_INFO, "GNSS recovered")

    def drift_jam(self, dt_s: float) -> None:
        """Advance the jamming drift of the reported position by ``dt_s`` simulated s."""
        if self._jam_since is None:
            return
        step_m = self._jam_rate * self.jam_level() * dt_s
        self._jam_dir += self._rng.gauss(0.0, JAM_DIR_WANDER_RAD * math.sqrt(dt_s))
        self.jam_offset = (
            self.jam_offset[0] + step_m * math.cos(self._jam_dir),
            self.jam_offset[1] + step_m * math.sin(self._jam_dir),
        )

    def jam_level(self) -> float:
        """0 (clean) .. 1 (fully jammed): jamming degrades the receiver over ~10 s."""
        if self._jam_since is None:
            return 0.0
        return min(1.0, (self._time.t_s - self._jam_since) / 10.0 + 0.1)

    def acquiring_gnss(self) -> bool:
        """No fix yet since the last boot (``VehicleSpec.gnss_fix_after_s``; a reboot
        acquires GNSS again)."""
        return self._time.t_s - self._time.boot_at_s < self._spec.gnss_fix_after_s

    def gps_fix_type(self) -> int:
        if self.acquiring_gnss():
            return 0
        lvl = self.jam_level()
        if lvl == 0.0:
            return 3
        if lvl < 0.4:
            return 3
        if lvl < 0.8:
            return 2
        return 1
