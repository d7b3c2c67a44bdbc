"""Pictures of a run, the counterparts of the paper's result figures for its use cases
(docs/use-cases.md says figure by figure what matches and what differs):

- ``<stem>_top.png``: top view of the filed plans with their operational volumes, every later
  plan version, the tracks flown, geofences, the alternatives TD generated (the selected one in
  black) and the predicted conflict points;
- ``<stem>_3d.png``: the same in 3D;
- ``<stem>_altitude.png``: altitude above ground against time per UAS, planned (every
  version) and flown, with the threat detections and the accepted recommendations;
- ``<stem>_separation.png``: distance between each UAS pair against time, as flown (tracks)
  and as the filed plans would have been flown with each vehicle's start delay and no
  resolution, with the separation minimum and the minimum reached;
- ``<stem>_geofence.png`` (runs with geofences): a close-up top view of each geofence with the
  paths near it, and each UAS's signed horizontal distance to the geofence edge over time
  while it is active (below 0 = inside).

Also GeoJSON and KML exports of the same data for QGIS / Google Earth.

Input is the JSON report of ``gcs-utm run`` (docs/use-cases.md lists its fields). Figures use
matplotlib's non-interactive Agg backend; matplotlib is the optional extra ``[plots]``,
imported only when a figure is drawn (without it ``gcs-utm run`` writes GeoJSON and KML
only). Each function returns what it drew (counts and the minima it computed from the report),
so tests check the data plotted, not only that a file exists. Units: metres and seconds from
scenario start, as in the report.
"""

from __future__ import annotations

import json
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gcs_utm.dashboard.export import to_geojson, to_kml

__all__ = [
    "PlotSummary",
    "ReportError",
    "export_all",
    "flown_pairs",
    "load_report",
    "planned_pairs",
    "plot_report",
    "to_geojson",
    "to_kml",
]

from gcs_utm.dashboard.plotting import PlotsUnavailableError, require_plots
from gcs_utm.dashboard.series import (
    Local,
    PairSeries,
    flown_pairs,
    interp_plan,
    minima,
    planned_pairs,
)

_log = logging.getLogger(__name__)


class ReportError(ValueError):
    """The report file is not a gcs-utm run report; ``field`` says what is missing."""

    def __init__(self, path: str, field_name: str, message: str) -> None:
        super().__init__(f"{path}: {field_name}: {message}")
        self.path = path
        self.field_name = field_name


@dataclass(slots=True)
class PlotSummary:
    files: list[Path] = field(default_factory=list)
    plans: int = 0
    alternatives: int = 0
    tracks: int = 0
    geofences: int = 0
    conflict_points: int = 0
    altitude_profiles: int = 0
    # "A|B" -> smallest flown distance drawn (horizontal, or 3D in sphere mode), metres
    min_separation_m: dict[str, float] = field(default_factory=dict)
    # "A|B" -> smallest distance of the filed plans flown late without resolution, metres
    min_planned_separation_m: dict[str, float] = field(default_factory=dict)
    # "A|B" -> the flown pair's verdict, naming both axes against their minima (cylinder rule)
    separation_verdict: dict[str, str] = field(default_factory=dict)
    # "UAS|geofence" -> smallest signed distance to the edge while active (< 0 = inside)
    min_geofence_distance_m: dict[str, float] = field(default_factory=dict)


def load_report(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ReportError(str(path), "-", f"cannot read JSON: {exc}") from exc
    if not isinstance(data, dict):
        raise ReportError(str(path), "-", "expected a JSON object")
    for key in ("origin", "operations", "geofences"):
        if key not in data:
            raise ReportError(str(path), key, "missing (not a gcs-utm run report?)")
    return data


def _circle(cx: float, cy: float, r: float, n: int = 48) -> tuple[list[float], list[float]]:
    xs = [cx + r * math.cos(2 * math.pi * i / n) for i in range(n + 1)]
    ys = [cy + r * math.sin(2 * math.pi * i / n) for i in range(n + 1)]
    return xs, ys


def plot_report(report: dict[str, Any], out_dir: Path, *, stem: str = "run") -> PlotSummary:
    """Write every figure of the module docstring into ``out_dir``."""
    require_plots()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    local = Local(report["origin"])
    summary = PlotSummary()
    focus = _focus_point(report, local)
    if focus is None:
        fig, ax_all = plt.subplots(figsize=(9, 8))
        ax: Any = ax_all
        ax_zoom: Any = None
    else:
        fig, (ax_all, ax_zoom) = plt.subplots(1, 2, figsize=(16, 8))
        ax = _Both(ax_all, ax_zoom)
    fig3 = plt.figure(figsize=(9, 8))
    ax3 = fig3.add_subplot(projection="3d")
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]

    _draw_geofences(report, local, ax, ax3, summary)
    _draw_operations(report, local, ax, ax3, summary, colours)
    labelled: set[str] = set()  # one legend entry per kind
    _draw_alternatives(report, local, ax, ax3, summary, labelled)
    _draw_threats(report, local, ax, ax3, summary, labelled)
    _label_top(report, summary, ax, ax_all, (ax_zoom, focus))
    _label_3d(report, summary, ax3)
    top = out_dir / f"{stem}_top.png"
    persp = out_dir / f"{stem}_3d.png"
    fig.savefig(top, dpi=110)
    fig3.savefig(persp, dpi=110)
    plt.close(fig)
    plt.close(fig3)
    summary.files += [top, persp]
    summary.files.append(plot_altitude(report, out_dir, stem, summary))
    for extra in (
        plot_separation(report, out_dir, stem, summary),
        plot_geofences(report, out_dir, stem, summary),
    ):
        if extra is not None:
            summary.files.append(extra)
    return summary


def _label_top(
    report: dict[str, Any], summary: PlotSummary, ax: Any, ax_all: Any, zoom: tuple[Any, Any]
) -> None:
    """Axes, title and legend of the top view; the close-up's window around its focus point
    (``zoom``: its axes and the focus, both None without one)."""
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax_all.set_aspect("equal", adjustable="datalim")
    ax_all.set_title(f"{report.get('scenario', '')}: top view")
    if summary.plans:
        ax_all.legend(fontsize=7, loc="best")
    ax_zoom, focus = zoom
    if focus is not None:
        (fx, fy), half, what = focus
        ax_zoom.set_xlim(fx - half, fx + half)
        ax_zoom.set_ylim(fy - half, fy + half)
        ax_zoom.plot([fx], [fy], "x", color="red", ms=12, mew=2)
        ax_zoom.set_aspect("equal", adjustable="box")
        ax_zoom.set_title(f"close-up: {what} (x), alternatives grey, selected black")


def _label_3d(report: dict[str, Any], summary: PlotSummary, ax3: Any) -> None:
    ax3.set_xlabel("east [m]")
    ax3.set_ylabel("north [m]")
    ax3.set_zlabel("altitude AMSL [m]")
    ax3.set_title(f"{report.get('scenario', '')}: 3D")
    if summary.plans:
        ax3.legend(fontsize=7, loc="upper left")


def _once(labelled: set[str], label: str) -> str:
    """A legend label the first time, none after (one legend entry per kind)."""
    if label in labelled:
        return "_nolegend_"
    labelled.add(label)
    return label


def _draw_geofences(
    report: dict[str, Any], local: Local, ax: Any, ax3: Any, summary: PlotSummary
) -> None:
    """Each geofence filled on the top view, its floor and ceiling outlined in 3D."""
    for g in report.get("geofences", []):
        summary.geofences += 1
        lo, hi = float(g.get("min_alt_amsl_m", 0.0)), float(g.get("max_alt_amsl_m", 0.0))
        if g.get("shape") == "cylinder":
            cx, cy = local.xy(g["center"]["lat_deg"], g["center"]["lon_deg"])
            xs, ys = _circle(cx, cy, float(g["radius_m"]))
        else:
            pts = [local.xy(v["lat_deg"], v["lon_deg"]) for v in g["vertices"]]
            pts.append(pts[0])
            xs, ys = [p[0] for p in pts], [p[1] for p in pts]
        ax.fill(xs, ys, color="red", alpha=0.25)
        ax.plot(xs, ys, color="red", lw=1)
        ax.annotate(str(g["id"]), (xs[0], ys[0]), color="red", fontsize=8)
        for z in (lo, hi):
            ax3.plot(xs, ys, [z] * len(xs), color="red", alpha=0.5, lw=0.8)


def _draw_operations(  # noqa: PLR0917 - private helper, positional like its siblings
    report: dict[str, Any],
    local: Local,
    ax: Any,
    ax3: Any,
    summary: PlotSummary,
    colours: list[str],
) -> None:
    """Each operation's plan versions (the filed one with its operational volume) and track."""
    for i, op in enumerate(report.get("operations", [])):
        colour = colours[i % len(colours)]
        ov = float(op.get("operational_volume_m", 0.0))
        for j, plan in enumerate(op.get("plans", [])):
            pts = [local.xy(w[0], w[1]) for w in plan["waypoints"]]
            zs = [float(w[2]) for w in plan["waypoints"]]
            xs, ys = [p[0] for p in pts], [p[1] for p in pts]
            style = "-" if j == 0 else "--"
            label = f"{op['id']} plan v{plan['version']}"
            ax.plot(xs, ys, style, color=colour, lw=1.5, label=label)
            if ov > 0 and j == 0:
                # the operational volume: the filed plan's path grown by its radius
                _fill_volume(ax, xs, ys, ov, colour)
            ax3.plot(xs, ys, zs, style, color=colour, lw=1.5, label=label)
            summary.plans += 1
        track = report.get("tracks", {}).get(op["id"], [])
        if track:
            pts = [local.xy(p[1], p[2]) for p in track]
            ax.plot(
                [p[0] for p in pts],
                [p[1] for p in pts],
                ":",
                color=colour,
                lw=1,
                label=f"{op['id']} flown",
            )
            ax3.plot(
                [p[0] for p in pts],
                [p[1] for p in pts],
                [p[3] for p in track],
                ":",
                color=colour,
                lw=1,
                label=f"{op['id']} flown",
            )
            summary.tracks += 1


def _draw_alternatives(  # noqa: PLR0917 - private helper, positional like its siblings
    report: dict[str, Any],
    local: Local,
    ax: Any,
    ax3: Any,
    summary: PlotSummary,
    labelled: set[str],
) -> None:
    """TD's alternatives of every recommendation: the selected one black, the others grey."""
    for rec in report.get("recommendations", []):
        for alt in rec.get("alternatives", []):
            wps = alt.get("waypoints") or []
            if len(wps) < 2:
                continue
            pts = [local.xy(w[0], w[1]) for w in wps]
            chosen = bool(alt.get("selected"))
            label = _once(labelled, "selected alternative" if chosen else "other TD alternatives")
            ax.plot(
                [p[0] for p in pts],
                [p[1] for p in pts],
                "-" if chosen else "-.",
                color="black" if chosen else "grey",
                lw=1.2 if chosen else 0.6,
                alpha=1.0 if chosen else 0.6,
                label=label,
            )
            ax3.plot(
                [p[0] for p in pts],
                [p[1] for p in pts],
                [w[2] for w in wps],
                color="black" if chosen else "grey",
                lw=0.8,
                label=label,
            )
            summary.alternatives += 1


def _draw_threats(  # noqa: PLR0917 - private helper, positional like its siblings
    report: dict[str, Any],
    local: Local,
    ax: Any,
    ax3: Any,
    summary: PlotSummary,
    labelled: set[str],
) -> None:
    """The predicted conflict point of every threat that has one."""
    for t in report.get("threats", []):
        pos = t.get("position")
        if pos:
            x, y = local.xy(pos["lat_deg"], pos["lon_deg"])
            label = _once(labelled, "predicted conflict point")
            ax.plot([x], [y], "x", color="red", ms=10, mew=2, label=label)
            ax3.scatter(
                [x], [y], [pos.get("alt_amsl_m", 0.0)], marker="x", color="red", label=label
            )
            summary.conflict_points += 1


class _Both:
    """Draw the same top view on the overall and the close-up axes."""

    def __init__(self, *axes: Any) -> None:
        self._axes = axes

    def __getattr__(self, name: str) -> Any:
        def call(*args: Any, **kwargs: Any) -> None:
            for a in self._axes:
                getattr(a, name)(*args, **kwargs)

        return call


def _focus_point(
    report: dict[str, Any], local: Local
) -> tuple[tuple[float, float], float, str] | None:
    """Where the close-up looks: the first predicted loss of separation or geofence conflict
    (east, north), a half-width that shows the manoeuvre around it, and what it is."""
    for t in report.get("threats", []):
        kind = t.get("kind")
        pos = t.get("position")
        if pos and kind in ("LOSS_OF_SEPARATION", "GEOFENCE_CONFLICT"):
            half = 250.0
            for g in report.get("geofences", []):
                if g.get("id") == t.get("geofence") and g.get("radius_m"):
                    half = max(half, 3.0 * float(g["radius_m"]))
            return local.xy(pos["lat_deg"], pos["lon_deg"]), half, str(kind)
        if kind == "LOSS_OF_SEPARATION" and t.get("closest_approach_at_s") is not None:
            # no position recorded: midway between the two plans (as flown late) at the
            # predicted closest approach
            at = float(t["closest_approach_at_s"])
            pts = []
            for op in report.get("operations", []):
                if op["id"] in t.get("uas", []) and op.get("plans"):
                    delay = float(op.get("start_delay_s", 0.0) or 0.0)
                    wps = [[w[0], w[1], w[2], w[3] + delay] for w in op["plans"][0]["waypoints"]]
                    p = interp_plan(wps, at)
                    if p is not None:
                        pts.append(local.xy(p[0], p[1]))
            if pts:
                mid = (sum(p[0] for p in pts) / len(pts), sum(p[1] for p in pts) / len(pts))
                return mid, 250.0, f"{kind} predicted at t={at:.0f} s"
    return None


def _fill_volume(ax: Any, xs: list[float], ys: list[float], radius_m: float, colour: str) -> None:
    from shapely.geometry import LineString, Point

    geom = LineString(list(zip(xs, ys, strict=True))) if len(xs) > 1 else Point(xs[0], ys[0])
    area = geom.buffer(radius_m)
    polys = list(getattr(area, "geoms", [area]))
    for poly in polys:
        bx, by = poly.exterior.xy
        ax.fill(list(bx), list(by), color=colour, alpha=0.15, lw=0)


# ---- time series: altitude, separation, geofence distance -------------------------------------


def _ground(report: dict[str, Any]) -> float:
    return float(report.get("origin", {}).get("ground_elevation_amsl_m", 0.0) or 0.0)


def _fence_signed_distance(local: Local, g: dict[str, Any], lat: float, lon: float) -> float:
    """Horizontal distance from a point to a geofence edge, negative inside."""
    x, y = local.xy(lat, lon)
    if g.get("shape") == "cylinder":
        cx, cy = local.xy(g["center"]["lat_deg"], g["center"]["lon_deg"])
        return math.hypot(x - cx, y - cy) - float(g["radius_m"])
    from shapely.geometry import Point, Polygon

    poly = Polygon([local.xy(v["lat_deg"], v["lon_deg"]) for v in g["vertices"]])
    d = float(poly.exterior.distance(Point(x, y)))
    return -d if poly.contains(Point(x, y)) else d


def _active(g: dict[str, Any], t_s: float) -> bool:
    start, end = g.get("start_s"), g.get("end_s")
    return (start is None or t_s >= start) and (end is None or t_s <= end)


def fence_distances(
    report: dict[str, Any],
) -> dict[tuple[str, str], tuple[list[float], list[float]]]:
    """(UAS, geofence) -> (times, signed horizontal distance to the edge) of the UAS's track
    while the geofence is active and within its altitude band; UAS exempt from a geofence
    (the jammed UAS inside its own) are left out."""
    local = Local(report["origin"])
    out: dict[tuple[str, str], tuple[list[float], list[float]]] = {}
    for g in report.get("geofences", []):
        exempt = set(g.get("exempt", []))
        lo = float(g.get("min_alt_amsl_m", -math.inf))
        hi = float(g.get("max_alt_amsl_m", math.inf))
        for uas, track in report.get("tracks", {}).items():
            if uas in exempt:
                continue
            ts, ds = [], []
            for s in track:
                if _active(g, s[0]) and lo <= float(s[3]) <= hi:
                    ts.append(float(s[0]))
                    ds.append(_fence_signed_distance(local, g, s[1], s[2]))
            if ts:
                out[(uas, str(g["id"]))] = (ts, ds)
    return out


def _threat_times(report: dict[str, Any], uas: str | None = None) -> list[tuple[float, str]]:
    out = []
    seen = set()
    for t in report.get("threats", []):
        if t.get("detected_at_s") is None or (uas is not None and uas not in t.get("uas", [])):
            continue
        key = (t.get("kind"), tuple(t.get("uas", [])), t.get("detected_at_s"))
        if key in seen:
            continue
        seen.add(key)
        out.append((float(t["detected_at_s"]), str(t.get("kind", ""))))
    return out


def _answer_times(report: dict[str, Any], uas: str | None = None) -> list[tuple[float, str]]:
    """(time, maneuver) of each accepted recommendation (its plan version's first time)."""
    out = []
    for r in report.get("recommendations", []):
        if r.get("decision") != "accepted" or (uas is not None and r.get("uas") != uas):
            continue
        if r.get("created_at_s") is not None:
            out.append((float(r["created_at_s"]), str(r.get("maneuver"))))
    return out


_EVENT_COLOURS = ("red", "darkorange", "purple", "saddlebrown", "magenta", "olive")
"""One colour per threat kind in the altitude figure (green is for accepted answers)."""


def plot_altitude(report: dict[str, Any], out_dir: Path, stem: str, summary: PlotSummary) -> Path:
    """``<stem>_altitude.png``: altitude above ground over time per UAS."""
    import matplotlib.pyplot as plt

    ops = report.get("operations", [])
    ground = _ground(report)
    fig, axes = plt.subplots(
        max(1, len(ops)), 1, figsize=(12, 2.6 * max(1, len(ops))), squeeze=False
    )
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, op in enumerate(ops):
        ax = axes[i][0]
        colour = colours[i % len(colours)]
        for j, plan in enumerate(op.get("plans", [])):
            wps = plan["waypoints"]
            ax.plot(
                [w[3] for w in wps],
                [w[2] - ground for w in wps],
                "-" if j == 0 else "--",
                color=colour if j == 0 else "black",
                lw=1.5 if j == 0 else 1.0,
                label="filed plan"
                if j == 0
                else f"plan v{plan['version']} ({plan.get('reason', '')})",
            )
        track = report.get("tracks", {}).get(op["id"], [])
        if track:
            ax.plot(
                [s[0] for s in track],
                [s[3] - ground for s in track],
                ":",
                color=colour,
                lw=1.5,
                label="flown",
            )
            summary.altitude_profiles += 1
        # events are named in the legend, not in text on the plot: detections a second
        # apart would print their labels on top of each other
        kinds: list[str] = []
        for t, kind in _threat_times(report, op["id"]):
            first = kind not in kinds
            kinds += [kind] if first else []
            ax.axvline(
                t,
                color=_EVENT_COLOURS[kinds.index(kind) % len(_EVENT_COLOURS)],
                lw=1.0,
                alpha=0.8,
                label=f"{kind} detected" if first else "_nolegend_",
            )
        for t, man in _answer_times(report, op["id"]):
            ax.axvline(t, color="green", lw=0.8, ls="--", label=f"accepted {man} (t={t:.0f} s)")
        ax.set_ylabel(f"{op['id']}\naltitude AGL [m]")
        ax.legend(fontsize=6, loc="center left", bbox_to_anchor=(1.01, 0.5))
        ax.grid(alpha=0.3)
    axes[-1][0].set_xlabel("time from scenario start [s]")
    return _save(
        fig,
        out_dir / f"{stem}_altitude.png",
        f"{report.get('scenario', '')}: altitude profiles (planned vs flown)",
    )


def plot_separation(
    report: dict[str, Any], out_dir: Path, stem: str, summary: PlotSummary
) -> Path | None:
    """``<stem>_separation.png``: pair distances over time, flown and as filed."""
    import matplotlib.pyplot as plt

    flown = flown_pairs(report)
    planned = planned_pairs(report)
    if not flown and not planned:
        return None
    mode, d_min, v_min = minima(report)
    keys = []
    for series_ab in [*flown, *planned]:
        if (series_ab.a, series_ab.b) not in keys:
            keys.append((series_ab.a, series_ab.b))
    fig, axes = plt.subplots(
        2, len(keys), figsize=(9 * len(keys), 6.5), squeeze=False, sharex="col"
    )
    for col, (a, b) in enumerate(keys):
        top, bottom = axes[0][col], axes[1][col]
        key = f"{a}|{b}"
        verdicts: list[str] = []
        for series, style, label, store in (
            (
                planned,
                "--",
                "filed plans, flown with the start delays, no resolution",
                summary.min_planned_separation_m,
            ),
            (flown, "-", "flown (UTM tracks)", summary.min_separation_m),
        ):
            ps = next((p for p in series if (p.a, p.b) == (a, b)), None)
            if ps is None:
                continue
            main = ps.distance_m if mode == "sphere" else ps.horizontal_m
            top.plot(ps.t_s, main, style, lw=1.3, label=label)
            bottom.plot(ps.t_s, ps.vertical_m, style, lw=1.3, label=label)
            k = min(range(len(main)), key=main.__getitem__)
            store[key] = main[k]
            top.plot(
                [ps.t_s[k]],
                [main[k]],
                "o",
                color="black" if style == "-" else "grey",
                label=f"closest {main[k]:.1f} m at t={ps.t_s[k]:.0f} s",
            )
            if style == "-" and mode != "sphere":
                verdicts.append(_shade_verdict(top, bottom, ps, d_min, v_min))
        top.axhline(d_min, color="red", lw=1, label=f"horizontal minimum {d_min:g} m")
        if mode != "sphere":
            bottom.axhline(v_min, color="red", lw=1, label=f"vertical minimum {v_min:g} m")
        first = True
        for t, kind in _threat_times(report):
            if kind == "LOSS_OF_SEPARATION":
                label = "loss of separation predicted" if first else "_nolegend_"
                top.axvline(t, color="orange", lw=0.8, ls=":", label=label)
                first = False
        for t, man in _answer_times(report):
            top.axvline(t, color="green", lw=0.8, ls="--", label=f"accepted {man} (t={t:.0f} s)")
        # a 10 km transit would hide the close encounter: show up to 6 minima, or a little
        # more than the closest distance drawn when that is further
        closest = [
            m.get(key, 0.0) for m in (summary.min_separation_m, summary.min_planned_separation_m)
        ]
        top.set_ylim(0, max(d_min * 6, 1.3 * max(closest), 1.0))
        bottom.set_ylim(0, max(v_min * 6, 1.0))
        top.set_ylabel("3D distance [m]" if mode == "sphere" else "horizontal distance [m]")
        bottom.set_ylabel("vertical distance [m]")
        bottom.set_xlabel("time from scenario start [s]")
        if verdicts:
            summary.separation_verdict[key] = verdicts[0]
        top.set_title(f"{a} - {b}" + (f": {verdicts[0]}" if verdicts else ""), fontsize=9)
        top.legend(fontsize=6, loc="upper right")
        bottom.legend(fontsize=6, loc="upper right")
        top.grid(alpha=0.3)
        bottom.grid(alpha=0.3)
    return _save(
        fig,
        out_dir / f"{stem}_separation.png",
        f"{report.get('scenario', '')}: separation over time ({mode})",
    )


def _shade_verdict(top: Any, bottom: Any, ps: PairSeries, h_min_m: float, v_min_m: float) -> str:
    """Shade where the flown pair was horizontally closer than its minimum: green where the
    vertical distance kept the minimum (separated), red where both were below (a loss).
    Returns the verdict for the title, naming both axes against their minima."""
    close = [h < h_min_m for h in ps.horizontal_m]
    lost = [c and v < v_min_m for c, v in zip(close, ps.vertical_m, strict=True)]
    kept = [c and not lo for c, lo in zip(close, lost, strict=True)]
    for where, colour, label in (
        (kept, "green", "horizontal below minimum, vertical kept"),
        (lost, "red", "loss of separation (both below)"),
    ):
        if not any(where):
            continue
        for ax in (top, bottom):
            ax.fill_between(
                ps.t_s,
                0,
                1,
                where=where,
                color=colour,
                alpha=0.15,
                transform=ax.get_xaxis_transform(),
                label=label if ax is top else "_nolegend_",
            )
    if any(lost):
        return f"LOSS of separation (horizontal < {h_min_m:g} m and vertical < {v_min_m:g} m)"
    if any(close):
        v_at = min(v for c, v in zip(close, ps.vertical_m, strict=True) if c)
        return (
            f"separated: horizontal below {h_min_m:g} m only while vertical >= "
            f"{v_min_m:g} m (least {v_at:.1f} m)"
        )
    return f"separated: horizontal never below {h_min_m:g} m"


def plot_geofences(
    report: dict[str, Any], out_dir: Path, stem: str, summary: PlotSummary
) -> Path | None:
    """``<stem>_geofence.png``: close-up of the geofences and distance to their edges."""
    import matplotlib.pyplot as plt

    fences = report.get("geofences", [])
    if not fences:
        return None
    local = Local(report["origin"])
    fig, (ax, ax_d) = plt.subplots(1, 2, figsize=(14, 6))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    xs_all: list[float] = []
    ys_all: list[float] = []
    for g in fences:
        if g.get("shape") == "cylinder":
            cx, cy = local.xy(g["center"]["lat_deg"], g["center"]["lon_deg"])
            xs, ys = _circle(cx, cy, float(g["radius_m"]))
        else:
            pts = [local.xy(v["lat_deg"], v["lon_deg"]) for v in g["vertices"]]
            pts.append(pts[0])
            xs, ys = [p[0] for p in pts], [p[1] for p in pts]
        ax.fill(xs, ys, color="red", alpha=0.25)
        ax.plot(xs, ys, color="red", lw=1)
        ax.annotate(f"{g['id']} ({g.get('reason', '')})", (xs[0], ys[0]), color="red", fontsize=7)
        xs_all += xs
        ys_all += ys
    margin = 150.0
    box = (min(xs_all) - margin, max(xs_all) + margin, min(ys_all) - margin, max(ys_all) + margin)
    for i, op in enumerate(report.get("operations", [])):
        colour = colours[i % len(colours)]
        for j, plan in enumerate(op.get("plans", [])):
            pts = [local.xy(w[0], w[1]) for w in plan["waypoints"]]
            ax.plot(
                [p[0] for p in pts],
                [p[1] for p in pts],
                "-" if j == 0 else "--",
                color=colour,
                lw=1.5 if j == 0 else 1.0,
                marker="." if j else None,
                label=f"{op['id']} plan v{plan['version']}",
            )
        track = report.get("tracks", {}).get(op["id"], [])
        if track:
            pts = [local.xy(s[1], s[2]) for s in track]
            ax.plot(
                [p[0] for p in pts],
                [p[1] for p in pts],
                ":",
                color=colour,
                lw=2,
                label=f"{op['id']} flown",
            )
    ax.set_xlim(box[0], box[1])
    ax.set_ylim(box[2], box[3])
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_title("geofences: close-up top view")
    ax.legend(fontsize=6, loc="best")
    for (uas, gid), (ts, ds) in fence_distances(report).items():
        k = min(range(len(ds)), key=ds.__getitem__)
        ax_d.plot(ts, ds, lw=1.3, label=f"{uas} to {gid} (closest {ds[k]:.1f} m)")
        summary.min_geofence_distance_m[f"{uas}|{gid}"] = ds[k]
        ax_d.plot([ts[k]], [ds[k]], "o", color="black")
    ax_d.axhline(0.0, color="red", lw=1, label="geofence edge")
    ax_d.set_xlabel("time from scenario start [s]")
    ax_d.set_ylabel("horizontal distance to the edge [m] (< 0 inside)")
    ax_d.set_title("distance to each geofence while it is active")
    ax_d.legend(fontsize=6, loc="best")
    ax_d.grid(alpha=0.3)
    return _save(fig, out_dir / f"{stem}_geofence.png", f"{report.get('scenario', '')}: geofences")


def export_all(report: dict[str, Any], out_dir: Path, *, stem: str = "run") -> PlotSummary:
    """Figures plus ``<stem>.geojson`` and ``<stem>.kml``; without matplotlib, the two
    exports only (logged)."""
    try:
        summary = plot_report(report, out_dir, stem=stem)
    except PlotsUnavailableError as exc:
        _log.warning("no figures: %s", exc)
        out_dir.mkdir(parents=True, exist_ok=True)
        summary = PlotSummary()
    gj = out_dir / f"{stem}.geojson"
    gj.write_text(json.dumps(to_geojson(report), indent=1))
    kml = out_dir / f"{stem}.kml"
    kml.write_text(to_kml(report))
    summary.files += [gj, kml]
    return summary


def _save(fig: Any, path: Path, title: str) -> Path:
    """Title, lay out, write ``path`` and free the figure."""
    import matplotlib.pyplot as plt

    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
