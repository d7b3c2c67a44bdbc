"""State the USM keeps per sender-chosen identity stays bounded (issue 21 item 3): ADS-B
statistics per ICAO address (feeds, MQTT ``adsb`` topic, MAVLink ADSB_VEHICLE) and hazard
coalescing keys (MQTT alerts, RPA-reported hazards)."""

from __future__ import annotations

import numpy as np

from gcs_utm.clock import ManualClock
from gcs_utm.messages import HazardReport
from gcs_utm.model import (
    Icao24,
    Measurement,
    MeasurementSource,
    OperationId,
    PredictedTrajectories,
    Threat,
    ThreatId,
    ThreatKind,
    TrackId,
)
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.usm import Usm, UsmConfig

SPOOFED = 12_000
CAP = 1_000


def _adsb(icao: int, t_s: float) -> Measurement:
    return Measurement(
        source=MeasurementSource.ADSB,
        capture_t_s=t_s,
        receipt_t_s=t_s,
        lat_deg=52.0,
        lon_deg=4.4,
        alt_amsl_m=900.0,
        icao24=Icao24(f"{icao:06x}"),
        link="mqtt:adsb",
    )


def test_adsb_statistics_capped_with_totals_kept() -> None:
    usm = Usm(Airspace(), ManualClock(0.0), config=UsmConfig(max_adsb_sources=CAP))
    for i in range(SPOOFED):
        usm.on_measurement(_adsb(0x100000 + i, i * 0.001))
    telemetry = usm.telemetry
    assert len(telemetry) <= CAP + 1  # + "adsb:evicted"
    assert usm.counters["adsb_sources_evicted"] >= SPOOFED - CAP
    assert sum(s.count for s in telemetry.values()) == SPOOFED
    # the most recent aircraft keep their own statistics
    assert telemetry[f"adsb:{0x100000 + SPOOFED - 1:06x}"].count == 1


async def test_hazard_keys_capped_then_forgotten_after_cooldown() -> None:
    config = UsmConfig(max_hazard_keys=CAP, hazard_cooldown_s=30.0)
    usm = Usm(Airspace(), ManualClock(0.0), config=config)
    for i in range(SPOOFED):  # within one cooldown: only the cap bounds them
        usm.on_hazard(HazardReport(kind=ThreatKind.ALERT_WARNING, t_s=i * 0.0001, source=f"x{i}"))
        assert len(usm._hazard_seen) <= CAP
    await usm.drain()
    assert usm.counters["hazard_keys_evicted"] >= SPOOFED - CAP
    # after the cooldown a new key finds the old ones forgotten
    assert len(usm._hazard_seen) > 1
    usm.on_hazard(HazardReport(kind=ThreatKind.ALERT_WARNING, t_s=100.0, source="late"))
    await usm.drain()
    assert len(usm._hazard_seen) == 1


async def test_threat_log_bounded_with_the_dropped_counted() -> None:
    """Spoofed MQTT alert ids each open a threat: memory keeps the newest, the store all."""
    usm = Usm(Airspace(), ManualClock(0.0), config=UsmConfig(threat_log_size=CAP))
    for i in range(SPOOFED // 4):
        usm.on_hazard(HazardReport(kind=ThreatKind.ALERT_WARNING, t_s=i * 0.0001, source=f"x{i}"))
    await usm.drain()
    assert len(usm.threat_log) == CAP
    assert usm.counters["threat_log_dropped"] == SPOOFED // 4 - CAP


async def test_threat_log_keeps_no_prediction() -> None:
    """The run report's threat log holds each threat's figures, not the prediction of every
    track it was computed on: a day of threats held with their predictions grew RSS by
    ~9 MB per simulated hour (``gcs-utm bench soak``)."""
    usm = Usm(Airspace(), ManualClock(0.0))
    prediction = PredictedTrajectories(
        t_s=0.0, track_ids=(TrackId("a"),), points=np.zeros((1, 61, 4)), sigma_m=np.zeros((1, 61))
    )
    threat = Threat(
        id=ThreatId("T1"),
        kind=ThreatKind.LOSS_OF_SEPARATION,
        uas_ids=(OperationId("A"), OperationId("B")),
        detected_at_s=0.0,
        predicted_event_at_s=40.0,
        closest_approach_m=12.0,
        snapshot=prediction,
    )
    await usm.on_threats([threat])
    await usm.drain()
    (logged,) = usm.threat_log
    assert logged.snapshot is None
    assert (logged.id, logged.closest_approach_m, logged.predicted_event_at_s) == ("T1", 12.0, 40.0)
    # the open threat EM decides on still carries it
    assert usm.threats[ThreatId("T1")].snapshot is prediction
