"""One simulated vehicle: the object that holds its parts and drives them.

The parts, each given what it needs and none importing this module: :class:`Faults` (fault
state, GNSS quality), :class:`Flight` (modes, mission execution, physics, battery),
:class:`Transport` (links, receive path), :class:`Telemetry` (streams),
:class:`CommandHandler` (commands, parameters) and :class:`MissionServer` (the mission
protocol). The vehicle is the :class:`sitl.core.Announcer` of the parts (STATUSTEXT and
other messages on every link) and the :class:`sitl.mission.MissionHost` of the mission server.

The vehicle is driven by `advance(t_s)` (simulated seconds since fleet start) from the fleet
ticker, which integrates the kinematics in fixed steps of at most PHYSICS_DT_S, runs the mode
logic and sends due streams. Sockets feed the transport; nothing here blocks and nothing a
peer sends can raise out of a handler (bad input is counted in `counters`).
"""

from __future__ import annotations

import asyncio
import logging
import math
import random
import time
from typing import Any

from sitl import mission as mp
from sitl._mav import Inbound, msg_id_of
from sitl.commands import CommandHandler
from sitl.core import (
    COUNTER_NAMES,
    HISTORY_PERIOD_S,
    PHYSICS_DT_S,
    PLANE_MODES,
    SEV_INFO,
    Timeline,
    mission_items_from_specs,
)
from sitl.faults import Faults
from sitl.flight import Flight
from sitl.links import Link
from sitl.physics import KinState
from sitl.spec import ARDUPILOT, FIXED_WING, FaultKind, Limits, SimClock, VehicleSpec
from sitl.telemetry import Telemetry
from sitl.transport import Transport

_log = logging.getLogger(__name__)

AP_STORAGE_READY_S = 1.5  # simulated s after boot before ArduPilot takes an upload
REBOOT_DELAY_S = 0.4  # PX4 px4_reboot_request(400 ms): the COMMAND_ACK goes out first
REBOOT_DOWN_S = 3.0  # simulated s without a word between the reboot and the new boot
IGNORED_MESSAGES = frozenset({"SYSTEM_TIME", "COMMAND_ACK", "STATUSTEXT", "PING"})

__all__ = ["PHYSICS_DT_S", "PLANE_MODES", "Vehicle", "mission_items_from_specs", "stream_msg_id"]


def _protocol_now_s() -> float:
    """The time of the mission protocol's timers (re-request, operation timeout): the running
    loop's, i.e. real seconds on an ordinary loop and simulated seconds on a fast-time loop
    (wall time there would fire them by how loaded the machine is, not by the simulation)."""
    try:
        return asyncio.get_running_loop().time()
    except RuntimeError:  # no loop running (a synchronous caller): real seconds
        return time.monotonic()


class Vehicle:
    """A PX4-like (or ArduPilot-like) vehicle. Read-only state is exposed for tests/reports."""

    def __init__(self, spec: VehicleSpec, sim_time: SimClock, *, t0_elapsed_s: float = 0.0) -> None:
        self.spec = spec
        self.sys_id = spec.system_id
        self.is_ardupilot = spec.autopilot == ARDUPILOT
        self.is_fixed_wing = spec.kind == FIXED_WING
        self.counters: dict[str, int] = dict.fromkeys(COUNTER_NAMES, 0)
        self.statustexts: list[tuple[float, int, str]] = []
        self.position_history: list[tuple[float, float, float, float]] = []
        self.time = Timeline(spec, sim_time, t0_elapsed_s)
        self._next_history_t = 0.0
        # one random stream for the vehicle: jamming drift, GNSS noise, packet loss draws
        self._rng = random.Random(spec.seed * 1000003 + self.sys_id)
        self.faults = Faults(
            spec=spec, time=self.time, rng=self._rng, counters=self.counters, announce=self
        )
        self.flight = Flight(spec=spec, time=self.time, faults=self.faults, announce=self)
        self.executor = self.flight.mission
        self.transport = Transport(
            spec=spec,
            time=self.time,
            faults=self.faults,
            rng=self._rng,
            counters=self.counters,
            deliver=self._handle,
        )
        self.telemetry = Telemetry(
            spec=spec,
            time=self.time,
            flight=self.flight,
            mission=self.executor,
            faults=self.faults,
            links=self.transport.links,
            rng=self._rng,
            counters=self.counters,
        )
        self.commands = CommandHandler(
            time=self.time,
            flight=self.flight,
            mission=self.executor,
            faults=self.faults,
            telemetry=self.telemetry,
            counters=self.counters,
            announce=self,
            reboot=self.reboot,
        )
        self._handlers = self.commands.handlers()
        self.reboots = 0  # reboots done (MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, :meth:`reboot`)
        self._reboot_at_s: float | None = None
        self.mission_server = mp.MissionServer(
            self, max_items=spec.max_mission_items, ardupilot=self.is_ardupilot
        )

    # Read-only state ------------------------------------------------------------------

    @property
    def signing_key(self) -> bytes | None:
        return self.transport.signing_key

    @property
    def rejected_messages(self) -> dict[str, int]:
        """Signing on: message name -> count of incoming messages dropped for their signature."""
        return self.transport.rejected_messages

    @property
    def lat_deg(self) -> float:
        return self.flight.lat_deg

    @property
    def lon_deg(self) -> float:
        return self.flight.lon_deg

    @property
    def alt_amsl_m(self) -> float:
        return self.flight.k.alt_amsl_m

    @property
    def k(self) -> KinState:
        """The true kinematic state (local frame around home)."""
        return self.flight.k

    @property
    def home(self) -> tuple[float, float, float]:
        """(lat deg, lon deg, alt AMSL m) of home."""
        return self.flight.home

    @property
    def ground_alt_m(self) -> float:
        return self.flight.ground_alt_m

    @property
    def lim(self) -> Limits:
        """The flight envelope of the vehicle's kind (``VehicleSpec.limits()``)."""
        return self.flight.lim

    def speed_item(self, it: mp.RawItem) -> float | None:
        """The speed a DO_CHANGE_SPEED item sets (see :meth:`MissionExecutor.speed_item`)."""
        return self.executor.speed_item(it)

    @property
    def mode(self) -> str:
        return self.flight.mode

    @property
    def armed(self) -> bool:
        return self.flight.armed

    @property
    def landed(self) -> bool:
        return self.flight.landed

    @property
    def mission(self) -> tuple[mp.RawItem, ...]:
        return tuple(self.executor.items)

    @property
    def mission_current_seq(self) -> int:
        return self.executor.seq

    @property
    def battery_pct(self) -> float:
        return self.flight.battery_pct

    @property
    def motor_failed(self) -> bool:
        return self.faults.motor_failed

    @property
    def local_port(self) -> int:
        return self.transport.local_port

    @property
    def api_local_port(self) -> int:
        return self.transport.api_local_port

    @property
    def tcp_port(self) -> int:
        return self.transport.tcp_port

    def reported_position(self) -> tuple[float, float, float]:
        """Position as telemetry reports it (spoofing offset, jamming drift; without noise)."""
        k, faults = self.flight.k, self.faults
        n = k.north_m + faults.spoof_north_m + faults.jam_offset[0]
        e = k.east_m + faults.jam_offset[1]
        lat, lon = self.flight.frame.to_latlon(n, e)
        return lat, lon, k.alt_amsl_m

    def sim_now_utc_s(self) -> float:
        return self.time.sim_now_utc_s()

    # Actions --------------------------------------------------------------------------

    def inject_fault(
        self, kind: FaultKind, *, duration_s: float | None = None, value: float | None = None
    ) -> None:
        """Start a fault now (the "on command" path of fault injection)."""
        self.faults.inject(kind, self.flight, duration_s=duration_s, value=value)

    def reboot(self) -> None:
        """Reboot REBOOT_DELAY_S from now (simulated): silent for REBOOT_DOWN_S, then a new
        boot (time_boot_ms from 0, GNSS acquired again, home taken again, disarmed in the
        boot mode, the stored mission and parameters kept, ArduPilot's TCP connections
        dropped and its streams off until asked again)."""
        self._reboot_at_s = self.time.t_s + REBOOT_DELAY_S

    def _restart(self) -> None:
        self._reboot_at_s = None
        self.reboots += 1
        clock = self.time
        clock.boot_at_s = clock.t_s + REBOOT_DOWN_S
        clock.booted = False
        _log.info("sysid %d: rebooting", self.sys_id)
        self.flight.reboot()
        self.mission_server.reset()
        self.transport.reboot()

    def arm(self, *, force: bool = False) -> int:
        """Arm as COMPONENT_ARM_DISARM would (the MAV_RESULT)."""
        return self.flight.arm(force=force)

    async def start(self) -> None:
        await self.transport.start()

    async def stop(self) -> None:
        await self.transport.stop()

    # Announcer ------------------------------------------------------------------------

    def statustext(self, severity: int, text: str) -> None:
        self.statustexts.append((self.sim_now_utc_s(), severity, text))
        _log.info("sysid %d: %s", self.sys_id, text)
        self.broadcast("STATUSTEXT", severity=severity, text=text.encode()[:50])

    def broadcast(self, name: str, **fields: Any) -> None:
        self.transport.broadcast(name, **fields)

    def mission_current_changed(self) -> None:
        self.telemetry.send_mission_current()

    # MissionHost ----------------------------------------------------------------------

    def mission_items(self) -> list[mp.RawItem]:
        return self.executor.wire_items()

    def accept_mission(self, items: list[mp.RawItem], flagged_current: int | None) -> None:
        self.flight.accept_mission(items, flagged_current)

    def clear_mission(self) -> None:
        self.flight.clear_mission()

    def set_current(self, seq: int) -> bool:
        return self.executor.set_current(seq)

    def send(self, peer: object, name: str, **fields: Any) -> None:
        if isinstance(peer, Link):
            peer.send(name, **fields)

    def count(self, counter: str) -> None:
        self.counters[counter] = self.counters.get(counter, 0) + 1

    def storage_ready(self) -> bool:
        """ArduPilot refuses uploads (MAV_MISSION_NO_SPACE) until its mission storage is up,
        about 1.5 simulated s after it starts (measured at speed 1 and 5); PX4 at once."""
        return not self.is_ardupilot or self.time.t_s - self.time.boot_at_s >= AP_STORAGE_READY_S

    # Receive path and time ------------------------------------------------------------

    def _handle(self, link: Link, m: Inbound) -> None:
        if m.has("target_system"):
            ts = m.i("target_system")
            if ts not in (0, self.sys_id):
                self.counters["dropped_other_sysid"] += 1
                return
            if m.has("target_component") and m.i("target_component") not in (0, 1):
                self.counters["dropped_other_compid"] += 1
                return
        t = m.type
        if t == "HEARTBEAT":
            return
        if self.mission_server.handle(link, m, _protocol_now_s()):
            return
        handler = self._handlers.get(t)
        if handler is not None:
            handler(link, m)
        elif t not in IGNORED_MESSAGES:
            self.counters["unhandled_msg"] += 1

    def advance(self, t_s: float) -> None:
        """Advance the vehicle to `t_s` simulated seconds after fleet start."""
        clock = self.time
        if t_s < clock.boot_at_s:
            if self.reboots:  # rebooting: the airframe is still there (and falls if flying)
                self._integrate(t_s)
            clock.t_s = t_s
            return
        if not clock.booted:
            clock.booted = True
            clock.t_s = max(clock.t_s, clock.boot_at_s)
            self.statustext(
                SEV_INFO, "Ready for takeoff!" if not self.is_ardupilot else "ArduPilot Ready"
            )
        self._integrate(t_s)
        clock.t_s = t_s
        if self._reboot_at_s is not None and t_s >= self._reboot_at_s:
            self._restart()
            return
        self.mission_server.tick(_protocol_now_s())
        if clock.t_s >= self._next_history_t:
            self._next_history_t = clock.t_s + HISTORY_PERIOD_S
            self.position_history.append(
                (self.sim_now_utc_s(), self.lat_deg, self.lon_deg, self.alt_amsl_m)
            )
        self.telemetry.send_streams()

    def _integrate(self, t_s: float) -> None:
        """The kinematics and mode logic up to ``t_s``, in fixed steps of at most
        PHYSICS_DT_S."""
        clock = self.time
        dt_total = t_s - clock.t_s
        if dt_total <= 0:
            return
        n = max(1, math.ceil(dt_total / PHYSICS_DT_S - 1e-9))
        n = min(n, 400)  # after a long stall take bigger steps rather than freezing the loop
        dt = dt_total / n
        for _ in range(n):
            clock.t_s += dt
            self.faults.update(self.flight)
            self.faults.drift_jam(dt)
            self.flight.auto_start()
            self.flight.step(dt)


def stream_msg_id(name: str) -> int:
    mid = msg_id_of(name)
    if mid is None:
        raise KeyError(name)
    return mid
