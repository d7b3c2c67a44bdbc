"""The tests' PX4 streams on its GCS link what gcs-utm reads at the rate the tests compare, and
the rest at PX4's normal GCS rates (autopilots.px4_etc_dir; docs/autopilots.md, "PX4 SITL under
load"). Reads ../shared's start script only: no PX4 is started."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.autopilot.autopilots import PX4_DIR, px4_etc_dir


def test_gcs_link_keeps_positions_at_50_hz_and_drops_the_boosts(tmp_path: Path) -> None:
    if not (PX4_DIR / "etc").is_dir():
        pytest.skip(f"no real PX4 SITL: {PX4_DIR} is absent")
    original = (PX4_DIR / "etc" / "init.d-posix" / "px4-rc.mavlink").read_text().splitlines()
    etc = px4_etc_dir(tmp_path)
    lines = (etc / "init.d-posix" / "px4-rc.mavlink").read_text().splitlines()
    streams = [line for line in lines if line.strip().startswith("mavlink stream")]
    assert streams == ["mavlink stream -r 50 -s GLOBAL_POSITION_INT -u $udp_gcs_port_local"]
    starts = [line for line in original if line.strip().startswith("mavlink start")]
    assert starts and all(line in lines for line in starts)  # every link still starts
    assert len(lines) == len(original) - (sum("mavlink stream" in x for x in original) - 1)
    # the rest of etc/ as it is, made once per root
    assert (etc / "init.d-posix" / "rcS").read_bytes() == (
        PX4_DIR / "etc" / "init.d-posix" / "rcS"
    ).read_bytes()
    assert px4_etc_dir(tmp_path) == etc
