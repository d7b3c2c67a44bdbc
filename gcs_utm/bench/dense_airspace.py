"""The dense airspace of ``gcs-utm bench strategic``'s end-to-end profile, as a scenario file.

N operations, each ONE straight level leg between two random points of a 20 km x 20 km area
(local east/north metres from the origin, so the file has no rounding of its own), at a
random 20-150 m above ground and 10-20 m/s, starting within the first 5 minutes; operational
volume 10 m, default minima. At N = 10,000 every plan is in about four conflicts (about
40,000 in all): the density of a user's stress test, four times that of the core benchmark's
airspace. Deterministic for a seed: the same file for the old and the new code.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

AREA_M = 20_000.0
START_WINDOW_S = 300.0
ORIGIN = (37.41, -6.0, 0.0)  # lat_deg, lon_deg, ground AMSL m


def dense_scenario_toml(n: int, seed: int) -> str:
    """The scenario TOML of ``n`` operations (``D0`` ... ``D{n-1}``)."""
    rng = np.random.default_rng(seed)
    a = rng.uniform(-AREA_M / 2, AREA_M / 2, (n, 2))  # m
    b = rng.uniform(-AREA_M / 2, AREA_M / 2, (n, 2))
    alt = rng.uniform(20.0, 150.0, n)  # m AGL
    speed = rng.uniform(10.0, 20.0, n)  # m/s
    start = rng.uniform(0.0, START_WINDOW_S, n)  # s
    duration_s = START_WINDOW_S + AREA_M * np.sqrt(2.0) / 10.0
    lines = [
        "[scenario]",
        f'name = "dense_{n}"',
        f'description = "{n} straight legs over 20 x 20 km, starts within 5 min"',
        f"duration_s = {duration_s:.1f}",
        "",
        "[airspace]",
        f"origin_lat_deg = {ORIGIN[0]}",
        f"origin_lon_deg = {ORIGIN[1]}",
        f"ground_elevation_amsl_m = {ORIGIN[2]}",
    ]
    for i in range(n):
        lines += [
            "",
            "[[operations]]",
            f'id = "D{i}"',
            "priority = 1",
            f"cruise_speed_mps = {speed[i]:.3f}",
            "flight_geometry_m = 5.0",
            "operational_volume_m = 10.0",
            f"start_s = {start[i]:.3f}",
            "waypoints = [",
            f"  {{ east_m = {a[i, 0]:.2f}, north_m = {a[i, 1]:.2f}, alt_agl_m = {alt[i]:.2f} }},",
            f"  {{ east_m = {b[i, 0]:.2f}, north_m = {b[i, 1]:.2f}, alt_agl_m = {alt[i]:.2f} }},",
            "]",
        ]
    return "\n".join(lines) + "\n"


def write_dense_scenario(path: Path, n: int, seed: int) -> Path:
    path.write_text(dense_scenario_toml(n, seed), encoding="utf-8")
    return path
