"""Test-wide settings. On CI (``CI`` set) hypothesis runs derandomized: the same examples on
every run, so a red CI is reproducible; local runs keep exploring new examples. No example
has a time limit (hypothesis' default is 200 ms): speed is checked by benchmarks, and a
loaded machine made a trivial example fail on time.

``tests/check.sh`` runs the tests in parallel processes (pytest-xdist, ``--dist loadgroup``,
see docs/testing.md); the collection hook below orders and groups them for that."""

from __future__ import annotations

import os
from typing import Any

import pytest
from hypothesis import settings

settings.register_profile("local", deadline=None)
settings.register_profile("ci", deadline=None, derandomize=True, print_blob=True)
settings.load_profile("ci" if os.environ.get("CI") else "local")

# With pytest-xdist (tests/check.sh), the scheduler below hands out whole modules, longest
# first. The real PX4 / ArduPilot tests form one group that one worker runs one after the other
# (most of their timing margins assume no CPU-bound test beside them; the whole suite runs them
# in lanes of their own, see tests/check.sh).
_REAL_AUTOPILOT_DIR = "tests/autopilot/"
# The tests that start a real PX4 carry the ``px4`` mark: tests/check.sh runs them one after the
# other in a lane of their own beside the lane of the other real-autopilot tests, but for a few
# with a single PX4 that run in that lane beside the PX4 soak (PX4 SIH in lockstep takes most of
# a core, ArduPilot SITL a fraction of one; docs/testing.md). A test
# that requests the ``px4`` fixture gets the mark here; one that starts PX4 another way (e.g.
# ``request.getfixturevalue``) carries it itself.
PX4_FIXTURE = "px4"


def _timeout_s(item: pytest.Item) -> float:
    """The test's pytest-timeout limit (its ``timeout`` mark, else the ini default)."""
    mark = item.get_closest_marker("timeout")
    if mark is not None and mark.args:
        return float(mark.args[0])
    return float(item.config.getini("timeout") or 0.0)


def group_of(nodeid: str) -> str:
    """The unit of work a test belongs to: its module or the real-autopilot group. A whole
    module goes to one worker, so module-scoped fixtures (e.g. a whole closed-loop
    evaluation) are built once."""
    module = nodeid.split("::", 1)[0]
    return "real-autopilot" if module.startswith(_REAL_AUTOPILOT_DIR) else module


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Marks the tests that start a real PX4 (``px4``, before ``-m`` selects on it). Orders
    longest first, so that parallel workers do not end on one long test: the real-autopilot
    modules, then the others, each by its longest test's timeout (the authors' bound on its
    duration), each module's tests kept together and in order."""
    by_module: dict[str, list[pytest.Item]] = {}
    for item in items:
        if PX4_FIXTURE in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.px4)
        by_module.setdefault(item.nodeid.split("::", 1)[0], []).append(item)
    ordered = sorted(
        by_module.values(),
        key=lambda its: (
            not its[0].nodeid.startswith(_REAL_AUTOPILOT_DIR),  # the longest chain starts first
            -max(map(_timeout_s, its)),
        ),
    )
    items[:] = [item for its in ordered for item in its]


@pytest.hookimpl(optionalhook=True)  # a hook of pytest-xdist: unknown without it
def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    """``--dist loadgroup`` with the groups of :func:`group_of` (decided from the test's id in
    the controller: xdist's own ``xdist_group`` marks do not reach it with pytest 9.2)."""
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class _ModuleGroups(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return group_of(nodeid)

    return _ModuleGroups(config, log)
