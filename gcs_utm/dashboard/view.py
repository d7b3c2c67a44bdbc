"""What the operator sees, as rich renderables built from one :class:`DashboardData` snapshot.

Pure functions of the snapshot (time passed in), so they render the same in the Textual app,
in ``--headless`` log lines and in tests (``Console(file=StringIO(), width=100)``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from rich.console import Group, RenderableType
from rich.panel import Panel
from rich.table import Table
from rich.text import Text

from gcs_utm.core.emergency.wording import action_text, command_text, option_text, why_text
from gcs_utm.messages import LinkHealth, VehicleStatus
from gcs_utm.model import (
    Geofence,
    GeofenceShape,
    Operation,
    Recommendation,
    SysId,
    Threat,
    ThreatKind,
    Track,
    TrackId,
)
from gcs_utm.services.recommendations import options_of
from gcs_utm.services.usm import Usm, UsmEvent


@dataclass(frozen=True, slots=True, kw_only=True)
class Minima:
    """The separation minima the prompt compares predictions with (``[monitoring]``): between
    operations, and between an operation and an intruder (``intruder_*``; None: not known,
    and an INTRUDER threat is then shown without a minimum rather than with the wrong one)."""

    horizontal_m: float
    vertical_m: float
    intruder_horizontal_m: float | None = None
    intruder_vertical_m: float | None = None
    safety_distance_m: float | None = None
    """Sphere mode (``separation_mode = "sphere"``): the 3D minimum, on both axes."""

    def for_threat(
        self, kind: ThreatKind, ov_sum_m: float = 0.0
    ) -> tuple[float | None, float | None]:
        """(horizontal, vertical) minima that apply to a threat of ``kind``: for a pair of
        operations the *effective* minima Monitoring judged it by, never below the sum
        ``ov_sum_m`` of their operational volumes (``MonitoringConfig.effective_minima``)."""
        if kind is ThreatKind.INTRUDER:
            return self.intruder_horizontal_m, self.intruder_vertical_m
        if self.safety_distance_m is not None:
            s = max(self.safety_distance_m, ov_sum_m)
            return s, s
        return max(self.horizontal_m, ov_sum_m), max(self.vertical_m, ov_sum_m)


@dataclass(frozen=True, slots=True, kw_only=True)
class DashboardData:
    t_s: float
    speed: float
    """Clock seconds per wall second: deadlines are shown in wall seconds (what the pilot has)."""
    operations: tuple[Operation, ...]
    tracks: dict[TrackId, Track]
    statuses: dict[SysId, VehicleStatus]
    health: dict[SysId, LinkHealth]
    threats: tuple[Threat, ...]
    pending: tuple[Recommendation, ...]
    geofences: tuple[Geofence, ...]
    events: tuple[UsmEvent, ...]
    minima: Minima | None = None


def collect(
    usm: Usm, tracks: Callable[[], dict[TrackId, Track]], minima: Minima | None = None
) -> DashboardData:
    """Take one snapshot of the USM's picture for rendering."""
    now = usm.clock.now_s()
    speed = usm.clock.speed
    return DashboardData(
        t_s=now,
        speed=speed if math.isfinite(speed) and speed > 0 else 1.0,
        minima=minima,
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


_OPS_COLUMNS = ("UAS", "ConOps", "Prio", "Position", "Alt AMSL", "Speed", "WP", "Link")
_OPS_COLUMNS_END = ("Batt", "Mode", "State")
_OPS_NARROW = ("UAS", "Alt AMSL", "Speed", "WP", "Link", "Mode", "State")
"""The columns kept below ``wide_at`` characters: what the pilot watches in an encounter."""


def operations_table(d: DashboardData, *, width: int | None = None, wide_at: int = 120) -> Table:
    """Operations (and intruders), one row each. Narrower than ``wide_at`` characters the
    table keeps the :data:`_OPS_NARROW` columns so every value stays readable."""
    columns: tuple[str, ...] = _OPS_COLUMNS + _OPS_COLUMNS_END
    if any(t.remote_id is not None for t in d.tracks.values()):
        columns += ("Remote ID",)  # only once some UAS broadcasts it (docs/remote-id.md)
    if width is not None and width < wide_at:
        columns = _OPS_NARROW
    table = Table(title="Operations", expand=True, show_lines=False)
    for col in columns:
        if col == "ConOps":
            table.add_column(col, overflow="ellipsis", max_width=14, no_wrap=True)
        else:
            table.add_column(col, overflow="fold", no_wrap=col == "UAS")
    rows: list[dict[str, str]] = []
    for op in d.operations:
        track = d.tracks.get(TrackId(op.id))
        status = d.statuses.get(op.sys_id) if op.sys_id is not None else None
        health = d.health.get(op.sys_id) if op.sys_id is not None else None
        wp_idx = track.next_waypoint if track and track.next_waypoint is not None else None
        link = "-"
        if health is not None:
            age = d.t_s - health.last_heard_t_s
            link = f"{health.rate_hz:.1f} Hz" + (f" ({age:.0f}s ago)" if age > 3 else "")
        elif track is not None and track.stale:
            link = "stale"
        rows.append(
            {
                "UAS": op.id,
                "ConOps": op.conops[:18],
                "Prio": str(op.priority),
                "Position": f"{track.lat_deg:.5f},{track.lon_deg:.5f}" if track else "-",
                "Alt AMSL": _fmt(track.alt_amsl_m, ".0f", " m") if track else "-",
                "Speed": _fmt(track.ground_speed_mps, ".1f", " m/s") if track else "-",
                "WP": f"{'-' if wp_idx is None else wp_idx}/{len(op.plan.waypoints)}",
                "Link": link,
                "Batt": _fmt(status.battery_pct, ".0f", "%") if status else "-",
                "Mode": status.mode.value if status else "-",
                "State": op.state.value,
                "Remote ID": _remote_id(track),
            }
        )
    for t in d.tracks.values():
        if t.cooperative:
            continue
        rows.append(
            {
                "UAS": t.id,
                "ConOps": "Remote ID" if t.id.startswith("rid:") else "intruder (ADS-B)",
                "Prio": "-",
                "Position": f"{t.lat_deg:.5f},{t.lon_deg:.5f}",
                "Alt AMSL": _fmt(t.alt_amsl_m, ".0f", " m"),
                "Speed": _fmt(t.ground_speed_mps, ".1f", " m/s"),
                "WP": "-",
                "Link": "stale" if t.stale else "ok",
                "Batt": "-",
                "Mode": "-",
                "State": "non-coop",
                "Remote ID": _remote_id(t),
            }
        )
    for row in rows:
        table.add_row(*(row[c] for c in columns))
    return table


def _remote_id(track: Track | None) -> str:
    """The UAS ID (and operator ID) its Remote ID broadcasts, "-" when none was heard."""
    rid = None if track is None else track.remote_id
    if rid is None or not (rid.uas_id or rid.operator_id):
        return "-"
    return " / ".join(x for x in (rid.uas_id, rid.operator_id) if x)


def _closest(t: Threat) -> str:
    """The predicted closest approach, per axis when known (a vertical pass is not a loss)."""
    if t.horizontal_m is not None and t.vertical_m is not None:
        return f"{t.horizontal_m:.0f} m h / {t.vertical_m:.0f} m v"
    return _fmt(t.closest_approach_m, ".0f", " m")


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
            _closest(t),
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


def wall_s(d: DashboardData, clock_s: float) -> float:
    """Clock seconds as the wall seconds the pilot has (at ``--speed 5``, 15 s are 3 s)."""
    return clock_s / d.speed


def _predicted(rec: Recommendation, d: DashboardData) -> str:
    """What Monitoring predicts for the threat behind ``rec``: with whom or what, when, and
    how close against the minima."""
    threat = next((t for t in d.threats if t.id == rec.threat_id), None)
    if threat is None:
        return f"{rec.threat_kind.value.lower().replace('_', ' ')} (threat {rec.threat_id})"
    others: list[str] = [u for u in threat.uas_ids if u != rec.operation_id]
    if threat.intruder_id is not None:
        others.append(f"intruder {threat.intruder_id}")
    what = threat.kind.value.lower().replace("_", " ")
    if others:
        what += " with " + ", ".join(others)
    if threat.geofence_id is not None:
        what += f" into geofence {threat.geofence_id}"
    if threat.predicted_event_at_s is not None:
        ahead = threat.predicted_event_at_s - d.t_s
        what += f" in {wall_s(d, ahead):.0f} s" if ahead > 0 else " now"
    ovs = {o.id: o.operational_volume_m for o in d.operations}
    pair = len(threat.uas_ids) == 2 and all(u in ovs for u in threat.uas_ids)
    ov_sum_m = sum(ovs[u] for u in threat.uas_ids) if pair else 0.0
    min_h, min_v = d.minima.for_threat(threat.kind, ov_sum_m) if d.minima else (None, None)
    parts = []
    if threat.horizontal_m is not None:
        parts.append(
            f"{threat.horizontal_m:.0f} m horizontal"
            + (f" (min {min_h:.0f})" if min_h is not None else "")
        )
    if threat.vertical_m is not None:
        parts.append(
            f"{threat.vertical_m:.0f} m vertical"
            + (f" (min {min_v:.0f})" if min_v is not None else "")
        )
    if parts:
        what += "; predicted closest " + ", ".join(parts)
    elif threat.closest_approach_m is not None:
        what += f"; predicted closest {threat.closest_approach_m:.0f} m"
    if threat.message:
        what += f"; {threat.message}"
    return what


def _prompt_head(rec: Recommendation, d: DashboardData, left_s: float) -> Text:
    """The prompt's top lines: threat, prediction, proposal, why, time left."""
    urgent = left_s < 10.0
    head = Text()
    head.append(f"{rec.threat_kind.value}", style="bold red")
    head.append(f"  UAS {rec.operation_id}  recommendation {rec.id} v{rec.version}\n")
    head.append("Predicted: ", style="bold")
    head.append(_predicted(rec, d) + "\n")
    if rec.selected is not None:
        head.append(f"Proposed: {action_text(rec.selected)}", style="bold")
        head.append(f" ({rec.selected.maneuver.value})\n")
    elif rec.command is not None:
        track = d.tracks.get(TrackId(rec.operation_id))
        what = command_text(rec.command, None if track is None else track.alt_amsl_m)
        head.append(f"Proposed command: {what}\n", style="bold")
    head.append("Why: ", style="bold")
    head.append(why_text(rec) + "\n")
    head.append(
        f"{'ANSWER NOW: ' if urgent else ''}{left_s:.0f} s left",
        style="bold white on red" if urgent else "bold yellow",
    )
    speed = f", clock x{d.speed:g}" if d.speed != 1.0 else ""
    head.append(f" (wall clock{speed})")
    return head


def _options_table(rec: Recommendation, viewing: int, details: bool) -> Table:
    """One row per option in words (``details``: with the manoeuvre, cost and risk)."""
    table = Table(expand=True, box=None, pad_edge=False, show_edge=False)
    table.add_column("#", no_wrap=True, width=3)
    if details:
        table.add_column("Manoeuvre", no_wrap=True)
    table.add_column("Option: what the UAS does, and its effect", overflow="fold", ratio=3)
    if details:
        table.add_column("Cost", no_wrap=True, justify="right")
        table.add_column("Risk", no_wrap=True, justify="right")
    for i, alt in enumerate(options_of(rec)):
        proposed = " (proposed)" if i == 0 and rec.selected is not None else ""
        row = [(">" if i == viewing else " ") + str(i)]
        if details:
            row += [alt.maneuver.value + proposed, option_text(alt)]
            row += [f"{alt.cost:.3f}", f"{alt.risk:.3f}"]
        else:
            row.append(option_text(alt) + proposed)
        table.add_row(*row, style="reverse" if i == viewing else None)
    return table


def _key_line(rec: Recommendation, viewing: int, details: bool) -> str:
    options = options_of(rec)
    if 0 <= viewing < len(options):
        target = f"{viewing} {options[viewing].maneuver.value}"
    else:
        target = rec.command.kind.value if rec.command is not None else "the proposal"
    return (
        f"[a] accept {target}   [r] reject   [n]/[p] option   "
        f"[d] {'hide' if details else 'show'} scores   [tab] next pending   [q] quit"
    )


def recommendation_panel(
    rec: Recommendation,
    d: DashboardData,
    *,
    viewing: int = 0,
    queue: int = 1,
    keys: str | None = None,
    note: str = "",
    details: bool = False,
    alarm: str = "",
) -> Panel:
    """The pilot prompt: what is predicted, each option as an action and its effect in the
    pilot's words (row ``viewing`` highlighted: it is what ``a`` accepts), why the proposed
    one, the wall-clock time left and how to answer. ``details`` adds the raw scores (cost,
    risk, the scoring terms, EM's reason). ``keys`` replaces the key line (e.g. for a line
    prompt); an empty string says that nothing on this screen answers. ``note`` is shown in
    bold (e.g. "key ignored"); ``alarm`` (an expiry, in a few words) heads the title."""
    left_s = max(0.0, wall_s(d, rec.deadline_t_s - d.t_s))
    head = _prompt_head(rec, d, left_s)
    head.append(f"   {queue} pending")
    parts: list[RenderableType] = [head]
    options = options_of(rec)
    if options:
        parts.append(_options_table(rec, viewing, details))
    if details and 0 <= viewing < len(options):
        alt = options[viewing]
        detail = Text(f"{viewing} {alt.maneuver.value}: ", style="bold")
        detail.append(alt.detail or "(no detail)")
        parts.append(detail)
    if details and rec.reason:
        parts.append(Text(f"EM: {rec.reason}", style="dim"))
    if note:
        parts.append(Text(note, style="bold magenta"))
    keys = _key_line(rec, viewing, details) if keys is None else keys
    if keys:
        parts.append(Text(keys, style="bold"))
    title = Text(f"Pilot confirmation: {left_s:.0f} s left")
    if alarm:
        title = Text.assemble((alarm, "bold white on red"), "  ", title)
    return Panel(
        Group(*parts),
        title=title,
        border_style="red" if left_s < 10.0 or alarm else "yellow",
    )


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
