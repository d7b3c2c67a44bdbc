"""SBS-1 BaseStation text (dump1090 port 30003) -> :class:`Measurement`, pure.

A line is ``MSG,<type>,<session>,<aircraft>,<hex ident>,<flight>,<date gen>,<time gen>,
<date logged>,<time logged>,<callsign>,<altitude ft>,<ground speed kt>,<track deg>,<lat>,
<lon>,<vertical rate ft/min>,<squawk>,<alert>,<emergency>,<spi>,<on ground>``.

Type 3 (airborne position) carries a position; its altitude is what the receiver reports for
SBS, the barometric pressure altitude (ft, ISA), used as metres AMSL without QNH correction.
Type 4 carries ground speed, track and vertical rate; type 1 the callsign. The stateless
:func:`decode_sbs_line` decodes type 3 alone; :class:`SbsDecoder` also remembers callsign and
velocity per aircraft and attaches them to later positions.

Capture time is the "message generated" date/time (UTC) when present and parseable, else the
receipt time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import UTC, datetime

from adapters.adsb.common import (
    FPM_TO_MPS,
    FT_TO_M,
    KT_TO_MPS,
    AdsbCounters,
    ground_velocity_ned_mps,
)
from adapters.adsb.errors import SbsFormatError
from adapters.mavlink.senders import idle_keys, over_cap_keys
from gcs_utm.model import Icao24, Measurement, MeasurementSource, ModelError, normalise_icao24

_N_FIELDS = 22


@dataclass(frozen=True, slots=True, kw_only=True)
class SbsRecord:
    """The fields of one ``MSG`` line that we use; ``None`` where the field is empty."""

    transmission_type: int
    icao24: Icao24
    generated_t_s: float | None
    callsign: str
    altitude_ft: float | None
    ground_speed_kt: float | None
    track_deg: float | None
    lat_deg: float | None
    lon_deg: float | None
    vertical_rate_fpm: float | None
    on_ground: bool | None


def _float(line: str, fields: list[str], index: int, name: str) -> float | None:
    text = fields[index].strip()
    if not text:
        return None
    try:
        value = float(text)
    except ValueError as exc:
        raise SbsFormatError(line, name, f"not a number: {text!r}") from exc
    if not math.isfinite(value):
        raise SbsFormatError(line, name, f"not finite: {text!r}")
    return value


def _time(date_text: str, time_text: str) -> float | None:
    date_text = date_text.strip()
    time_text = time_text.strip()
    if not date_text or not time_text:
        return None
    try:
        stamp = datetime.strptime(f"{date_text} {time_text}", "%Y/%m/%d %H:%M:%S.%f")
    except ValueError:
        try:
            stamp = datetime.strptime(f"{date_text} {time_text}", "%Y/%m/%d %H:%M:%S")
        except ValueError:
            return None
    return stamp.replace(tzinfo=UTC).timestamp()


def sbs_line_time(line: str) -> float | None:
    """The "message generated" date/time of an SBS-1 line (UTC POSIX seconds), None when the
    line has none or is not an SBS-1 record."""
    fields = line.split(",")
    if len(fields) < _N_FIELDS or fields[0].strip() != "MSG":
        return None
    return _time(fields[6], fields[7])


def parse_sbs_line(line: str) -> SbsRecord:
    """Parse one ``MSG`` line or raise :class:`SbsFormatError` (other record kinds such as
    ``AIR``/``ID``/``STA`` are also reported as errors: they carry no surveillance data)."""
    fields = line.strip().split(",")
    if fields[0] != "MSG":
        raise SbsFormatError(line, "message type", f"not MSG: {fields[0][:10]!r}")
    if len(fields) < _N_FIELDS:
        raise SbsFormatError(line, "fields", f"expected {_N_FIELDS}, got {len(fields)}")
    try:
        kind = int(fields[1])
    except ValueError as exc:
        raise SbsFormatError(line, "transmission type", "not an integer") from exc
    try:
        icao = normalise_icao24(fields[4])
    except ModelError as exc:
        raise SbsFormatError(line, "hex ident", exc.message) from exc
    lat = _float(line, fields, 14, "latitude")
    lon = _float(line, fields, 15, "longitude")
    if lat is not None and not -90.0 <= lat <= 90.0:
        raise SbsFormatError(line, "latitude", f"out of range: {lat}")
    if lon is not None and not -180.0 <= lon <= 180.0:
        raise SbsFormatError(line, "longitude", f"out of range: {lon}")
    ground = fields[21].strip()
    return SbsRecord(
        transmission_type=kind,
        icao24=icao,
        generated_t_s=_time(fields[6], fields[7]),
        callsign=fields[10].strip(),
        altitude_ft=_float(line, fields, 11, "altitude"),
        ground_speed_kt=_float(line, fields, 12, "ground speed"),
        track_deg=_float(line, fields, 13, "track"),
        lat_deg=lat,
        lon_deg=lon,
        vertical_rate_fpm=_float(line, fields, 16, "vertical rate"),
        on_ground=None if not ground else ground not in ("0", "false", "False"),
    )


def _measurement(
    rec: SbsRecord,
    receipt_t_s: float,
    use_generated_time: bool,
    *,
    callsign: str = "",
    vel: tuple[float, float, float] | None = None,
    link: str = "sbs",
) -> Measurement | None:
    if rec.lat_deg is None or rec.lon_deg is None or rec.altitude_ft is None:
        return None
    capture = rec.generated_t_s if use_generated_time and rec.generated_t_s else receipt_t_s
    return Measurement(
        source=MeasurementSource.ADSB,
        capture_t_s=capture,
        receipt_t_s=receipt_t_s,
        lat_deg=rec.lat_deg,
        lon_deg=rec.lon_deg,
        alt_amsl_m=rec.altitude_ft * FT_TO_M,
        vel_ned_mps=vel,
        icao24=rec.icao24,
        link=link,
        callsign=rec.callsign or callsign,
    )


def decode_sbs_line(
    line: str, receipt_t_s: float, *, use_generated_time: bool = True
) -> Measurement | None:
    """One SBS line -> a measurement when it carries a position (type 3), else ``None``.
    Raises :class:`SbsFormatError` on a malformed line (:class:`SbsDecoder` counts instead)."""
    return _measurement(parse_sbs_line(line), receipt_t_s, use_generated_time)


class SbsDecoder:
    """Stateful SBS decoder: merges callsign (type 1) and velocity (type 4) into positions.
    Never raises on bad input; see :attr:`counters`.

    Its per-aircraft state is bounded as :class:`adapters.adsb.modes.ModeSDecoder`'s is
    (``max_aircraft``, ``aircraft_idle_s``, counted in ``aircraft_evicted``); "heard" is the
    receipt time, never the line's own (sender-chosen) time."""

    def __init__(
        self,
        *,
        use_generated_time: bool = True,
        velocity_max_age_s: float = 10.0,
        link: str = "sbs",
        max_aircraft: int = 4096,
        aircraft_idle_s: float = 120.0,
    ) -> None:
        self._use_generated_time = use_generated_time
        self._velocity_max_age_s = velocity_max_age_s
        self._link = link
        self._callsign: dict[Icao24, str] = {}
        self._vel: dict[Icao24, tuple[float, tuple[float, float, float]]] = {}
        self._positions: dict[Icao24, int] = {}
        self._heard_t_s: dict[Icao24, float] = {}  # receipt time of the last valid line
        self._max_aircraft = max_aircraft
        self._idle_s = aircraft_idle_s
        self._next_sweep_t_s = float("-inf")
        self.counters = AdsbCounters()

    def state_size(self) -> int:
        """Addresses with state kept."""
        return len(self._heard_t_s)

    def _forget(self, icaos: list[Icao24]) -> int:
        for icao in icaos:
            self._heard_t_s.pop(icao, None)
            self._positions.pop(icao, None)
            self._callsign.pop(icao, None)
            self._vel.pop(icao, None)
        self.counters.aircraft_evicted += len(icaos)
        return len(icaos)

    def evict_idle(self, now_s: float) -> int:
        """Forget the aircraft not heard for ``aircraft_idle_s``; returns how many."""
        self._next_sweep_t_s = now_s + self._idle_s / 8.0
        return self._forget(idle_keys(self._heard_t_s, now_s, self._idle_s))

    def aircraft(self) -> dict[Icao24, str]:
        """ICAO address -> callsign of every aircraft seen in a valid line."""
        return {icao: self._callsign.get(icao, "") for icao in self._positions}

    def feed(self, line: str, receipt_t_s: float) -> Measurement | None:
        c = self.counters
        if not line.strip():
            return None
        c.frames += 1
        try:
            rec = parse_sbs_line(line)
        except SbsFormatError:
            c.malformed += 1
            return None
        icao = rec.icao24
        if receipt_t_s >= self._next_sweep_t_s:
            self.evict_idle(receipt_t_s)
        if icao not in self._heard_t_s and len(self._heard_t_s) >= self._max_aircraft:
            self._forget(over_cap_keys(self._heard_t_s, self._max_aircraft))
        self._heard_t_s[icao] = receipt_t_s
        self._positions.setdefault(icao, 0)
        t_s = rec.generated_t_s if self._use_generated_time and rec.generated_t_s else receipt_t_s
        if rec.callsign:
            self._callsign[icao] = rec.callsign
            c.identifications += 1
        if rec.ground_speed_kt is not None and rec.track_deg is not None:
            climb = (rec.vertical_rate_fpm or 0.0) * FPM_TO_MPS
            self._vel[icao] = (
                t_s,
                ground_velocity_ned_mps(rec.ground_speed_kt * KT_TO_MPS, rec.track_deg, climb),
            )
            c.velocities += 1
        vel_entry = self._vel.get(icao)
        vel = (
            vel_entry[1]
            if vel_entry is not None and t_s - vel_entry[0] <= self._velocity_max_age_s
            else None
        )
        m = _measurement(
            rec,
            receipt_t_s,
            self._use_generated_time,
            callsign=self._callsign.get(icao, ""),
            vel=vel,
            link=self._link,
        )
        if m is None:
            if rec.transmission_type not in (1, 4):
                c.not_adsb += 1
            return None
        self._positions[icao] += 1
        c.positions += 1
        return m
