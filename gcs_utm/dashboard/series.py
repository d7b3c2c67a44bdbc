"""Distances between UAS pairs over time from a run report (seconds from scenario start,
metres): as flown (the UTM's tracks) and as the filed plans would have been flown with each
vehicle's start delay and no resolution; the report's separation rule. Pure data, no
matplotlib: the separation figure of :mod:`gcs_utm.dashboard.plot` draws these."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any


class Local:
    """Equirectangular metres around the report origin: exact enough for figures at the
    scale of one operation area (a few km)."""

    def __init__(self, origin: dict[str, Any]) -> None:
        self.lat0 = float(origin["lat_deg"])
        self.lon0 = float(origin["lon_deg"])
        self.k = math.cos(math.radians(self.lat0))

    def xy(self, lat: float, lon: float) -> tuple[float, float]:
        return ((lon - self.lon0) * 111_320.0 * self.k, (lat - self.lat0) * 110_540.0)


def interp_plan(wps: list[list[float]], t_s: float) -> tuple[float, float, float] | None:
    """(lat, lon, alt) of a report plan (``[lat, lon, alt, t]`` rows) at ``t_s``, or None
    outside its time span."""
    if not wps or t_s < wps[0][3] or t_s > wps[-1][3]:
        return None
    for a, b in itertools.pairwise(wps):
        if a[3] <= t_s <= b[3]:
            u = 0.0 if b[3] <= a[3] else (t_s - a[3]) / (b[3] - a[3])
            return (
                a[0] + u * (b[0] - a[0]),
                a[1] + u * (b[1] - a[1]),
                a[2] + u * (b[2] - a[2]),
            )
    return (wps[-1][0], wps[-1][1], wps[-1][2])


@dataclass(slots=True)
class PairSeries:
    """Distances between two UAS over time (seconds from scenario start, metres)."""

    a: str
    b: str
    t_s: list[float] = field(default_factory=list)
    horizontal_m: list[float] = field(default_factory=list)
    vertical_m: list[float] = field(default_factory=list)

    @property
    def distance_m(self) -> list[float]:
        return [math.hypot(h, v) for h, v in zip(self.horizontal_m, self.vertical_m, strict=True)]


def nearest_sample(samples: list[list[float]], t_s: float, tol_s: float) -> list[float] | None:
    import bisect

    i = bisect.bisect_left([s[0] for s in samples], t_s)
    best = None
    for j in (i - 1, i):
        if (
            0 <= j < len(samples)
            and abs(samples[j][0] - t_s) <= tol_s
            and (best is None or abs(samples[j][0] - t_s) < abs(best[0] - t_s))
        ):
            best = samples[j]
    return best


def flown_pairs(report: dict[str, Any], *, tol_s: float = 0.6) -> list[PairSeries]:
    """Pairwise distances from the report's tracks, each sample of A matched with B's sample
    nearest in time (within ``tol_s``), like the report's ``separation``."""
    local = Local(report["origin"])
    tracks = report.get("tracks", {})
    ids = [op["id"] for op in report.get("operations", []) if len(tracks.get(op["id"], [])) > 1]
    out = []
    for i, a in enumerate(ids):
        for b in ids[i + 1 :]:
            ps = PairSeries(a=a, b=b)
            for s in tracks[a]:
                m = nearest_sample(tracks[b], s[0], tol_s)
                if m is None:
                    continue
                xa, ya = local.xy(s[1], s[2])
                xb, yb = local.xy(m[1], m[2])
                ps.t_s.append(float(s[0]))
                ps.horizontal_m.append(math.hypot(xa - xb, ya - yb))
                ps.vertical_m.append(abs(float(s[3]) - float(m[3])))
            if ps.t_s:
                out.append(ps)
    return out


def planned_pairs(report: dict[str, Any], *, step_s: float = 0.2) -> list[PairSeries]:
    """Pairwise distances of the *filed* plans (version 1), each shifted by its vehicle's
    ``start_delay_s``: what would have been flown without any resolution."""
    local = Local(report["origin"])
    plans = {}
    for op in report.get("operations", []):
        if not op.get("plans"):
            continue
        delay = float(op.get("start_delay_s", 0.0) or 0.0)
        wps = [[w[0], w[1], w[2], w[3] + delay] for w in op["plans"][0]["waypoints"]]
        if len(wps) > 1:
            plans[op["id"]] = wps
    ids = list(plans)
    out = []
    for i, a in enumerate(ids):
        for b in ids[i + 1 :]:
            ps = PairSeries(a=a, b=b)
            t0 = max(plans[a][0][3], plans[b][0][3])
            t1 = min(plans[a][-1][3], plans[b][-1][3])
            n = int((t1 - t0) / step_s) + 1 if t1 >= t0 else 0
            for k in range(n):
                t = t0 + k * step_s
                pa, pb = interp_plan(plans[a], t), interp_plan(plans[b], t)
                if pa is None or pb is None:
                    continue
                xa, ya = local.xy(pa[0], pa[1])
                xb, yb = local.xy(pb[0], pb[1])
                ps.t_s.append(t)
                ps.horizontal_m.append(math.hypot(xa - xb, ya - yb))
                ps.vertical_m.append(abs(pa[2] - pb[2]))
            if ps.t_s:
                out.append(ps)
    return out


def minima(report: dict[str, Any]) -> tuple[str, float, float]:
    """(mode, horizontal-or-3D minimum, vertical minimum) of the run's separation rule."""
    sm = report.get("separation_minimum", {})
    mode = str(sm.get("mode", "cylinder"))
    if mode == "sphere":
        d = float(sm.get("safety_distance_m", 0.0) or 0.0)
        return mode, d, d
    return mode, float(sm.get("horizontal_m", 0.0) or 0.0), float(sm.get("vertical_m", 0.0) or 0.0)
