"""Pictures of a run, like the paper's Figures 15, 16, 18 and 19: top view and 3D perspective of
the flight plans with their operational volumes, the tracks flown, geofences, the alternatives
TD generated and the one selected, and conflict points. Also GeoJSON and KML exports of the
same data for QGIS / Google Earth.

Input is the JSON report of ``gcs-utm run`` (see the README for its fields). Figures use
matplotlib's non-interactive Agg backend. Each function returns what it drew (counts), so
tests check the data plotted, not only that a file exists.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from xml.sax.saxutils import escape


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


class _Local:
    """Equirectangular metres around the report origin: exact enough for figures at the
    scale of one operation area (a few km)."""

    def __init__(self, origin: dict[str, Any]) -> None:
        self.lat0 = float(origin["lat_deg"])
        self.lon0 = float(origin["lon_deg"])
        self.k = math.cos(math.radians(self.lat0))

    def xy(self, lat: float, lon: float) -> tuple[float, float]:
        return ((lon - self.lon0) * 111_320.0 * self.k, (lat - self.lat0) * 110_540.0)


def _circle(cx: float, cy: float, r: float, n: int = 48) -> tuple[list[float], list[float]]:
    xs = [cx + r * math.cos(2 * math.pi * i / n) for i in range(n + 1)]
    ys = [cy + r * math.sin(2 * math.pi * i / n) for i in range(n + 1)]
    return xs, ys


def plot_report(report: dict[str, Any], out_dir: Path, *, stem: str = "run") -> PlotSummary:
    """Write ``<stem>_top.png`` and ``<stem>_3d.png`` into ``out_dir``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    local = _Local(report["origin"])
    summary = PlotSummary()
    fig, ax = plt.subplots(figsize=(9, 8))
    fig3 = plt.figure(figsize=(9, 8))
    ax3 = fig3.add_subplot(projection="3d")
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]

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
            ax3.plot(xs, ys, zs, style, color=colour, lw=1.5)
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
            )
            summary.tracks += 1

    for rec in report.get("recommendations", []):
        for alt in rec.get("alternatives", []):
            wps = alt.get("waypoints") or []
            if len(wps) < 2:
                continue
            pts = [local.xy(w[0], w[1]) for w in wps]
            chosen = bool(alt.get("selected"))
            ax.plot(
                [p[0] for p in pts],
                [p[1] for p in pts],
                "-" if chosen else "-.",
                color="black" if chosen else "grey",
                lw=1.2 if chosen else 0.6,
                alpha=1.0 if chosen else 0.6,
            )
            ax3.plot(
                [p[0] for p in pts],
                [p[1] for p in pts],
                [w[2] for w in wps],
                color="black" if chosen else "grey",
                lw=0.8,
            )
            summary.alternatives += 1

    for t in report.get("threats", []):
        pos = t.get("position")
        if pos:
            x, y = local.xy(pos["lat_deg"], pos["lon_deg"])
            ax.plot([x], [y], "x", color="red", ms=10, mew=2)
            ax3.scatter([x], [y], [pos.get("alt_amsl_m", 0.0)], marker="x", color="red")
            summary.conflict_points += 1

    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(f"{report.get('scenario', '')}: top view")
    if summary.plans:
        ax.legend(fontsize=7, loc="best")
    ax3.set_xlabel("east [m]")
    ax3.set_ylabel("north [m]")
    ax3.set_zlabel("altitude AMSL [m]")
    ax3.set_title(f"{report.get('scenario', '')}: 3D")
    top = out_dir / f"{stem}_top.png"
    persp = out_dir / f"{stem}_3d.png"
    fig.savefig(top, dpi=110)
    fig3.savefig(persp, dpi=110)
    plt.close(fig)
    plt.close(fig3)
    summary.files += [top, persp]
    return summary


def _fill_volume(ax: Any, xs: list[float], ys: list[float], radius_m: float, colour: str) -> None:
    from shapely.geometry import LineString, Point

    geom = LineString(list(zip(xs, ys, strict=True))) if len(xs) > 1 else Point(xs[0], ys[0])
    area = geom.buffer(radius_m)
    polys = list(getattr(area, "geoms", [area]))
    for poly in polys:
        bx, by = poly.exterior.xy
        ax.fill(list(bx), list(by), color=colour, alpha=0.15, lw=0)


# ---- GeoJSON and KML --------------------------------------------------------------------------


def _geofence_ring(g: dict[str, Any]) -> list[tuple[float, float]]:
    """(lon, lat) ring of a geofence; cylinders as 48-gons."""
    if g.get("shape") == "cylinder":
        lat0, lon0 = float(g["center"]["lat_deg"]), float(g["center"]["lon_deg"])
        r = float(g["radius_m"])
        k = math.cos(math.radians(lat0))
        ring = [
            (lon0 + r * math.cos(a) / (111_320.0 * k), lat0 + r * math.sin(a) / 110_540.0)
            for a in (2 * math.pi * i / 48 for i in range(48))
        ]
    else:
        ring = [(float(v["lon_deg"]), float(v["lat_deg"])) for v in g["vertices"]]
    ring.append(ring[0])
    return ring


def to_geojson(report: dict[str, Any]) -> dict[str, Any]:
    feats: list[dict[str, Any]] = []
    for op in report.get("operations", []):
        for plan in op.get("plans", []):
            feats.append(
                {
                    "type": "Feature",
                    "properties": {
                        "kind": "plan",
                        "operation": op["id"],
                        "version": plan["version"],
                        "reason": plan.get("reason", ""),
                    },
                    "geometry": {
                        "type": "LineString",
                        "coordinates": [[w[1], w[0], w[2]] for w in plan["waypoints"]],
                    },
                }
            )
        track = report.get("tracks", {}).get(op["id"], [])
        if len(track) >= 2:
            feats.append(
                {
                    "type": "Feature",
                    "properties": {"kind": "track", "operation": op["id"]},
                    "geometry": {
                        "type": "LineString",
                        "coordinates": [[p[2], p[1], p[3]] for p in track],
                    },
                }
            )
    for g in report.get("geofences", []):
        feats.append(
            {
                "type": "Feature",
                "properties": {
                    "kind": "geofence",
                    "id": g["id"],
                    "reason": g.get("reason", ""),
                    "min_alt_amsl_m": g.get("min_alt_amsl_m"),
                    "max_alt_amsl_m": g.get("max_alt_amsl_m"),
                },
                "geometry": {"type": "Polygon", "coordinates": [_geofence_ring(g)]},
            }
        )
    for rec in report.get("recommendations", []):
        for alt in rec.get("alternatives", []):
            wps = alt.get("waypoints") or []
            if len(wps) >= 2:
                feats.append(
                    {
                        "type": "Feature",
                        "properties": {
                            "kind": "alternative",
                            "operation": rec.get("uas"),
                            "maneuver": alt.get("maneuver"),
                            "selected": bool(alt.get("selected")),
                            "cost": alt.get("cost"),
                            "risk": alt.get("risk"),
                        },
                        "geometry": {
                            "type": "LineString",
                            "coordinates": [[w[1], w[0], w[2]] for w in wps],
                        },
                    }
                )
    return {"type": "FeatureCollection", "features": feats}


def to_kml(report: dict[str, Any]) -> str:
    """KML with absolute (AMSL) altitudes, one Placemark per GeoJSON feature."""
    out = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        '<kml xmlns="http://www.opengis.net/kml/2.2"><Document>',
        f"<name>{escape(str(report.get('scenario', 'gcs-utm')))}</name>",
    ]
    for feat in to_geojson(report)["features"]:
        props = feat["properties"]
        name = escape(f"{props['kind']} {props.get('operation') or props.get('id', '')}")
        geom = feat["geometry"]
        if geom["type"] == "LineString":
            coords = " ".join(f"{c[0]},{c[1]},{c[2]}" for c in geom["coordinates"])
            body = (
                f"<LineString><altitudeMode>absolute</altitudeMode>"
                f"<coordinates>{coords}</coordinates></LineString>"
            )
        else:
            alt = props.get("max_alt_amsl_m") or 0.0
            coords = " ".join(f"{c[0]},{c[1]},{alt}" for c in geom["coordinates"][0])
            body = (
                "<Polygon><extrude>1</extrude><altitudeMode>absolute</altitudeMode>"
                f"<outerBoundaryIs><LinearRing><coordinates>{coords}</coordinates>"
                "</LinearRing></outerBoundaryIs></Polygon>"
            )
        out.append(f"<Placemark><name>{name}</name>{body}</Placemark>")
    out.append("</Document></kml>")
    return "\n".join(out)


def export_all(report: dict[str, Any], out_dir: Path, *, stem: str = "run") -> PlotSummary:
    """Figures plus ``<stem>.geojson`` and ``<stem>.kml``."""
    summary = plot_report(report, out_dir, stem=stem)
    gj = out_dir / f"{stem}.geojson"
    gj.write_text(json.dumps(to_geojson(report), indent=1))
    kml = out_dir / f"{stem}.kml"
    kml.write_text(to_kml(report))
    summary.files += [gj, kml]
    return summary
