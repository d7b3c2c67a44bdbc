"""The airspace view in the running dashboard (Textual's pilot, 80x24 and 120x40): the map shows
UAS by label with their headings, a scale and north; the geofence panel is one line when
there are none; the event log wraps at words and keeps the newest event on screen."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import pytest
from textual.app import App, ComposeResult
from textual.geometry import Region

from gcs_utm.clock import ManualClock
from gcs_utm.dashboard.airspace_map import rows_to_fit
from gcs_utm.dashboard.airspace_scene import MapPlan, MapScene
from gcs_utm.dashboard.panels import event_log
from gcs_utm.dashboard.tui import DashboardApp
from gcs_utm.dashboard.view import Minima
from gcs_utm.dashboard.widgets import AirspaceMap
from gcs_utm.model import OperationId, SysId, Threat, ThreatId, ThreatKind, Track, TrackId
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.usm import Usm, UsmEvent

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_dashboard import _tracks, _usm
from test_prompt import screen_text

NEWEST = "recommendation E1-T1-LOS/UAS1 v1 for UAS1: go_down (LOSS_OF_SEPARATION), deadline in 20 s"


def _events() -> list[UsmEvent]:
    """Twenty events, oldest first, long enough to wrap several times in a narrow column."""
    old = [
        UsmEvent(
            t_s=float(i),
            kind="vehicle",
            text=f"sysid {i}: home 40.6593863, -3.5940591, 675.00 m AMSL (from HOME_POSITION)",
        )
        for i in range(19)
    ]
    return [*old, UsmEvent(t_s=19.0, kind="recommendation", text=NEWEST)]


def _two_uas_no_geofence() -> tuple[Usm, dict[TrackId, Track]]:
    """UAS1 and UAS2 250 m apart in a loss-of-separation threat; no geofence."""
    op1 = _usm().airspace.operations[OperationId("UAS1")]
    op2 = replace(
        op1,
        id=OperationId("UAS2"),
        sys_id=SysId(2),
        plan=replace(op1.plan, operation_id=OperationId("UAS2")),
    )
    airspace = Airspace()
    airspace.load([op1, op2], [])
    usm = Usm(airspace, ManualClock(20.0))
    usm.threats[ThreatId("los")] = Threat(
        id=ThreatId("los"),
        kind=ThreatKind.LOSS_OF_SEPARATION,
        uas_ids=(op1.id, op2.id),
        detected_at_s=18.0,
    )
    usm.events.extend(_events())
    t1 = _tracks()[TrackId("UAS1")]
    t2 = replace(
        t1, id=TrackId("UAS2"), operation_id=op2.id, lat_deg=40.00255, vel_enu_mps=(0.0, -6.0, 0.0)
    )
    return usm, {t1.id: t1, t2.id: t2}


def _drawn(app: App[None], selector: str) -> list[str]:
    """The characters the widget ``selector`` draws on screen, row by row, at its size in the
    layout (an empty list when it is hidden)."""
    widget = app.query_one(selector)
    if not widget.display or not widget.region.area:
        return []
    return [strip.text for strip in widget.render_lines(Region(0, 0, *widget.size))]


async def _screen(size: tuple[int, int] = (80, 24)) -> tuple[str, list[str], list[str]]:
    """The dashboard at ``size`` with no prompt: the whole screen, the map's and the event
    log's rows."""
    usm, tracks = _two_uas_no_geofence()
    app = DashboardApp(
        usm, lambda: tracks, refresh_s=0.1, minima=Minima(horizontal_m=50.0, vertical_m=15.0)
    )
    async with app.run_test(size=size) as pilot:
        # the map takes the rows its first scene needs and the panels refill at the next
        # refresh (0.1 s): read once two refreshes in a row draw the same screen (a loaded
        # machine may need several)
        shown: tuple[str, list[str], list[str]] | None = None
        for _ in range(50):
            await pilot.pause(0.1)
            now = (screen_text(app), _drawn(app, "#map"), _drawn(app, "#events"))
            if now == shown:
                break
            shown = now
        assert shown is not None
        return shown


@pytest.mark.parametrize("size", [(80, 24), (120, 40)])
async def test_map_shows_each_uas_by_label_with_heading_scale_and_north(
    size: tuple[int, int],
) -> None:
    text, map_rows, _events_rows = await _screen(size)
    drawn = "\n".join(map_rows)
    assert len(map_rows) >= 8, text  # a map of its own, not a few dots in a corner
    assert "↗UAS1" in drawn and "↓UAS2" in drawn, drawn  # labels after the course arrows
    assert "∘" in drawn  # the threat pair's separation rings
    assert map_rows[-1].lstrip().startswith("├") and map_rows[-1].rstrip().endswith("↑N")
    assert " m" in map_rows[-1] or " km" in map_rows[-1]  # the scale bar's length


async def test_panels_at_80x24_say_no_geofences_and_keep_the_newest_event_whole() -> None:
    text, _map_rows, event_rows = await _screen()
    # no geofence: one line says so, no empty table
    assert "no geofences active" in text and "Band AMSL" not in text
    # the newest event is on screen, every word whole (no word split across lines)
    shown = " ".join(" ".join(event_rows).split())
    assert NEWEST in shown, event_rows
    assert "sysid 0:" not in shown  # the oldest ones gave way


def test_event_log_wraps_between_words_and_keeps_the_newest() -> None:
    events = _events()
    words = {w for e in events for w in (e.kind, *e.text.split())}
    ages = {f"{e.t_s - 20.0:+.0f}s" for e in events}
    # at 26 columns the newest takes 6 lines, each older one 4: 13 rows hold two whole events
    out = event_log(events, 20.0, width=26, height=13).plain.splitlines()
    assert len(out) == 10 and all(len(line) <= 26 for line in out)
    for line in out:  # every piece on a line is a whole word or an event's age
        assert all(token in words | ages for token in line.split()), (line, out)
    # the newest event is whole at the bottom, the one before it above; the next one
    # would not fit whole and is left out
    text = " ".join(" ".join(out).split())
    assert text.endswith("-1s recommendation " + NEWEST)
    assert text.startswith("-2s vehicle sysid 18:")
    # continuation lines are indented under their event's first line
    firsts = [line for line in out if not line.startswith(" ")]
    assert [line.split()[0] for line in firsts] == ["-2s", "-1s"]


def test_a_word_longer_than_the_line_is_the_only_thing_cut() -> None:
    long = UsmEvent(t_s=0.0, kind="audit", text="id " + "x" * 40 + " end")
    out = event_log([long], 0.0, width=20, height=10).plain.splitlines()
    assert out[0] == "+0s audit id"
    assert all(len(line) <= 20 for line in out)
    assert "".join(line.strip() for line in out[1:]) == "x" * 40 + " end"
    assert out[-1].split()[-1] == "end"


class _MapOnly(App[None]):
    CSS = "#map { height: auto; min-height: 8; max-height: 65%; }"

    def compose(self) -> ComposeResult:
        yield AirspaceMap(id="map")


async def test_map_height_follows_the_scene_without_jumping_a_row() -> None:
    """The map widget takes the rows its scene needs at its width (a flat scene few, a tall
    one up to its cap) and ignores a change of one row."""
    flat = MapScene(plans=(MapPlan("UAS1", ((0.0, 0.0), (2000.0, 700.0))),))
    tall = MapScene(plans=(MapPlan("UAS1", ((0.0, 0.0), (300.0, 2000.0))),))
    app = _MapOnly()
    async with app.run_test(size=(40, 40)) as pilot:
        widget = app.query_one(AirspaceMap)
        heights = []
        for scene in (flat, tall, flat, _one_row_taller(flat, 40)):
            widget.show(scene)
            await pilot.pause()
            heights.append(widget.size.height)
    flat_rows = rows_to_fit(flat, 40)
    assert 8 < flat_rows < 15
    assert heights == [flat_rows, 26, flat_rows, flat_rows]


def _one_row_taller(scene: MapScene, width: int) -> MapScene:
    """``scene`` with its plan stretched north until it needs one row more at ``width``."""
    (a, b) = scene.plans[0].points
    for north_m in range(int(b[1]), int(b[1]) + 1000):
        taller = MapScene(plans=(MapPlan("UAS1", (a, (b[0], float(north_m)))),))
        if rows_to_fit(taller, width) == rows_to_fit(scene, width) + 1:
            return taller
    raise AssertionError("no scene one row taller")
