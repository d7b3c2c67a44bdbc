"""Raw Mode-S / ADS-B (DF17/18 extended squitter) -> :class:`Measurement`, pure and stateful.

Input is hex frames from AVR text (``*8D...;``, ``@<12 hex MLAT>8D...;``) or Beast binary.
Only CRC-valid DF17/18 frames are used; other downlink formats are counted as ``not_adsb``.

- Airborne positions (TC 9-18 barometric, TC 20-22 GNSS) each yield one measurement. With a
  receiver position every frame is resolved at once against it (pyModeS ``reference=``);
  without one, pyModeS's ``PipeDecoder`` resolves even/odd pairs and frames wait until then.
- Altitude: TC 9-18 is pressure altitude (ft, ISA), used as metres AMSL without QNH
  correction; TC 20-22 is GNSS height converted from feet. The velocity report's
  GNSS-minus-baro difference is *not* applied (it is referenced to the ellipsoid on DO-260B).
- Velocity (TC 19 subtypes 1/2: ground speed, true track, vertical rate) is attached to the
  next positions of the same aircraft while younger than ``velocity_max_age_s``; airspeed
  subtypes 3/4 are not a ground velocity and are ignored.
- Identification (TC 1-4) gives the callsign. Horizontal accuracy ``eph_m`` (1-sigma per
  axis): from the NACp of operational status (TC 31, ADS-B version >= 1; version 0 has no
  NACp there) or target state (TC 29 subtype 1, DO-260B; subtype 0 has another layout), as
  its 95 % bound (EPU); until a NACp > 0 is known, from the position's own containment
  radius by type code (NIC/NUCp), taken as a 95 % bound: conservative
  (:func:`adapters.adsb.common.typecode_to_eph_m`). The tracker falls back to its
  ``adsb_eph_m`` default only when neither is known (TC 18/22).
- Surface positions (TC 5-8) are counted in ``not_adsb`` only when undecodable; otherwise
  skipped: their altitude is the unknown ground elevation.
- Bounded state: anybody can send frames with any ICAO address, so the per-aircraft state
  (here and in the pair decoder) is capped at ``max_aircraft`` (when full, the least recently
  heard eighth is forgotten) and an aircraft not heard for ``aircraft_idle_s`` is forgotten,
  by a sweep run as frames come (at most every eighth of ``aircraft_idle_s``) and by
  :meth:`ModeSDecoder.evict_idle` (the service calls it when no frame comes). Both are counted
  in ``aircraft_evicted``; the rules are those of :mod:`adapters.mavlink.senders`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from adapters.adsb._pymodes import PairDecoder, decode_reference
from adapters.adsb.beast import BeastCounters, BeastFrame, BeastFramer
from adapters.adsb.common import (
    FPM_TO_MPS,
    FT_TO_M,
    KT_TO_MPS,
    AdsbCounters,
    ground_velocity_ned_mps,
    nacp_to_eph_m,
    typecode_to_eph_m,
)
from adapters.adsb.config import AdsbConfig
from adapters.adsb.errors import ModeSFrameError
from adapters.mavlink.senders import idle_keys, over_cap_keys
from gcs_utm.geo import haversine_m
from gcs_utm.model import Icao24, Measurement, MeasurementSource, ModelError, normalise_icao24

_AIRBORNE_BARO = range(9, 19)
_AIRBORNE_GNSS = range(20, 23)
_HEX = frozenset("0123456789abcdefABCDEF")


@dataclass(slots=True)
class _Aircraft:
    callsign: str = ""
    vel_ned_mps: tuple[float, float, float] | None = None
    vel_t_s: float = 0.0
    eph_m: float | None = None
    positions: int = 0
    last_t_s: float = 0.0  # last valid frame (for the idle sweep and the cap)


@dataclass(slots=True)
class _State:
    aircraft: dict[Icao24, _Aircraft] = field(default_factory=dict)


def parse_avr_line(line: str) -> str:
    """AVR text -> hex frame. Accepts ``*HEX;`` and ``@<12 hex MLAT>HEX;`` (dump1090 port
    30002 and ``--mlat`` output). Raises :class:`ModeSFrameError`."""
    text = line.strip()
    if not text:
        raise ModeSFrameError(line, "empty line")
    if text[0] == "*":
        body = text[1:]
    elif text[0] == "@":
        body = text[13:]
    else:
        raise ModeSFrameError(line, "expected '*' or '@' at the start")
    body = body.rstrip(";")
    if len(body) not in (14, 28) or not set(body) <= _HEX:
        raise ModeSFrameError(line, f"expected 14 or 28 hex digits, got {len(body)} characters")
    return body


class ModeSDecoder:
    """Stateful decoder of one receiver's Mode-S stream. Never raises on bad input: every
    frame is counted in :attr:`counters` and corrupt ones are dropped."""

    def __init__(
        self,
        reference_lat_deg: float | None = None,
        reference_lon_deg: float | None = None,
        *,
        max_range_m: float = 333_360.0,
        velocity_max_age_s: float = 10.0,
        link: str = "adsb",
        max_aircraft: int = 4096,
        aircraft_idle_s: float = 120.0,
    ) -> None:
        if (reference_lat_deg is None) != (reference_lon_deg is None):
            raise ValueError("give both reference_lat_deg and reference_lon_deg, or neither")
        self._reference: tuple[float, float] | None = (
            None
            if reference_lat_deg is None or reference_lon_deg is None
            else (reference_lat_deg, reference_lon_deg)
        )
        self._pairs = PairDecoder(aircraft_idle_s) if self._reference is None else None
        self._max_aircraft = max_aircraft
        self._idle_s = aircraft_idle_s
        self._next_sweep_t_s = float("-inf")
        self._max_range_m = max_range_m
        self._velocity_max_age_s = velocity_max_age_s
        self._link = link
        self._state = _State()
        self._framer = BeastFramer()
        self.counters = AdsbCounters()

    @classmethod
    def from_config(cls, config: AdsbConfig, *, link: str = "adsb") -> ModeSDecoder:
        known = config.receiver_position_known
        return cls(
            config.receiver_lat_deg if known else None,
            config.receiver_lon_deg if known else None,
            max_range_m=config.max_range_m,
            velocity_max_age_s=config.velocity_max_age_s,
            link=link,
            max_aircraft=config.max_aircraft,
            aircraft_idle_s=config.aircraft_idle_s,
        )

    @property
    def beast_counters(self) -> BeastCounters:
        """Framing counters of :meth:`feed_beast`."""
        return self._framer.counters

    def aircraft(self) -> dict[Icao24, str]:
        """ICAO address -> callsign ('' if none yet) of every aircraft with a valid frame."""
        return {icao: a.callsign for icao, a in self._state.aircraft.items()}

    def state_size(self) -> int:
        """Addresses with state kept: this decoder's or its pair decoder's, the larger."""
        pairs = 0 if self._pairs is None else self._pairs.size()
        return max(len(self._state.aircraft), pairs)

    # ---- bounds (module docstring: bounded state) ----------------------------------------
    def evict_idle(self, now_s: float) -> int:
        """Forget the aircraft not heard for ``aircraft_idle_s``; returns how many."""
        self._next_sweep_t_s = now_s + self._idle_s / 8.0
        table = self._state.aircraft
        idle = idle_keys({k: a.last_t_s for k, a in table.items()}, now_s, self._idle_s)
        for icao in idle:
            del table[icao]
        evicted = len(idle)
        if self._pairs is not None:
            evicted = max(evicted, self._pairs.evict_idle(now_s))
        self.counters.aircraft_evicted += evicted
        return evicted

    def _trim(self) -> None:
        """Make room for one more aircraft here and in the pair decoder."""
        table = self._state.aircraft
        if len(table) >= self._max_aircraft:
            old = over_cap_keys({k: a.last_t_s for k, a in table.items()}, self._max_aircraft)
            for icao in old:
                del table[icao]
            if self._pairs is not None:
                self._pairs.forget([str(k) for k in old])
            self.counters.aircraft_evicted += len(old)
        if self._pairs is not None and self._pairs.size() >= self._max_aircraft:
            old_pairs = over_cap_keys(self._pairs.last_heard_t_s(), self._max_aircraft)
            self._pairs.forget(old_pairs)
            self.counters.aircraft_evicted += len(old_pairs)

    # ---- inputs -------------------------------------------------------------------------
    def feed_avr(self, line: str, t_s: float) -> Measurement | None:
        """One AVR text line received at ``t_s`` -> a measurement or ``None``."""
        try:
            frame = parse_avr_line(line)
        except ModeSFrameError:
            self.counters.frames += 1
            self.counters.malformed += 1
            return None
        return self.feed_hex(frame, t_s)

    def feed_beast(self, data: bytes, t_s: float) -> list[Measurement]:
        """A chunk of a Beast byte stream received at ``t_s`` -> measurements of the frames it
        completes (a frame split across chunks is completed by the next call)."""
        out: list[Measurement] = []
        for frame in self._framer.feed(data):
            m = self.feed_hex(frame.hex, t_s)
            if m is not None:
                out.append(m)
        return out

    def beast_frames(self, data: bytes) -> list[BeastFrame]:
        """A chunk of a Beast byte stream -> its complete Mode-S frames, framed (and counted)
        as :meth:`feed_beast` frames them, for a caller that times each frame itself (a
        capture replayed by its MLAT counter); decode them with :meth:`feed_hex`."""
        return self._framer.feed(data)

    def reset_stream(self) -> None:
        """Forget a partial Beast frame (the connection it came on is gone)."""
        self._framer.reset()

    def feed_hex(self, frame: str, t_s: float) -> Measurement | None:
        """One Mode-S frame (14 or 28 hex digits) captured at ``t_s``."""
        c = self.counters
        c.frames += 1
        if t_s >= self._next_sweep_t_s:
            self.evict_idle(t_s)
        if self._pairs is not None and self._pairs.size() >= self._max_aircraft:
            self._trim()
        try:
            if self._pairs is not None:
                d = self._pairs.decode(frame, t_s)
            else:
                assert self._reference is not None
                d = decode_reference(frame, self._reference)
        except ModeSFrameError:
            c.malformed += 1
            return None
        if d.get("df") not in (17, 18):
            c.not_adsb += 1
            return None
        if d.get("crc_valid") is not True:
            c.crc_failed += 1
            return None
        try:
            icao = normalise_icao24(str(d.get("icao", "")))
        except ModelError:
            c.malformed += 1
            return None
        ac = self._state.aircraft.get(icao)
        if ac is None:
            if len(self._state.aircraft) >= self._max_aircraft:
                self._trim()
            ac = self._state.aircraft[icao] = _Aircraft()
        ac.last_t_s = t_s
        return self._apply(icao, ac, d, t_s)

    # ---- per message kind ---------------------------------------------------------------
    def _apply(
        self, icao: Icao24, ac: _Aircraft, d: dict[str, Any], t_s: float
    ) -> Measurement | None:
        c = self.counters
        tc = d.get("typecode")
        if not isinstance(tc, int):
            c.not_adsb += 1
            return None
        if 1 <= tc <= 4:
            callsign = str(d.get("callsign") or "").strip("_ #").strip()
            if callsign:
                ac.callsign = callsign
                c.identifications += 1
            return None
        if tc == 19:
            gs = d.get("groundspeed")
            trk = d.get("track")
            if isinstance(gs, int | float) and isinstance(trk, int | float):
                vr = d.get("vertical_rate")
                climb = float(vr) * FPM_TO_MPS if isinstance(vr, int | float) else 0.0
                ac.vel_ned_mps = ground_velocity_ned_mps(float(gs) * KT_TO_MPS, float(trk), climb)
                ac.vel_t_s = t_s
                c.velocities += 1
            return None
        if tc in (29, 31):
            nac_p = d.get("nac_p")
            # Only where the field is a NACp: TC 31 from version 1 on, TC 29 subtype 1.
            has_nacp = d.get("version") in (1, 2) if tc == 31 else d.get("subtype") == 1
            if has_nacp and isinstance(nac_p, int):
                ac.eph_m = nacp_to_eph_m(nac_p)
            return None
        if tc in _AIRBORNE_BARO or tc in _AIRBORNE_GNSS:
            return self._position(icao, ac, d, t_s)
        return None

    def _position(
        self, icao: Icao24, ac: _Aircraft, d: dict[str, Any], t_s: float
    ) -> Measurement | None:
        c = self.counters
        lat = d.get("latitude")
        lon = d.get("longitude")
        alt_ft = d.get("altitude")
        if not isinstance(alt_ft, int | float):
            c.not_adsb += 1  # position without altitude: useless in 4D
            return None
        if not isinstance(lat, int | float) or not isinstance(lon, int | float):
            c.pending_cpr += 1
            return None
        if self._reference is not None and (
            haversine_m(self._reference[0], self._reference[1], float(lat), float(lon))
            > self._max_range_m
        ):
            c.out_of_range += 1
            return None
        vel = ac.vel_ned_mps
        if vel is not None and t_s - ac.vel_t_s > self._velocity_max_age_s:
            vel = None
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
            c.malformed += 1
            return None
        m = Measurement(
            source=MeasurementSource.ADSB,
            capture_t_s=t_s,
            receipt_t_s=t_s,
            lat_deg=float(lat),
            lon_deg=float(lon),
            alt_amsl_m=float(alt_ft) * FT_TO_M,
            vel_ned_mps=vel,
            eph_m=ac.eph_m if ac.eph_m is not None else typecode_to_eph_m(int(d["typecode"])),
            icao24=icao,
            link=self._link,
            callsign=ac.callsign,
        )
        ac.positions += 1
        c.positions += 1
        return m
