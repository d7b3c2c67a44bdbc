"""One simulated vehicle: its links, the receive path, and ``advance``.

The vehicle is driven by `advance(t_s)` (simulated seconds since fleet start) from the fleet
ticker, which integrates the kinematics in fixed steps of at most PHYSICS_DT_S, runs the mode
logic and sends due streams. Sockets feed `_receive`; nothing here blocks and nothing a peer
sends can raise out of a handler (bad input is counted in `counters`). The behaviour lives in
the layers :class:`Vehicle` inherits (see :mod:`sitl.core`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections.abc import Callable

from sitl import mission as mp
from sitl._mav import Inbound, msg_id_of, name_of
from sitl.commands import CommandHandling
from sitl.core import (
    HISTORY_PERIOD_S,
    PHYSICS_DT_S,
    PLANE_MODES,
    SEV_INFO,
    mission_items_from_specs,
)
from sitl.links import Link, TcpLink, UdpLink
from sitl.spec import (
    ARDUPILOT,
    SimClock,
    VehicleSpec,
)

_log = logging.getLogger(__name__)

AP_STORAGE_READY_S = 1.5  # simulated s after boot before ArduPilot takes an upload

__all__ = ["PHYSICS_DT_S", "PLANE_MODES", "Vehicle", "mission_items_from_specs", "stream_msg_id"]


class Vehicle(CommandHandling):
    """A PX4-like (or ArduPilot-like) vehicle. Read-only state is exposed for tests/reports."""

    def __init__(self, spec: VehicleSpec, sim_time: SimClock, *, t0_elapsed_s: float = 0.0) -> None:
        super().__init__(spec, sim_time, t0_elapsed_s=t0_elapsed_s)
        self.mission_server = mp.MissionServer(
            self, max_items=spec.max_mission_items, ardupilot=spec.autopilot == ARDUPILOT
        )

    @property
    def local_port(self) -> int:
        return self._udp.local_port if self._udp is not None else 0

    @property
    def api_local_port(self) -> int:
        return self._api.local_port if self._api is not None else 0

    @property
    def tcp_port(self) -> int:
        if self._tcp_server is None or not self._tcp_server.sockets:
            return 0
        return int(self._tcp_server.sockets[0].getsockname()[1])

    async def start(self) -> None:
        loop = asyncio.get_running_loop()
        spec = self.spec
        streaming = dict(spec.stream_rates_hz)
        if self.is_ardupilot:
            # ArduPilot streams nothing but HEARTBEAT until asked (SRx_ params at 0).
            streaming = {"HEARTBEAT": streaming.get("HEARTBEAT", 1.0)}
        want_udp = not self.is_ardupilot or spec.bind_port is not None
        if want_udp:
            port = spec.bind_port if spec.bind_port is not None else 18570 + spec.instance
            link = UdpLink(self, "gcs", streaming, (spec.gcs_host, spec.gcs_port))
            await loop.create_datagram_endpoint(lambda: link, local_addr=(spec.bind_host, port))
            self._udp = link
            self._links.append(link)
        if spec.api_link:
            port = spec.api_bind_port if spec.api_bind_port is not None else 18580 + spec.instance
            # PX4's API link binds 14580+i: keep the convention unless a port is given.
            if spec.api_bind_port is None:
                port = 14580 + spec.instance
            remote = (
                spec.gcs_host,
                spec.api_port if spec.api_port is not None else 14540 + spec.instance,
            )
            api = UdpLink(self, "api", streaming, remote, link_id=1)
            await loop.create_datagram_endpoint(lambda: api, local_addr=(spec.bind_host, port))
            self._api = api
            self._links.append(api)
        if self.is_ardupilot:
            tport = spec.tcp_port if spec.tcp_port is not None else 5760 + 10 * spec.instance
            self._tcp_server = await loop.create_server(
                lambda: TcpLink(self, {"HEARTBEAT": 1.0}), host=spec.bind_host, port=tport
            )

    async def stop(self) -> None:
        for link in list(self._links):
            link.closed = True
            tr = getattr(link, "transport", None)
            if tr is not None:
                tr.close()
        self._links.clear()
        if self._tcp_server is not None:
            self._tcp_server.close()
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self._tcp_server.wait_closed(), 1.0)

    def _out(self, link: Link, data: bytes) -> None:
        if not self._booted:
            return
        if self._link_loss:
            self.counters["dropped_link_loss"] += 1
            return
        if self._packet_loss > 0 and self._rng.random() < self._packet_loss:
            self.counters["dropped_packet_loss"] += 1
            return
        self.counters["tx_messages"] += 1
        if self._latency_s > 0:
            self.counters["delayed_latency"] += 1
            asyncio.get_running_loop().call_later(
                self._clock.real_delay_s(self._latency_s), link.transmit, data
            )
        else:
            link.transmit(data)

    def _in(self, link: Link, data: bytes, peer: tuple[str, int] | None) -> None:
        if not self._booted:
            return
        self.counters["rx_datagrams"] += 1
        if self._link_loss:
            self.counters["dropped_link_loss"] += 1
            return
        if self._packet_loss > 0 and self._rng.random() < self._packet_loss:
            self.counters["dropped_packet_loss"] += 1
            return
        if self._latency_s > 0:
            self.counters["delayed_latency"] += 1
            asyncio.get_running_loop().call_later(
                self._clock.real_delay_s(self._latency_s), self._receive, link, data, peer
            )
        else:
            self._receive(link, data, peer)

    def _receive(self, link: Link, data: bytes, peer: tuple[str, int] | None) -> None:
        try:
            if isinstance(link, UdpLink) and peer is not None:
                res = link.parser_for(peer).parse_datagram(data)
            elif isinstance(link, TcpLink):
                res = link.parser.parse_stream(data)
            else:
                return
            c = self.counters
            c["garbage"] += res.garbage
            c["bad_crc"] += res.bad_crc
            c["bad_frame"] += res.bad_frame
            c["truncated"] += res.truncated
            c["unknown_msgid"] += res.unknown_msgid
            if res.rejected_msg_ids:
                c["rejected_unsigned"] += res.unsigned_rejected
                c["rejected_bad_signature"] += res.bad_signature
                for mid in res.rejected_msg_ids:
                    name = name_of(mid) or f"MSG_{mid}"
                    self.rejected_messages[name] = self.rejected_messages.get(name, 0) + 1
            if (
                res.messages
                and isinstance(link, UdpLink)
                and peer is not None
                and not link.remote_learned
            ):
                # As PX4: the first peer that talks to us becomes the reply address.
                link.remote = peer
                link.remote_learned = True
            for m in res.messages:
                c["rx_messages"] += 1
                try:
                    self._handle(link, m)
                except Exception:
                    c["handler_errors"] += 1
                    _log.exception("sysid %d: error handling %s", self.sys_id, m.type)
        except Exception:
            self.counters["handler_errors"] += 1
            _log.exception("sysid %d: error receiving", self.sys_id)

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
        if self.mission_server.handle(link, m, time.monotonic()):
            return
        handler = _HANDLERS.get(t)
        if handler is not None:
            handler(self, link, m)
        elif t not in ("SYSTEM_TIME", "COMMAND_ACK", "STATUSTEXT", "PING"):
            self.counters["unhandled_msg"] += 1

    def storage_ready(self) -> bool:
        """ArduPilot refuses uploads (MAV_MISSION_NO_SPACE) until its mission storage is up,
        about 1.5 simulated s after it starts (measured at speed 1 and 5); PX4 at once."""
        return not self.is_ardupilot or self._t - self.spec.boot_at_s >= AP_STORAGE_READY_S

    def _on_command_message(self, link: Link, m: Inbound) -> None:
        self.counters["commands"] += 1
        self._on_command(link, m)

    def _on_set_mode(self, _link: Link, m: Inbound) -> None:
        self._set_mode_numbers(m.i("base_mode"), m.i("custom_mode"))

    def _on_param_list(self, link: Link, _m: Inbound) -> None:
        for i, name in enumerate(self._params):
            self._send_param(link, name, i)

    def _on_timesync(self, link: Link, m: Inbound) -> None:
        if m.i("tc1") == 0:
            link.send("TIMESYNC", tc1=int(self.sim_now_utc_s() * 1e9), ts1=m.i("ts1"))

    def advance(self, t_s: float) -> None:
        """Advance the vehicle to `t_s` simulated seconds after fleet start."""
        if t_s < self.spec.boot_at_s:
            self._t = t_s
            return
        if not self._booted:
            self._booted = True
            self._t = max(self._t, self.spec.boot_at_s)
            self.statustext(
                SEV_INFO, "Ready for takeoff!" if not self.is_ardupilot else "ArduPilot Ready"
            )
        dt_total = t_s - self._t
        if dt_total > 0:
            n = max(1, math.ceil(dt_total / PHYSICS_DT_S - 1e-9))
            n = min(n, 400)  # after a long stall take bigger steps rather than freezing the loop
            dt = dt_total / n
            for _ in range(n):
                self._t += dt
                self._update_faults()
                self._drift_jam(dt)
                self._auto_start()
                self._step(dt)
        self._t = t_s
        self.mission_server.tick(time.monotonic())
        if self._t >= self._next_history_t:
            self._next_history_t = self._t + HISTORY_PERIOD_S
            self.position_history.append(
                (self.sim_now_utc_s(), self.lat_deg, self.lon_deg, self.alt_amsl_m)
            )
        self._send_streams()


_HANDLERS: dict[str, Callable[[Vehicle, Link, Inbound], None]] = {
    "COMMAND_LONG": Vehicle._on_command_message,
    "COMMAND_INT": Vehicle._on_command_message,
    "SET_MODE": Vehicle._on_set_mode,
    "REQUEST_DATA_STREAM": Vehicle._on_request_data_stream,
    "PARAM_REQUEST_LIST": Vehicle._on_param_list,
    "PARAM_REQUEST_READ": Vehicle._on_param_read,
    "PARAM_SET": Vehicle._on_param_set,
    "TIMESYNC": Vehicle._on_timesync,
}


def stream_msg_id(name: str) -> int:
    mid = msg_id_of(name)
    if mid is None:
        raise KeyError(name)
    return mid
