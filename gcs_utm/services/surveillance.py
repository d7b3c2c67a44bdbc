"""Surveillance feeds in the running service: dump1090/readsb-style TCP feeds (SBS-1, AVR,
Beast; :mod:`adapters.adsb.net`) -> ADS-B measurements handed to the USM.

Role: one task per configured feed (``[adsb] enabled``, a port of 0 is off). Each reader
reconnects with the configured backoff and logs once per outage; this service counts, per
feed, the connection (connects, failures, outages, bytes, up), the frames read, the positions
decoded and the rejects (corrupt lines or frames, positions beyond ``max_range_m``, a Beast
frame cut short). The measurements go to ``on_measurement`` -- the USM's
``on_measurement``, the same entry the MQTT surveillance topic and the MAVLink hub use --
and from there to Tracking: an ICAO address bound to an operation fuses with its track,
anything else becomes the intruder track ``icao:<hex>``.

Bounded state: each feed's decoder keeps per-aircraft state for at most ``max_aircraft``
ICAO addresses and forgets one not heard for ``aircraft_idle_s`` (counted in
``aircraft_evicted``); :meth:`SurveillanceService.evict_idle` runs that sweep every eighth of
``aircraft_idle_s`` while the feeds run, so a flood that stopped leaves nothing behind even
when no frame comes after it.

Times: receipt time is the service clock (so a sped-up ``run`` keeps its time base); SBS
capture time is the line's "generated" time when ``sbs_times_are_utc``, else receipt.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import AsyncIterator, Callable
from dataclasses import asdict, dataclass, field
from typing import Any

from adapters.adsb import ModeSDecoder, SbsDecoder
from adapters.adsb.capture import CaptureKind
from adapters.adsb.config import AdsbConfig
from adapters.adsb.net import (
    Backoff,
    ChunkTap,
    ConnectionStats,
    read_avr,
    read_beast,
    read_sbs,
)
from adapters.mavlink.adsb_relay import AdsbRelayCounters
from gcs_utm.clock import Clock
from gcs_utm.model import Measurement

_log = logging.getLogger(__name__)

FEED_KINDS = ("sbs", "avr", "beast")

FeedTap = Callable[[str, CaptureKind, bytes, float, bool], None]
"""``(feed name, kind, data, receipt t_s, new connection)``: the recorder's tap on every feed
(:meth:`gcs_utm.services.recorder.LinkRecorder.tap_feed`)."""


@dataclass(slots=True)
class FeedStats:
    """What one feed did: its connection and its decoder's counters."""

    kind: str
    host: str
    port: int
    connection: ConnectionStats = field(default_factory=ConnectionStats)
    sbs: SbsDecoder | None = None
    modes: ModeSDecoder | None = None
    handed_over: int = 0

    @property
    def name(self) -> str:
        return f"{self.kind}:{self.host}:{self.port}"

    def as_dict(self) -> dict[str, int]:
        """``frames`` read, ``positions`` decoded, ``rejects`` (corrupt, out of range, Beast
        frames cut short), ``measurements`` handed to the USM, plus the connection's counts
        and the decoder's detail."""
        out = self.connection.as_dict()
        if self.sbs is not None:
            c = self.sbs.counters
            detail = c.as_dict()
            rejects = c.corrupt + c.out_of_range
        else:
            assert self.modes is not None
            c = self.modes.counters
            detail = c.as_dict()
            rejects = c.corrupt + c.out_of_range
            if self.kind == "beast":
                b = self.modes.beast_counters
                rejects += b.truncated + b.bad_type
                detail["beast_truncated"] = b.truncated
                detail["beast_bad_type"] = b.bad_type
        out.update(detail)
        out["frames"] = c.frames
        out["positions"] = c.positions
        out["rejects"] = rejects
        out["measurements"] = self.handed_over
        return out


class SurveillanceService:
    """The ADS-B receiver feeds of ``[adsb]`` (none unless ``enabled``)."""

    def __init__(
        self,
        config: AdsbConfig,
        clock: Clock,
        on_measurement: Callable[[Measurement], None],
    ) -> None:
        self.config = config
        self.clock = clock
        self._on_measurement = on_measurement
        self.raw_tap: FeedTap | None = None  # set before run() to record every feed raw
        self.feeds: list[FeedStats] = []
        if not config.enabled:
            return
        ports = {"sbs": config.sbs_port, "avr": config.avr_port, "beast": config.beast_port}
        for kind in FEED_KINDS:
            port = ports[kind]
            if port == 0:
                continue
            feed = FeedStats(kind=kind, host=config.host, port=port)
            link = f"adsb-{feed.name}"
            if kind == "sbs":
                feed.sbs = SbsDecoder(
                    use_generated_time=config.sbs_times_are_utc,
                    velocity_max_age_s=config.velocity_max_age_s,
                    link=link,
                    max_aircraft=config.max_aircraft,
                    aircraft_idle_s=config.aircraft_idle_s,
                )
            else:
                feed.modes = ModeSDecoder.from_config(config, link=link)
            self.feeds.append(feed)

    def stats(self) -> dict[str, dict[str, int]]:
        """Per feed (``kind:host:port``): see :meth:`FeedStats.as_dict`."""
        return {f.name: f.as_dict() for f in self.feeds}

    def report(self, relay: AdsbRelayCounters) -> dict[str, Any]:
        """For the run report: every feed's counts and the MAVLink ``ADSB_VEHICLE`` relay's."""
        return {"feeds": self.stats(), "mavlink_relay": asdict(relay)}

    def _reader(self, feed: FeedStats) -> AsyncIterator[Measurement]:
        backoff = Backoff(
            initial_s=self.config.reconnect_initial_s, max_s=self.config.reconnect_max_s
        )
        stats, now_s = feed.connection, self.clock.now_s
        on_chunk = self._chunk_tap(feed)
        if feed.sbs is not None:
            return read_sbs(
                feed.host,
                feed.port,
                decoder=feed.sbs,
                backoff=backoff,
                stats=stats,
                now_s=now_s,
                on_chunk=on_chunk,
            )
        read = read_avr if feed.kind == "avr" else read_beast
        return read(
            feed.host,
            feed.port,
            decoder=feed.modes,
            backoff=backoff,
            stats=stats,
            now_s=now_s,
            on_chunk=on_chunk,
        )

    def _chunk_tap(self, feed: FeedStats) -> ChunkTap | None:
        tap = self.raw_tap
        if tap is None:
            return None
        name, kind = f"adsb-{feed.name}", CaptureKind(feed.kind)

        def on_chunk(data: bytes, t_s: float, new_connection: bool) -> None:
            tap(name, kind, data, t_s, new_connection)

        return on_chunk

    def evict_idle(self) -> int:
        """Forget, in every feed's decoder, the aircraft not heard for ``aircraft_idle_s``."""
        now_s = self.clock.now_s()
        evicted = 0
        for feed in self.feeds:
            decoder = feed.sbs if feed.sbs is not None else feed.modes
            assert decoder is not None
            evicted += decoder.evict_idle(now_s)
        return evicted

    async def _sweep(self) -> None:
        while True:
            await self.clock.sleep(self.config.aircraft_idle_s / 8.0)
            self.evict_idle()

    async def _run_feed(self, feed: FeedStats) -> None:
        gen = self._reader(feed)
        try:
            async for m in gen:
                feed.handed_over += 1
                try:
                    self._on_measurement(m)
                except Exception:  # a sink bug must not stop the feed
                    _log.exception("ADS-B feed %s: measurement sink failed", feed.name)
        finally:
            await gen.aclose()  # type: ignore[attr-defined]

    async def run(self) -> None:
        """Read every feed until cancelled (returns at once when there is none)."""
        if not self.feeds:
            return
        _log.info("ADS-B feeds: %s", ", ".join(f.name for f in self.feeds))
        try:
            async with asyncio.TaskGroup() as tg:
                for feed in self.feeds:
                    tg.create_task(self._run_feed(feed), name=f"adsb-{feed.kind}")
                tg.create_task(self._sweep(), name="adsb-sweep")
        finally:
            for name, c in self.stats().items():
                _log.info(
                    "ADS-B feed %s: %d frames, %d positions, %d rejects, %d connects, %d outages",
                    name,
                    c["frames"],
                    c["positions"],
                    c["rejects"],
                    c["connects"],
                    c["outages"],
                )
