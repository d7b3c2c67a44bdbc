"""``run --fly`` is only valid with ``--external`` (the built-in vehicles fly the plans)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from gcs_utm.app import RunOptions


def test_fly_without_external_is_refused() -> None:
    with pytest.raises(ValueError, match="fly makes external autopilots fly"):
        RunOptions(fly=True)
    assert RunOptions(fly=True, external=True, speed=4.0).fly


def test_cli_fly_without_external_is_one_clear_error() -> None:
    run = subprocess.run(
        [sys.executable, "-m", "gcs_utm", "run", "config/scenarios/use_case_1.toml", "--fly",
         "--auto-accept", "--headless"],
        capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL, check=False,
    )  # fmt: skip
    assert run.returncode == 2
    assert "fly makes external autopilots fly the plans" in run.stderr
    assert "Traceback" not in run.stderr
