"""Fixtures that start real PX4 / ArduPilot SITL processes (see autopilots.py).

A test asks for ``px4`` or ``ardupilot`` and calls it to start instances; when the test ends,
passed or failed, every pilot link (pilot.py) it left open is closed and every process it
started is stopped (and its logs printed on failure). Without ``../shared``
the tests skip with the reason; on CI (``CI`` set) with ``../shared`` present, a missing
private network namespace is a failure, not a skip, so the real-autopilot tests cannot
silently stop running.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from tests.autopilot.autopilots import (
    SitlProcess,
    launcher,
    private_netns,
    start_ardupilot,
    start_px4,
    unavailable_reason,
)


def _require(kind: str) -> None:
    reason = unavailable_reason(kind)
    if not reason:
        return
    if os.environ.get("CI") and not private_netns() and "absent" not in reason:
        pytest.fail(reason)
    pytest.skip(reason)


def _factory(
    kind: str, start: Callable[..., SitlProcess], tmp_path: Path, request: pytest.FixtureRequest
) -> Iterator[Callable[..., SitlProcess]]:
    _require(kind)

    def failed() -> bool:
        rep = getattr(request.node, "rep_call", None)
        return rep is not None and bool(rep.failed)

    yield from launcher(kind, start, tmp_path, failed)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Iterator[None]:
    outcome = yield
    rep = outcome.get_result()
    if rep.when == "call":
        item.rep_call = rep  # type: ignore[attr-defined]


@pytest.fixture
def px4(tmp_path: Path, request: pytest.FixtureRequest) -> Iterator[Callable[..., SitlProcess]]:
    """``px4(instance=0, airframe="quad", home=(lat, lon), speed=5.0)`` starts a real PX4."""
    yield from _factory("px4", start_px4, tmp_path, request)


@pytest.fixture
def ardupilot(
    tmp_path: Path, request: pytest.FixtureRequest
) -> Iterator[Callable[..., SitlProcess]]:
    """``ardupilot(instance=0, vehicle="copter", speed=5.0)`` starts a real ArduPilot."""
    yield from _factory("ardupilot", start_ardupilot, tmp_path, request)
