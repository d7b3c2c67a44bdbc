"""Ground commands of a simulated vehicle, answered as PX4 v1.15 (Commander) and ArduPilot 4.6
(GCS_MAVLINK) answer them: MAV_CMD_DO_SET_HOME and MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN.

Functions given the parts they act on (the flight, the fault state, the vehicle's reboot);
:class:`sitl.commands.CommandHandler` dispatches to them. Each returns the MAV_RESULT."""

from __future__ import annotations

import math
from collections.abc import Callable

from sitl._mav import const
from sitl.core import R_ACCEPTED, R_DENIED, R_FAILED, R_UNSUPPORTED
from sitl.faults import Faults
from sitl.flight import Flight

AP_FORCE_REBOOT_MAGIC = 20190226.0  # ArduPilot: param4 of a reboot that is forced while armed
R_TEMPORARILY_REJECTED = const("MAV_RESULT_TEMPORARILY_REJECTED")


def set_home(flight: Flight, faults: Faults, p: list[float], *, ardupilot: bool) -> int:
    """MAV_CMD_DO_SET_HOME: param1 = 1 the current position, else param5-7 (latitude,
    longitude, altitude AMSL). Needs a position (a fix): PX4 answers TEMPORARILY_REJECTED
    without one, ArduPilot FAILED. PX4 takes the current position as an automatic home and a
    given one as a manual home; ArduPilot locks either (a locked or manual home is kept at
    arming). PX4 denies a location that is not finite; ArduPilot takes lat = lon = 0 as the
    current position and denies a location out of range."""
    no_fix = faults.gps_fix_type() < 3
    lat, lon, alt = p[4], p[5], p[6]
    here = p[0] >= 0.5 or (ardupilot and lat == 0.0 and lon == 0.0)
    if here:
        if no_fix:
            return R_FAILED if ardupilot else R_TEMPORARILY_REJECTED
        flight.set_home(flight.lat_deg, flight.lon_deg, flight.k.alt_amsl_m)
        flight.home_manual = ardupilot  # PX4: setHomePosition(force) is not a manual home
        return R_ACCEPTED
    if not (math.isfinite(lat) and math.isfinite(lon) and math.isfinite(alt)):
        return R_DENIED
    if ardupilot and not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        return R_DENIED
    if no_fix:
        return R_FAILED if ardupilot else R_TEMPORARILY_REJECTED
    flight.set_home(lat, lon, alt)
    flight.home_manual = True
    return R_ACCEPTED


def reboot(
    flight: Flight, do_reboot: Callable[[], None], p: list[float], *, ardupilot: bool
) -> int:
    """MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, param1 = 1: reboot the autopilot. Refused while
    armed: PX4 DENIED, ArduPilot FAILED unless param4 is its force value (20190226). PX4
    accepts param1 = 0 (nothing to do); any other request is UNSUPPORTED here."""
    action = int(p[0]) if math.isfinite(p[0]) else -1
    if action == 0 and not ardupilot:
        return R_ACCEPTED
    if action != 1:
        return R_UNSUPPORTED
    if flight.armed:
        if not ardupilot:
            return R_DENIED
        if p[3] != AP_FORCE_REBOOT_MAGIC:
            return R_FAILED
    do_reboot()
    return R_ACCEPTED
