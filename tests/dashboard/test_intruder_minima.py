"""The pilot prompt states the minima that apply to the threat it shows: the intruder minima
of ``[monitoring]`` (default 150 m / 50 m) for an INTRUDER threat, the UAS minima (50 m /
15 m) for a loss of separation between operations."""

from __future__ import annotations

import sys
from dataclasses import replace
from io import StringIO
from pathlib import Path

from rich.console import Console

from gcs_utm.app.wiring import minima
from gcs_utm.dashboard.view import collect, recommendation_panel
from gcs_utm.model import Threat, ThreatId, ThreatKind, TrackId
from gcs_utm.settings import Settings

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_dashboard import OP, _rec, _tracks, _usm


def _prompt(kind: ThreatKind) -> str:
    threat = Threat(
        id=ThreatId("t1"),
        kind=kind,
        uas_ids=(OP,),
        detected_at_s=10.0,
        predicted_event_at_s=30.0,
        intruder_id=TrackId("icao:a1b2c3") if kind is ThreatKind.INTRUDER else None,
        horizontal_m=90.0,
        vertical_m=20.0,
    )
    rec = replace(_rec(), threat_kind=kind)
    data = replace(collect(_usm(), _tracks, minima(Settings())), threats=(threat,))
    buf = StringIO()
    Console(file=buf, width=200, color_system=None).print(recommendation_panel(rec, data))
    return " ".join(buf.getvalue().split())


def test_intruder_threat_shows_the_intruder_minima_from_settings() -> None:
    mon = Settings().monitoring
    assert (mon.intruder_horizontal_m, mon.intruder_vertical_m) == (150.0, 50.0)
    text = _prompt(ThreatKind.INTRUDER)
    assert "intruder icao:a1b2c3" in text
    assert "90 m horizontal (min 150)" in text
    assert "20 m vertical (min 50)" in text


def test_loss_of_separation_shows_the_uas_minima() -> None:
    mon = Settings().monitoring
    text = _prompt(ThreatKind.LOSS_OF_SEPARATION)
    assert f"90 m horizontal (min {mon.separation_horizontal_m:.0f})" in text
    assert f"20 m vertical (min {mon.separation_vertical_m:.0f})" in text


def test_loss_of_separation_shows_the_effective_minima_of_the_pair() -> None:
    """Monitoring judges a pair by minima never below the sum of their operational volumes
    (``MonitoringConfig.effective_minima``): the prompt states those, not the configured
    ones, when they differ."""
    from gcs_utm.model import OperationId

    usm = _usm()
    op = usm.airspace.operation(OP)
    uas2 = OperationId("UAS2")
    other = replace(
        op, id=uas2, plan=replace(op.plan, operation_id=uas2), operational_volume_m=25.0
    )
    usm.airspace.load([replace(op, operational_volume_m=25.0), other], [])
    threat = Threat(
        id=ThreatId("t1"),
        kind=ThreatKind.LOSS_OF_SEPARATION,
        uas_ids=(OP, OperationId("UAS2")),
        detected_at_s=10.0,
        predicted_event_at_s=30.0,
        horizontal_m=40.0,
        vertical_m=20.0,
    )
    mon = Settings().monitoring
    assert (
        mon.effective_minima(25.0, 25.0)
        == (50.0, 50.0)
        != (
            mon.separation_horizontal_m,
            mon.separation_vertical_m,
        )
    )
    data = replace(collect(usm, _tracks, minima(Settings())), threats=(threat,))
    buf = StringIO()
    Console(file=buf, width=200, color_system=None).print(recommendation_panel(_rec(), data))
    text = " ".join(buf.getvalue().split())
    assert "40 m horizontal (min 50), 20 m vertical (min 50)" in text
