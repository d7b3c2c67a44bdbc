"""What the operator sees, as rich renderables built from one :class:`DashboardData` snapshot.

Pure functions of the snapshot (time passed in), so they render the same in the Textual app,
in ``--headless`` log lines and in tests (``Console(file=StringIO(), width=100)``).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass

from rich.console import Group
from rich.panel import Panel
from rich.table import Table
from rich.text import Text

from gcs_utm.messages import LinkHealth, VehicleStatus
from gcs_utm.model import (
    Alternative,
    Geofence,
    GeofenceShape,
    Operation,
    Recommendation,
    SysId,
    Threat,
    Track,
    TrackId,
)
from gcs_utm.services.usm import Usm, UsmEvent


@dataclass(frozen=True, slots=True, kw_only=True)
class DashboardData:
    t_s: float
    operations: tuple[Operation, ...]
    tracks: dict[TrackId, Track]
    statuses: dict[SysId, VehicleStatus]
    health: dict[SysId, LinkHealth]
    threats: tuple[Threat, ...]
    pending: tuple[Recommendation, ...]
    geofences: tuple[Geofence, ...]
    events: tuple[UsmEvent, ...]


def collect(usm: Usm, tracks: Callable[[], dict[TrackId, Track]]) -> DashboardData:
    """Take one snapshot of the USM's picture for rendering."""
    now = usm.clock.now_s()
    return DashboardData(
        t_s=now,
        operations=tuple(sorted(usm.airspace.operations.values(), key=lambda o: o.id)),
        tracks=tracks(),
        statuses=usm.statuses_by_sys_id(),
        health=usm.health_by_sys_id(),
        threats=tuple(sorted(usm.threats.values(), key=lambda t: t.detected_at_s)),
        pending=tuple(sorted(usm.pending(), key=lambda r: r.deadline_t_s)),
        geofences=usm.airspace.geofences(active_at_s=now),
        events=tuple(usm.events)[-50:],
    )


def _fmt(value: float | None, spec: str = ".0f", unit: str = "") -> str:
    if value is None or not math.isfinite(value):
        return "-"
    return f"{value:{spec}}{unit}"


def operations_table(d: DashboardData) -> Table:
    table = Table(title="Operations", expand=True, show_lines=False)
    table.add_column("UAS", no_wrap=True, min_width=6)
    table.add_column("ConOps", overflow="ellipsis", max_width=14, no_wrap=True)
    for col in ("Prio", "Position", "Alt AMSL", "Speed", "WP", "Link", "Batt", "Mode", "State"):
        table.add_column(col, overflow="fold")
    for op in d.operations:
        track = d.tracks.get(TrackId(op.id))
        status = d.statuses.get(op.sys_id) if op.sys_id is not None else None
        health = d.health.get(op.sys_id) if op.sys_id is not None else None
        pos = f"{track.lat_deg:.5f},{track.lon_deg:.5f}" if track else "-"
        alt = _fmt(track.alt_amsl_m, ".0f", " m") if track else "-"
        speed = _fmt(track.ground_speed_mps, ".1f", " m/s") if track else "-"
        wp_idx = track.next_waypoint if track and track.next_waypoint is not None else None
        wp = (
            f"{wp_idx}/{len(op.plan.waypoints)}"
            if wp_idx is not None
            else (f"-/{len(op.plan.waypoints)}")
        )
        link = "-"
        if health is not None:
            age = d.t_s - health.last_heard_t_s
            link = f"{health.rate_hz:.1f} Hz" + (f" ({age:.0f}s ago)" if age > 3 else "")
        elif track is not None and track.stale:
            link = "stale"
        batt = _fmt(status.battery_pct, ".0f", "%") if status else "-"
        mode = status.mode.value if status else "-"
        table.add_row(
            op.id,
            op.conops[:18],
            str(op.priority),
            pos,
            alt,
            speed,
            wp,
            link,
            batt,
            mode,
            op.state.value,
        )
    intruders = [t for t in d.tracks.values() if not t.cooperative]
    for t in intruders:
        table.add_row(
            t.id,
            "intruder (ADS-B)",
            "-",
            f"{t.lat_deg:.5f},{t.lon_deg:.5f}",
            _fmt(t.alt_amsl_m, ".0f", " m"),
            _fmt(t.ground_speed_mps, ".1f", " m/s"),
            "-",
            "stale" if t.stale else "ok",
            "-",
            "-",
            "non-coop",
        )
    return table


def threats_table(d: DashboardData) -> Table:
    table = Table(title="Active threats", expand=True)
    for col in ("Kind", "UAS", "Geofence", "Detected", "Event in", "Closest"):
        table.add_column(col, no_wrap=True)
    for t in d.threats:
        event_in = (
            f"{t.predicted_event_at_s - d.t_s:+.0f} s"
            if t.predicted_event_at_s is not None
            else "-"
        )
        table.add_row(
            t.kind.value,
            ",".join(t.uas_ids) or "-",
            t.geofence_id or "-",
            f"{d.t_s - t.detected_at_s:.0f} s ago",
            event_in,
            _fmt(t.closest_approach_m, ".0f", " m"),
        )
    return table


def geofences_table(d: DashboardData) -> Table:
    table = Table(title="Geofences", expand=True)
    for col in ("Id", "Shape", "Band AMSL", "Window", "Reason"):
        table.add_column(col, no_wrap=True)
    for g in d.geofences:
        shape = (
            f"circle r={g.radius_m:.0f} m"
            if g.shape is GeofenceShape.CYLINDER
            else f"polygon {len(g.vertices)} pts"
        )
        start = "-" if g.start_t_s is None else f"{g.start_t_s - d.t_s:+.0f}s"
        end = "-" if g.end_t_s is None else f"{g.end_t_s - d.t_s:+.0f}s"
        table.add_row(
            g.id,
            shape,
            f"{g.min_alt_amsl_m:.0f}-{g.max_alt_amsl_m:.0f} m",
            f"{start}..{end}",
            g.reason or g.kind.value,
        )
    return table


def _alt_row(index: int, alt: Alternative, chosen: bool) -> tuple[str, str, str, str, str]:
    mark = ">" if chosen else " "
    return (
        mark + str(index),
        alt.maneuver.value,
        f"{alt.cost:.3f}",
        f"{alt.risk:.3f}",
        alt.detail[:40],
    )


def recommendation_panel(
    rec: Recommendation, d: DashboardData, *, viewing: int = 0, queue: int = 1
) -> Panel:
    """The pilot prompt: threat, proposed action, alternatives with cost and risk, deadline."""
    left = rec.deadline_t_s - d.t_s
    head = Text()
    head.append(f"{rec.threat_kind.value}", style="bold red")
    head.append(f"  UAS {rec.operation_id}  recommendation {rec.id} v{rec.version}\n")
    if rec.selected is not None:
        head.append(f"Proposed: {rec.selected.maneuver.value}", style="bold")
        head.append(f"  cost {rec.selected.cost:.3f}  risk {rec.selected.risk:.3f}\n")
    elif rec.command is not None:
        head.append(f"Proposed command: {rec.command.kind.value}\n", style="bold")
    if rec.reason:
        head.append(f"Why: {rec.reason}\n")
    head.append(f"Deadline: {max(0.0, left):.0f} s left", style="yellow" if left > 10 else "red")
    head.append(f"   ({queue} pending)\n")
    options = (
        [rec.selected, *rec.alternatives] if rec.selected is not None else list(rec.alternatives)
    )
    table = Table(expand=True)
    for col in ("#", "Maneuver", "Cost", "Risk", "Detail"):
        table.add_column(col)
    for i, alt in enumerate(o for o in options if o is not None):
        table.add_row(*_alt_row(i, alt, i == viewing))
    keys = Text(
        "[a] accept   [r] reject   [n]/[p] view alternatives   [tab] next pending", style="dim"
    )
    return Panel(Group(head, table, keys), title="Pilot confirmation", border_style="red")


def events_text(d: DashboardData, limit: int = 12) -> Text:
    out = Text()
    for e in d.events[-limit:]:
        out.append(f"{e.t_s - d.t_s:+6.0f}s ", style="dim")
        out.append(f"{e.kind:<14}", style="cyan")
        out.append(e.text + "\n")
    return out


def top_view(d: DashboardData, *, width: int = 60, height: int = 20) -> Text:
    """A character map of the airspace seen from above: plans (.), tracks (letters) and
    geofences (#), scaled to fit. Uses lat/lon scaled by cos(lat): fine at city scale."""
    pts: list[tuple[float, float]] = []
    for op in d.operations:
        pts.extend((w.lat_deg, w.lon_deg) for w in op.plan.waypoints)
    pts.extend((t.lat_deg, t.lon_deg) for t in d.tracks.values())
    for g in d.geofences:
        if g.center is not None:
            pts.append((g.center.lat_deg, g.center.lon_deg))
        pts.extend((v.lat_deg, v.lon_deg) for v in g.vertices)
    if not pts:
        return Text("(empty airspace)")
    lat0 = sum(p[0] for p in pts) / len(pts)
    k = math.cos(math.radians(lat0))
    xs = [p[1] * k for p in pts]
    ys = [p[0] for p in pts]
    x_min, x_max, y_min, y_max = min(xs), max(xs), min(ys), max(ys)
    span = max(x_max - x_min, y_max - y_min, 1e-6)
    grid = [[" "] * width for _ in range(height)]

    def put(lat: float, lon: float, ch: str) -> None:
        col = int((lon * k - x_min) / span * (width - 1))
        row = height - 1 - int((lat - y_min) / span * (height - 1))
        if 0 <= row < height and 0 <= col < width:
            grid[row][col] = ch

    for g in d.geofences:
        if g.center is not None and g.radius_m is not None:
            r_deg = g.radius_m / 111_320.0
            for i in range(24):
                a = 2 * math.pi * i / 24
                put(
                    g.center.lat_deg + r_deg * math.sin(a),
                    g.center.lon_deg + r_deg * math.cos(a) / k,
                    "#",
                )
        for v in g.vertices:
            put(v.lat_deg, v.lon_deg, "#")
    for op in d.operations:
        wps = op.plan.waypoints
        for w0, w1 in itertools.pairwise(wps):
            for step in range(8):
                f = step / 8
                put(
                    w0.lat_deg + f * (w1.lat_deg - w0.lat_deg),
                    w0.lon_deg + f * (w1.lon_deg - w0.lon_deg),
                    ".",
                )
    for i, t in enumerate(sorted(d.tracks.values(), key=lambda t: t.id)):
        put(t.lat_deg, t.lon_deg, chr(ord("A") + i % 26) if t.cooperative else "!")
    return Text("\n".join("".join(r) for r in grid))


def headless_line(d: DashboardData) -> str:
    """One log line summarising the picture (``--headless``)."""
    parts = []
    for op in d.operations:
        t = d.tracks.get(TrackId(op.id))
        if t is None:
            parts.append(f"{op.id}:{op.state.value}")
        else:
            parts.append(
                f"{op.id}:{op.state.value} {t.alt_amsl_m:.0f}m {t.ground_speed_mps:.1f}m/s"
            )
    return (
        f"{len(d.operations)} ops, {len(d.threats)} threats, {len(d.pending)} pending | "
        + "; ".join(parts)
    )
