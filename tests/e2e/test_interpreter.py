"""The running service bounds how long its event loop can wait for the GIL (the store's writer
thread holds it while it encodes tracks): ``configure_interpreter`` lowers the switch
interval, never raises it."""

from __future__ import annotations

import sys
from collections.abc import Iterator

import pytest

from gcs_utm.app import GIL_SWITCH_INTERVAL_S, configure_interpreter


@pytest.fixture
def restore_switch_interval() -> Iterator[None]:
    before = sys.getswitchinterval()
    yield
    sys.setswitchinterval(before)


@pytest.mark.usefixtures("restore_switch_interval")
def test_the_default_switch_interval_is_lowered() -> None:
    sys.setswitchinterval(0.005)  # Python's default
    configure_interpreter()
    assert sys.getswitchinterval() == pytest.approx(GIL_SWITCH_INTERVAL_S)


@pytest.mark.usefixtures("restore_switch_interval")
def test_a_lower_switch_interval_set_by_the_user_is_kept() -> None:
    sys.setswitchinterval(0.0001)
    configure_interpreter()
    assert sys.getswitchinterval() == pytest.approx(0.0001)


@pytest.mark.usefixtures("restore_switch_interval")
def test_building_the_service_changes_nothing_process_wide() -> None:
    """The switch interval is the entry point's choice (the CLI calls configure_interpreter):
    building a runtime, as a test or an embedding program does, leaves it alone."""
    from gcs_utm.app import Persistence, build_runtime
    from gcs_utm.clock import ManualClock
    from gcs_utm.geo import LocalFrame
    from gcs_utm.settings import Settings

    class NoStore(Persistence):
        def __init__(self) -> None:
            pass

        @property
        def epoch(self) -> int:
            return 1

    sys.setswitchinterval(0.005)
    build_runtime(Settings(), ManualClock(0.0), LocalFrame(40.0, -3.0, 600.0), NoStore())
    assert sys.getswitchinterval() == pytest.approx(0.005)
