"""Use case 2 on external autopilots (``run --external``): the scenario's GNSS jamming reaches
the USM as the RPA's report (PX4 SIH's GNSS takes no jamming), and
``config/scenarios/use_case_2_px4.toml`` is use case 2 moved to PX4 SIH's origin and shifted
for take-off, nothing else."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from gcs_utm.app import vehicle_specs
from gcs_utm.app.runner import played_hazards
from gcs_utm.model import ThreatKind
from gcs_utm.scenario import load_any

SCENARIOS = Path(__file__).resolve().parents[2] / "config" / "scenarios"
SHIFT_S = 110.0  # use_case_2_px4.toml's time shift for boot, upload, arming and climb
PX4_SIH_ORIGIN = (45.4671160, -73.7578370, 32.34)


def test_an_external_run_reports_the_scenarios_jamming_to_the_usm() -> None:
    scenario = load_any(SCENARIOS / "use_case_2_px4.toml")
    (jam,) = played_hazards(scenario, external=True)
    assert (jam.kind, jam.operation_id, jam.source) == (
        ThreatKind.JAMMING_ATTACK,
        "UAS1",
        "scenario",
    )
    assert jam.t_s == scenario.t0_s + 122.0
    assert "jamming" in jam.message
    # the built-in vehicles suffer it in their simulated receiver instead: not reported twice
    assert played_hazards(scenario, external=False) == []
    (uas1,) = [s for s in vehicle_specs(scenario, lead_s=0.0, gcs_port=14550) if s.sys_id == 1]
    assert [f.kind.name for f in uas1.faults] == ["GNSS_JAMMING"]


def _toml(name: str) -> dict[str, Any]:
    with (SCENARIOS / name).open("rb") as f:
        return tomllib.load(f)


def test_use_case_2_px4_is_use_case_2_at_px4s_origin_shifted_for_take_off() -> None:
    uc2, px4 = _toml("use_case_2.toml"), _toml("use_case_2_px4.toml")
    a = px4["airspace"]
    assert (
        a["origin_lat_deg"],
        a["origin_lon_deg"],
        a["ground_elevation_amsl_m"],
    ) == PX4_SIH_ORIGIN
    assert px4["scenario"]["duration_s"] == uc2["scenario"]["duration_s"] + SHIFT_S
    assert px4["landing_sites"] == uc2["landing_sites"]
    for op, op_px4 in zip(uc2["operations"], px4["operations"], strict=True):
        shifted = {**op, "waypoints": [
            {**w, "t_s": w["t_s"] + SHIFT_S} if "t_s" in w else w for w in op["waypoints"]
        ]}  # fmt: skip
        if "start_s" in op:
            shifted["start_s"] = op["start_s"] + SHIFT_S
        assert op_px4 == shifted
    ((event,), (event_px4,)) = (uc2["events"], px4["events"])
    assert event_px4 == {**event, "at_s": event["at_s"] + SHIFT_S}
