"""GeoJSON and KML exports of a run report (plans, alternatives, tracks, geofences), for
QGIS / Google Earth. Input is the JSON report of ``gcs-utm run``; coordinates WGS84."""

from __future__ import annotations

import math
from typing import Any
from xml.sax.saxutils import escape

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
