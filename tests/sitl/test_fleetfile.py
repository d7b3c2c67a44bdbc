"""The fleet TOML format and the one-vehicle command line."""

from __future__ import annotations

from pathlib import Path

import pytest

import sitl
from sitl.__main__ import build_parser, specs_from_args
from sitl.fleetfile import FleetFileError, load_fleet

FLEET = """
speed = 5.0
start_utc_s = 1700000000.0
[defaults]
gcs_port = 14999
[[vehicle]]
instance = 0
home = [47.3977, 8.5456, 488.0]
auto_start_at_s = 1.0
mission = [[47.3985, 8.5456, 510.0], [47.3985, 8.5470, 510.0, 6.0]]
faults = [{ kind = "gnss_jamming", at_s = 3.0, duration_s = 5.0, value = 2.0 }]
[[vehicle]]
instance = 1
kind = "fixed_wing"
autopilot = "ardupilot"
tcp_port = 0
"""


def test_load_fleet(tmp_path: Path) -> None:
    p = tmp_path / "fleet.toml"
    p.write_text(FLEET)
    specs, speed, start = load_fleet(p)
    assert speed == 5.0 and start == 1_700_000_000.0 and len(specs) == 2
    a, b = specs
    assert a.gcs_port == 14999 and a.home_alt_amsl_m == 488.0 and a.system_id == 1
    assert a.mission[1].speed_mps == 6.0
    assert a.faults == (
        sitl.FaultSpec(kind=sitl.FaultKind.GNSS_JAMMING, at_s=3.0, duration_s=5.0, value=2.0),
    )
    assert b.kind == "fixed_wing" and b.autopilot == "ardupilot"


def test_unknown_key_names_file_and_key(tmp_path: Path) -> None:
    p = tmp_path / "bad.toml"
    p.write_text("[[vehicle]]\ninstance = 0\nwingspan = 3\n")
    with pytest.raises(FleetFileError) as ei:
        load_fleet(p)
    assert "bad.toml" in str(ei.value) and ei.value.key == "vehicle[0].wingspan"


def test_instance_cli() -> None:
    args = build_parser().parse_args(
        [
            "--instance",
            "2",
            "--kind",
            "fixed_wing",
            "--gcs",
            "127.0.0.1:15000",
            "--home",
            "1,2,3",
            "--speed",
            "4",
        ]
    )
    specs, speed, _ = specs_from_args(args)
    assert speed == 4.0 and specs[0].system_id == 3 and specs[0].gcs_port == 15000
    assert specs[0].home_lat_deg == 1.0 and specs[0].kind == "fixed_wing"
