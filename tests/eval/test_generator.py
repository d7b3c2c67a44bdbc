"""The seeded encounter generator: reproducible, covers every kind, vehicle kind and size it
promises, writes scenarios the loader accepts, and builds what each kind says (checked here on
the filed plans with a plain closest-approach computation)."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import pytest

from gcs_utm.eval.generator import (
    KINDS,
    PROFILES,
    Encounter,
    encounter,
    generate,
    write_encounters,
)
from gcs_utm.flyable import leg_speeds_mps, leg_vertical_rates_mps, plan_problem
from gcs_utm.model import VehicleKind
from gcs_utm.scenario import Scenario, load_any


def _local(s: Scenario, lat: float, lon: float) -> tuple[float, float]:
    e, n = s.frame.point_to_local(lat, lon)
    return float(e), float(n)


def _position(s: Scenario, op_index: int, t_s: float) -> tuple[float, float, float] | None:
    wps = s.operations[op_index].plan.waypoints
    if not wps[0].t_s <= t_s <= wps[-1].t_s:
        return None
    for a, b in itertools.pairwise(wps):
        if a.t_s <= t_s <= b.t_s:
            u = 0.0 if b.t_s == a.t_s else (t_s - a.t_s) / (b.t_s - a.t_s)
            ea, na = _local(s, a.lat_deg, a.lon_deg)
            eb, nb = _local(s, b.lat_deg, b.lon_deg)
            return (
                ea + u * (eb - ea),
                na + u * (nb - na),
                a.alt_amsl_m + u * (b.alt_amsl_m - a.alt_amsl_m),
            )
    return None


def _closest(s: Scenario, i: int, j: int) -> tuple[float, float]:
    """(min horizontal m while within 15 m vertically, min vertical m while within 50 m
    horizontally) of the filed plans, sampled every 0.1 s."""
    best_h = best_v = math.inf
    for k in range(int(s.duration_s * 10)):
        t = s.t0_s + k / 10.0
        a, b = _position(s, i, t), _position(s, j, t)
        if a is None or b is None:
            continue
        dh, dv = math.hypot(a[0] - b[0], a[1] - b[1]), abs(a[2] - b[2])
        if dv < 15.0:
            best_h = min(best_h, dh)
        if dh < 50.0:
            best_v = min(best_v, dv)
    return best_h, best_v


def test_the_same_seed_gives_the_same_files_and_another_seed_others() -> None:
    assert [e.toml for e in generate(10, seed=5)] == [e.toml for e in generate(10, seed=5)]
    assert [e.toml for e in generate(10, seed=5)] != [e.toml for e in generate(10, seed=6)]


def test_a_set_covers_every_kind_size_vehicle_kind_and_geofences(tmp_path: Path) -> None:
    encounters = generate(40, seed=1)
    assert {e.kind for e in encounters} == set(KINDS)
    assert {e.n_uas for e in encounters} == {2, 3, 4, 5, 6}
    assert sum(e.geofence for e in encounters) >= 8
    assert sum(e.fixed_wings > 0 for e in encounters) >= 10
    assert sum(e.fixed_wings < e.n_uas for e in encounters) >= 30  # multirotors in most
    assert len({e.origin for e in encounters}) == 2
    for path in write_encounters(tmp_path, 40, seed=1):
        s = load_any(path, t0_s=1000.0)
        assert 2 <= len(s.operations) <= 6
        kinds = {op.vehicle_kind for op in s.operations}
        assert kinds <= {VehicleKind.MULTIROTOR, VehicleKind.FIXED_WING}


@pytest.mark.parametrize("index", range(15))
def test_each_encounter_is_what_its_kind_says(tmp_path: Path, index: int) -> None:
    (enc,) = [e for e in generate(15, seed=3) if e.name.endswith(f"_{index:04d}_" + e.kind)]
    path = tmp_path / f"{enc.name}.toml"
    path.write_text(enc.toml)
    s = load_any(path, t0_s=0.0)
    ov = [op.operational_volume_m for op in s.operations]
    min_h = max(50.0, ov[0] + ov[1])
    h, v = _closest(s, 0, 1)
    if enc.kind == "near_threshold":
        assert abs(h - min_h) <= 6.5, (h, min_h)
    else:
        assert h < min_h and v < 15.0, (enc.kind, h, v)
    if enc.kind == "vertical":
        alts = [w.alt_amsl_m for w in s.operations[1].plan.waypoints]
        assert max(alts) - min(alts) >= 30.0
    for op in s.operations:  # no plan asks for more climb than the vehicle has
        wps = op.plan.waypoints
        for a, b in itertools.pairwise(wps):
            rate = abs(b.alt_amsl_m - a.alt_amsl_m) / (b.t_s - a.t_s)
            assert rate <= op.max_climb_rate_mps, (op.id, rate)
    for g in s.geofences:  # a geofence never lies on a filed path
        assert g.center is not None and g.radius_m is not None
        ce, cn = _local(s, g.center.lat_deg, g.center.lon_deg)
        for k in range(len(s.operations)):
            for t in range(int(s.duration_s)):
                p = _position(s, k, float(t))
                if p is not None:
                    assert math.hypot(p[0] - ce, p[1] - cn) > g.radius_m + 30.0


# ---- profiles ---------------------------------------------------------------------------


def _load(tmp_path: Path, enc: Encounter) -> Scenario:
    path = tmp_path / f"{enc.name}.toml"
    path.write_text(enc.toml)
    return load_any(path, t0_s=0.0)


def test_profiles_are_deterministic_and_all_cycles_through_them() -> None:
    every = generate(2 * len(PROFILES), seed=4, profile="all")
    assert [e.profile for e in every] == [*PROFILES, *PROFILES]
    assert [e.toml for e in every] == [e.toml for e in generate(len(every), 4, "all")]
    assert [e.toml for e in generate(3, 4, "late")] != [e.toml for e in generate(3, 5, "late")]
    assert generate(5, seed=7, profile="classic") == generate(5, seed=7)  # today's sets
    with pytest.raises(ValueError, match="unknown profile 'nope'"):
        generate(1, seed=1, profile="nope")


def _loss_start_s(s: Scenario, i: int, j: int, min_h: float, min_v: float) -> float | None:
    for k in range(int(s.duration_s * 10)):
        a, b = _position(s, i, k / 10.0), _position(s, j, k / 10.0)
        if a and b and math.hypot(a[0] - b[0], a[1] - b[1]) < min_h and abs(a[2] - b[2]) < min_v:
            return k / 10.0
    return None


@pytest.mark.parametrize("index", range(10))
def test_late_uas_appears_3_to_15_s_before_the_loss(tmp_path: Path, index: int) -> None:
    enc = generate(10, seed=2, profile="late")[index]
    s = _load(tmp_path, enc)
    ov = [op.operational_volume_m for op in s.operations]
    start = _loss_start_s(s, 0, 1, max(50.0, ov[0] + ov[1]), max(15.0, ov[0] + ov[1]))
    appears = s.operations[1].plan.waypoints[0].t_s
    if start is not None and start > appears:  # near-threshold kinds may miss the minima
        assert 3.0 - 0.2 <= start - appears <= 15.0 + 0.2, (start, appears)


def test_lagging_vehicles_start_later_than_their_plans(tmp_path: Path) -> None:
    for enc in generate(10, seed=2, profile="lag"):
        s = _load(tmp_path, enc)
        delays = {v.operation_id: v.start_delay_s for v in s.vehicles}
        assert 2.0 <= delays["UAS2"] <= 15.0, enc.name


def test_endpoint_plans_end_at_the_conflict_point(tmp_path: Path) -> None:
    for enc in generate(10, seed=2, profile="endpoint"):
        s = _load(tmp_path, enc)
        end2 = s.operations[1].plan.waypoints[-1]
        end1 = s.operations[0].plan.waypoints[-1]
        assert end2.t_s < end1.t_s  # UAS1 passes after UAS2 has stopped there


def test_fences_touch_cross_or_enclose_filed_paths(tmp_path: Path) -> None:
    fenced = 0
    for enc in generate(12, seed=2, profile="fence"):
        s = _load(tmp_path, enc)
        for g in s.geofences:
            assert g.center is not None and g.radius_m is not None
            ce, cn = _local(s, g.center.lat_deg, g.center.lon_deg)
            nearest = min(
                math.hypot(p[0] - ce, p[1] - cn)
                for k in range(len(s.operations))
                for t in range(int(s.duration_s) * 2)
                if (p := _position(s, k, t / 2.0)) is not None
            )
            assert nearest <= g.radius_m + 3.5, (enc.name, nearest, g.radius_m)
            fenced += 1
    assert fenced >= 10


def test_vertical_plans_are_centimetres_from_the_vertical_minimum(tmp_path: Path) -> None:
    for enc in generate(10, seed=2, profile="vertical"):
        s = _load(tmp_path, enc)
        ov = [op.operational_volume_m for op in s.operations]
        dv = abs(
            s.operations[0].plan.waypoints[0].alt_amsl_m
            - s.operations[1].plan.waypoints[0].alt_amsl_m
        )
        assert 0.009 <= abs(dv - max(15.0, ov[0] + ov[1])) <= 0.1005, (enc.name, dv)


def test_merge_and_mixed_profiles(tmp_path: Path) -> None:
    merges = generate(10, seed=2, profile="merge")
    assert all(e.n_uas >= 3 for e in merges)
    for enc in generate(10, seed=2, profile="mixed"):
        kinds = [op.vehicle_kind for op in _load(tmp_path, enc).operations[:2]]
        assert set(kinds) == {VehicleKind.MULTIROTOR, VehicleKind.FIXED_WING}, enc.name


@pytest.mark.parametrize("index", [153, 187, *range(0, 40, 3)])
def test_no_loss_begins_within_3_s_of_a_uas_appearing(tmp_path: Path, index: int) -> None:
    """Seed 1's encounters 153 (late: UAS2 appeared 51 m from UAS5, 0.27 s before their
    loss) and 187 (endpoint: UAS1 appeared 50 m ahead of the faster UAS2 on its track, 0.23 s
    before) measured the generator, not the UTM: no command acts that fast. Every pair of
    filed plans stays out of its effective minima for 3 s after the later one appears."""
    s = _load(tmp_path, encounter(index, seed=1, profile="all"))
    ops = s.operations
    for i, j in itertools.combinations(range(len(ops)), 2):
        v = ops[i].operational_volume_m + ops[j].operational_volume_m
        start = _loss_start_s(s, i, j, max(50.0, v), max(15.0, v))
        appears = max(ops[i].plan.waypoints[0].t_s, ops[j].plan.waypoints[0].t_s)
        assert start is None or start >= appears + 3.0 - 0.2, (ops[i].id, ops[j].id, start)


# ---- flyable plans ------------------------------------------------------------------------


def _heading_changes_deg(s: Scenario, op_index: int) -> list[float]:
    wps = s.operations[op_index].plan.waypoints
    pts = [_local(s, w.lat_deg, w.lon_deg) for w in wps]
    headings = [
        math.degrees(math.atan2(b[0] - a[0], b[1] - a[1]))
        for a, b in itertools.pairwise(pts)
        if math.dist(a, b) > 1.0
    ]
    return [abs((h2 - h1 + 180.0) % 360.0 - 180.0) for h1, h2 in itertools.pairwise(headings)]


@pytest.mark.parametrize("profile", PROFILES)
def test_every_generated_plan_is_one_its_vehicle_flies(tmp_path: Path, profile: str) -> None:
    """Within the vehicle's envelope (the UTM's and the simulated vehicle's): climbs and
    descents within its rates (a fixed wing descends at 3 m/s, under its 5 m/s climb),
    speeds within its range, and (a fixed wing) no turn on the filed path. Loading files the
    plans: a plan the filing rule refuses fails here."""
    for enc in generate(10, seed=6, profile=profile):
        s = _load(tmp_path, enc)
        for k, op in enumerate(s.operations):
            assert plan_problem(op) is None, (enc.name, plan_problem(op))
            env = op.performance()
            for speed in leg_speeds_mps(op):
                assert env.min_speed_mps - 0.05 <= speed <= env.max_speed_mps, (enc.name, op.id)
            for rate in leg_vertical_rates_mps(op):
                limit = env.climb_rate_mps if rate > 0.0 else env.descent_rate_mps
                assert abs(rate) <= 0.8 * limit + 0.01, (enc.name, op.id, rate)
            if op.vehicle_kind is VehicleKind.FIXED_WING:
                assert all(turn < 1.0 for turn in _heading_changes_deg(s, k)), (enc.name, op.id)


def test_a_descending_fixed_wing_is_filed_at_its_descent_rate(tmp_path: Path) -> None:
    """Seed 6's encounter 63 (mixed, vertical): UAS2, a fixed wing (climb 5 m/s, descent
    3 m/s), descends 45 m through UAS1's level; it was filed at 4.0 m/s (80 % of its climb
    rate), reached its waypoint 11 m high and circled down across a geofence."""
    enc = encounter(63, seed=6, profile="all")
    assert enc.name == "enc_6_0063_mixed_vertical"
    s = _load(tmp_path, enc)
    plane = s.operations[1]
    assert plane.vehicle_kind is VehicleKind.FIXED_WING
    rates = leg_vertical_rates_mps(plane)
    assert min(rates) == pytest.approx(-0.8 * plane.performance().descent_rate_mps, abs=0.01)
    assert plane.performance().descent_rate_mps == 3.0
