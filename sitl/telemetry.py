"""Telemetry of a simulated vehicle: the streams each link carries (rates set by
SET_MESSAGE_INTERVAL / REQUEST_DATA_STREAM), one-shot messages (REQUEST_MESSAGE), and the
content of each message (HEARTBEAT mode numbers, positions as reported, GPS quality).

:class:`Telemetry` reads the flight and fault state it is given and writes to the vehicle's
links (the list the transport keeps)."""

from __future__ import annotations

import logging
import math
import random
import time
from collections.abc import Callable

from sitl._mav import Inbound, const, name_of
from sitl.core import (
    AP_STREAM_GROUPS,
    COPTER_MODES,
    GUIDED,
    HOLD,
    LAND,
    MISSION,
    PLANE_MODES,
    POSCTL,
    PX4_MAIN_AUTO,
    PX4_MAIN_POSCTL,
    PX4_SUB,
    R_ACCEPTED,
    R_UNSUPPORTED,
    REQUESTABLE,
    RTL,
    SENSOR_BATTERY,
    SENSOR_GPS,
    SENSOR_MOTORS,
    SENSORS_PRESENT,
    STREAMS,
    TAKEOFF,
    Timeline,
)
from sitl.executor import MissionExecutor
from sitl.faults import Faults
from sitl.flight import Flight
from sitl.links import Link, StreamState, send_ack
from sitl.spec import VehicleSpec

_log = logging.getLogger(__name__)

AP_BOOT_S = 2.0
"""ArduPilot's HEARTBEATs say MAV_STATE_BOOT this long after a boot (ArduCopter 4.6 SITL)."""
PX4_INIT_AFTER_FIX_S = 2.0
"""PX4's HEARTBEATs say MAV_STATE_UNINIT until this long after its first fix (v1.15 SIH)."""
HOME_PRE_FIX_OFFSET_M = -2.0
"""A PX4's HOME_POSITION altitude before its fix, off its true home (PX4 SIH's wandered
by up to 2 m while its estimator converged)."""


class Telemetry:
    """Streams and message content (see the module docstring)."""

    def __init__(
        self,
        *,
        spec: VehicleSpec,
        time: Timeline,
        flight: Flight,
        mission: MissionExecutor,
        faults: Faults,
        links: list[Link],
        rng: random.Random,
        counters: dict[str, int],
    ) -> None:
        self.spec = spec
        self._time = time
        self._flight = flight
        self._mission = mission
        self._faults = faults
        self._links = links
        self._rng = rng
        self._counters = counters
        self.sys_id = spec.system_id
        self.is_ardupilot = flight.is_ardupilot
        self.is_fixed_wing = flight.is_fixed_wing

    def send_mission_current(self) -> None:
        if self._time.booted:
            for link in list(self._links):
                if (
                    link.streams.get("MISSION_CURRENT", StreamState(0.0)).period_s > 0
                    or not self.is_ardupilot
                ):
                    self.send_stream(link, "MISSION_CURRENT")

    def send_streams(self) -> None:
        if not self._time.booted:
            return
        now_real = time.monotonic()
        min_real = 1.0 / self.spec.max_real_stream_hz
        for link in list(self._links):
            for name, st in link.streams.items():
                if st.period_s <= 0 or self._time.t_s < st.next_due_s:
                    continue
                if now_real - st.last_real_s < min_real:
                    continue
                st.next_due_s = max(st.next_due_s + st.period_s, self._time.t_s)
                st.last_real_s = now_real
                self.send_stream(link, name)

    def custom_mode(self) -> tuple[int, int]:
        mode = self._flight.mode
        if self.is_ardupilot:
            table = PLANE_MODES if self.is_fixed_wing else COPTER_MODES
            return const("MAV_MODE_FLAG_CUSTOM_MODE_ENABLED") | 16, table[mode]
        if mode == POSCTL:
            return 1 | 16 | 64, PX4_MAIN_POSCTL << 16  # custom | stabilize | manual input
        return 1 | 4 | 8 | 16, (PX4_MAIN_AUTO << 16) | (
            PX4_SUB[HOLD if mode == GUIDED else mode] << 24
        )

    def _system_status(self) -> int:
        if not self._flight.armed and self._booting():
            return const("MAV_STATE_BOOT") if self.is_ardupilot else const("MAV_STATE_UNINIT")
        if self._faults.motor_failed or self._flight.bat_level >= 3:
            return const("MAV_STATE_EMERGENCY")
        if self._flight.bat_level == 2 or self._faults.jam_level() >= 0.8:
            return const("MAV_STATE_CRITICAL")
        return const("MAV_STATE_ACTIVE") if self._flight.armed else const("MAV_STATE_STANDBY")

    def _booting(self) -> bool:
        """Whether the autopilot is still starting (measured on the real SITL after a
        restart): ArduPilot 4.6 sends MAV_STATE_BOOT for its first ~2 s; PX4 v1.15 sends
        MAV_STATE_UNINIT until its arming state leaves INIT, ~2 s after its first position
        with a fix (36 s after boot for a fix at 33 s). Each boot starts it again."""
        up_s = self._time.t_s - self._time.boot_at_s
        if self.is_ardupilot:
            return up_s < AP_BOOT_S
        return up_s < self.spec.gnss_fix_after_s + PX4_INIT_AFTER_FIX_S

    def health(self) -> int:
        h = SENSORS_PRESENT
        if self._faults.jam_level() >= 0.4:
            h &= ~SENSOR_GPS
        if self._faults.motor_failed:
            h &= ~SENSOR_MOTORS
        if self._flight.bat_level >= 2:
            h &= ~SENSOR_BATTERY
        return h

    def _noisy_reported(self) -> tuple[float, float, float]:
        n = self._flight.k.north_m + self._faults.spoof_north_m + self._faults.jam_offset[0]
        e = self._flight.k.east_m + self._faults.jam_offset[1]
        if self.spec.gnss_noise_m > 0:
            n += self._rng.gauss(0.0, self.spec.gnss_noise_m)
            e += self._rng.gauss(0.0, self.spec.gnss_noise_m)
        lat, lon = self._flight.frame.to_latlon(n, e)
        return lat, lon, self._flight.k.alt_amsl_m

    def send_stream(self, link: Link, name: str) -> None:
        """Send one ``name`` message (a stream or a one-shot request) on ``link``."""
        sender = _SENDERS.get(name)
        if sender is not None:
            sender(self, link)

    def _tx_heartbeat(self, link: Link) -> None:
        base, custom = self.custom_mode()
        if self._flight.armed:
            base |= const("MAV_MODE_FLAG_SAFETY_ARMED")
        mav_type = (
            const("MAV_TYPE_FIXED_WING") if self.is_fixed_wing else const("MAV_TYPE_QUADROTOR")
        )
        ap = (
            const("MAV_AUTOPILOT_ARDUPILOTMEGA")
            if self.is_ardupilot
            else const("MAV_AUTOPILOT_PX4")
        )
        link.send(
            "HEARTBEAT",
            type=mav_type,
            autopilot=ap,
            base_mode=base,
            custom_mode=custom,
            system_status=self._system_status(),
            mavlink_version=3,
        )

    def _tx_global_position_int(self, link: Link) -> None:
        k = self._flight.k
        tb = self._time.time_boot_ms()
        lat, lon, alt = self._noisy_reported()
        if self._faults.acquiring_gnss():
            lat = lon = 0.0  # no global position before the first fix
        link.send(
            "GLOBAL_POSITION_INT",
            time_boot_ms=tb,
            lat=round(lat * 1e7),
            lon=round(lon * 1e7),
            alt=round(alt * 1000),
            relative_alt=round((alt - self._flight.home[2]) * 1000),
            vx=round(k.vn_mps * 100),
            vy=round(k.ve_mps * 100),
            vz=round(-k.vup_mps * 100),
            hdg=round(math.degrees(k.yaw_rad) % 360 * 100) % 36000,
        )

    def _tx_gps_raw_int(self, link: Link) -> None:
        k = self._flight.k
        lat, lon, alt = self._noisy_reported()
        lvl = self._faults.jam_level()
        fix = self._faults.gps_fix_type()
        hdop = 0.8 + 30.0 * lvl * lvl  # eph grows with the jamming level
        h_acc_m = 1.0 + self.spec.gnss_noise_m + 60.0 * lvl * lvl
        if fix == 0 and self._faults.acquiring_gnss():
            h_acc_m = 100.0  # (PX4 SIH without a fix: 100 m)
        sats = max(0, round(14 - 12 * lvl))
        gs = math.hypot(k.vn_mps, k.ve_mps)
        link.send(
            "GPS_RAW_INT",
            time_usec=int(self._time.sim_now_utc_s() * 1e6),
            fix_type=fix,
            lat=round(lat * 1e7),
            lon=round(lon * 1e7),
            alt=round(alt * 1000),
            eph=min(65534, round(hdop * 100)),
            epv=min(65534, round((1.2 + 40 * lvl * lvl) * 100)),
            vel=round(gs * 100),
            cog=round(math.degrees(math.atan2(k.ve_mps, k.vn_mps)) % 360 * 100) % 36000,
            satellites_visible=sats,
            alt_ellipsoid=round((alt + 47.0) * 1000),
            h_acc=round(h_acc_m * 1000),
            v_acc=round(h_acc_m * 1500),
            vel_acc=round(300 + 2000 * lvl),
            hdg_acc=0,
            yaw=0,
        )

    def _tx_sys_status(self, link: Link) -> None:
        mv, ca = self._battery_electrics()
        link.send(
            "SYS_STATUS",
            onboard_control_sensors_present=SENSORS_PRESENT,
            onboard_control_sensors_enabled=SENSORS_PRESENT,
            onboard_control_sensors_health=self.health(),
            load=250,
            voltage_battery=mv,
            current_battery=ca,
            battery_remaining=round(self._flight.battery_pct),
            drop_rate_comm=0,
            errors_comm=self._counters["bad_crc"] + self._counters["garbage"] % 65535,
            errors_count1=0,
            errors_count2=0,
            errors_count3=0,
            errors_count4=0,
        )

    def _tx_battery_status(self, link: Link) -> None:
        mv, ca = self._battery_electrics()
        cell = mv // 4
        charge = [
            const("MAV_BATTERY_CHARGE_STATE_OK"),
            const("MAV_BATTERY_CHARGE_STATE_LOW"),
            const("MAV_BATTERY_CHARGE_STATE_CRITICAL"),
            const("MAV_BATTERY_CHARGE_STATE_EMERGENCY"),
        ][self._flight.bat_level]
        remaining_s = int(self._flight.battery_pct / 100.0 * self.spec.battery_capacity_s)
        link.send(
            "BATTERY_STATUS",
            id=0,
            battery_function=const("MAV_BATTERY_FUNCTION_ALL"),
            type=const("MAV_BATTERY_TYPE_LIPO"),
            temperature=2500,
            voltages=[cell, cell, cell, cell, 65535, 65535, 65535, 65535, 65535, 65535],
            current_battery=ca,
            current_consumed=round((100.0 - self._flight.battery_pct) * 50),
            energy_consumed=-1,
            battery_remaining=round(self._flight.battery_pct),
            time_remaining=remaining_s,
            charge_state=charge,
        )

    def _tx_extended_sys_state(self, link: Link) -> None:
        if self._flight.landed:
            landed = const("MAV_LANDED_STATE_ON_GROUND")
        elif self._flight.mode == TAKEOFF:
            landed = const("MAV_LANDED_STATE_TAKEOFF")
        elif self._flight.mode == LAND or (
            self._flight.mode == RTL and self._flight.rtl_phase == 3
        ):
            landed = const("MAV_LANDED_STATE_LANDING")
        else:
            landed = const("MAV_LANDED_STATE_IN_AIR")
        link.send(
            "EXTENDED_SYS_STATE",
            vtol_state=const("MAV_VTOL_STATE_UNDEFINED"),
            landed_state=landed,
        )

    def _tx_home_position(self, link: Link) -> None:
        alt = self._flight.home[2]
        if self._faults.acquiring_gnss():  # (VehicleSpec.gnss_fix_after_s)
            if self.is_ardupilot:
                return
            alt += HOME_PRE_FIX_OFFSET_M
        link.send(
            "HOME_POSITION",
            latitude=round(self._flight.home[0] * 1e7),
            longitude=round(self._flight.home[1] * 1e7),
            altitude=round(alt * 1000),
            x=0.0,
            y=0.0,
            z=0.0,
            q=[1.0, 0.0, 0.0, 0.0],
            approach_x=0.0,
            approach_y=0.0,
            approach_z=0.0,
            time_usec=int(self._time.sim_now_utc_s() * 1e6),
        )

    def _tx_mission_current(self, link: Link) -> None:
        in_mission = 1 if self._flight.mode == MISSION else 2
        link.send(
            "MISSION_CURRENT",
            seq=self._mission.seq,
            total=len(self._mission.items),
            mission_state=self._mission.state,
            mission_mode=in_mission if self._mission.items else 0,
        )

    def _tx_attitude(self, link: Link) -> None:
        k = self._flight.k
        tb = self._time.time_boot_ms()
        link.send(
            "ATTITUDE",
            time_boot_ms=tb,
            roll=k.roll_rad,
            pitch=k.pitch_rad,
            yaw=k.yaw_rad,
            rollspeed=0.0,
            pitchspeed=0.0,
            yawspeed=0.0,
        )

    def _tx_system_time(self, link: Link) -> None:
        tb = self._time.time_boot_ms()
        link.send(
            "SYSTEM_TIME", time_unix_usec=int(self._time.sim_now_utc_s() * 1e6), time_boot_ms=tb
        )

    def _tx_vfr_hud(self, link: Link) -> None:
        k = self._flight.k
        link.send(
            "VFR_HUD",
            airspeed=k.airspeed_mps,
            groundspeed=math.hypot(k.vn_mps, k.ve_mps),
            heading=round(math.degrees(k.yaw_rad) % 360) % 360,
            throttle=50 if self._flight.armed else 0,
            alt=k.alt_amsl_m,
            climb=k.vup_mps,
        )

    def _tx_autopilot_version(self, link: Link) -> None:
        caps = (
            const("MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT")
            | const("MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT")
            | const("MAV_PROTOCOL_CAPABILITY_MISSION_INT")
            | const("MAV_PROTOCOL_CAPABILITY_COMMAND_INT")
            | const("MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT")
            | const("MAV_PROTOCOL_CAPABILITY_MAVLINK2")
        )
        version = (1 << 24) | (15 << 16) | (4 << 8) | 255  # 1.15.4 official, like the measured PX4
        link.send(
            "AUTOPILOT_VERSION",
            capabilities=caps,
            flight_sw_version=version,
            middleware_sw_version=0,
            os_sw_version=0,
            board_version=0,
            flight_custom_version=[0] * 8,
            middleware_custom_version=[0] * 8,
            os_custom_version=[0] * 8,
            vendor_id=0,
            product_id=0,
            uid=self.sys_id,
            uid2=[0] * 18,
        )

    def _battery_electrics(self) -> tuple[int, int]:
        """(pack millivolts, centiamps) of a 4S LiPo: 16.8 V full, 13.2 V empty."""
        mv = round((13.2 + 3.6 * self._flight.battery_pct / 100.0) * 1000)
        ca = 0 if not self._flight.armed else (1500 if self._flight.landed else 2500)
        return mv, ca

    def on_request_data_stream(self, link: Link, m: Inbound) -> None:
        sid, rate, on = m.i("req_stream_id"), m.i("req_message_rate"), m.i("start_stop")
        if sid == 0:
            names: tuple[str, ...] = tuple(n for g in AP_STREAM_GROUPS.values() for n in g)
        else:
            names = AP_STREAM_GROUPS.get(sid, ())
        for n in names:
            link.set_rate(n, float(rate) if on else 0.0)

    def cmd_set_interval(self, link: Link, _m: Inbound, p: list[float]) -> int:
        name = name_of(int(p[0]))
        if name is None or name not in STREAMS:
            return R_UNSUPPORTED
        interval_us = p[1]
        if interval_us < 0:
            link.set_rate(name, 0.0)
        elif interval_us == 0:
            link.set_rate(name, dict(self.spec.stream_rates_hz).get(name, 1.0))
        else:
            link.set_rate(name, 1e6 / interval_us)
        return R_ACCEPTED

    def cmd_request_message(self, link: Link, m: Inbound, p: list[float]) -> int | None:
        name = name_of(int(p[0]))
        if name is None or name not in REQUESTABLE:
            return R_UNSUPPORTED
        send_ack(link, m, const("MAV_CMD_REQUEST_MESSAGE"), R_ACCEPTED)
        self.send_stream(link, name)
        return None

    def cmd_capabilities(self, link: Link, m: Inbound, _p: list[float]) -> int | None:
        send_ack(link, m, const("MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES"), R_ACCEPTED)
        self.send_stream(link, "AUTOPILOT_VERSION")
        return None

    def cmd_home(self, link: Link, m: Inbound, _p: list[float]) -> int | None:
        send_ack(link, m, const("MAV_CMD_GET_HOME_POSITION"), R_ACCEPTED)
        self.send_stream(link, "HOME_POSITION")
        return None


_SENDERS: dict[str, Callable[[Telemetry, Link], None]] = {
    "HEARTBEAT": Telemetry._tx_heartbeat,
    "GLOBAL_POSITION_INT": Telemetry._tx_global_position_int,
    "GPS_RAW_INT": Telemetry._tx_gps_raw_int,
    "SYS_STATUS": Telemetry._tx_sys_status,
    "BATTERY_STATUS": Telemetry._tx_battery_status,
    "EXTENDED_SYS_STATE": Telemetry._tx_extended_sys_state,
    "HOME_POSITION": Telemetry._tx_home_position,
    "MISSION_CURRENT": Telemetry._tx_mission_current,
    "ATTITUDE": Telemetry._tx_attitude,
    "SYSTEM_TIME": Telemetry._tx_system_time,
    "VFR_HUD": Telemetry._tx_vfr_hud,
    "AUTOPILOT_VERSION": Telemetry._tx_autopilot_version,
}
