"""Test-wide settings. On CI (``CI`` set) hypothesis runs derandomized: the same examples on
every run, so a red CI is reproducible; local runs keep exploring new examples. No example
has a time limit (hypothesis' default is 200 ms): speed is checked by benchmarks, and a
loaded machine made a trivial example fail on time.

``tests/check.sh`` runs the tests in parallel processes (pytest-xdist, ``--dist loadgroup``,
see docs/testing.md); the collection hook below orders and groups them for that."""

from __future__ import annotations

import os

import pytest
from hypothesis import settings

settings.register_profile("local", deadline=None)
settings.register_profile("ci", deadline=None, derandomize=True, print_blob=True)
settings.load_profile("ci" if os.environ.get("CI") else "local")

_SHARED_SCOPES = {"module", "class", "package"}
# The real PX4 / ArduPilot tests: one worker runs them one after the other (their timing
# margins were set with the machine's cores to themselves); a module there may name a group of
# its own (the 30-minute serve soak, one PX4, runs beside them on the other worker).
_REAL_AUTOPILOT_DIR = "tests/autopilot/"
_REAL_AUTOPILOT_GROUP = "real-autopilot"


def _timeout_s(item: pytest.Item) -> float:
    """The test's pytest-timeout limit (its ``timeout`` mark, else the ini default)."""
    mark = item.get_closest_marker("timeout")
    if mark is not None and mark.args:
        return float(mark.args[0])
    return float(item.config.getini("timeout") or 0.0)


def _shares_a_fixture(item: pytest.Item) -> bool:
    """Whether the test uses a module-, class- or package-scoped fixture (an expensive set-up
    its module's other tests reuse)."""
    info = getattr(item, "_fixtureinfo", None)
    if info is None:
        return False
    return any(fd.scope in _SHARED_SCOPES for defs in info.name2fixturedefs.values() for fd in defs)


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Longest first, so that parallel workers do not end on one long test: the real-autopilot
    modules, then the others, each by its longest test's timeout (the authors' bound on its
    duration), each module's tests kept together and in order. With pytest-xdist, the
    real-autopilot tests form one group (``_REAL_AUTOPILOT_GROUP``), and the tests of a module
    that shares a module-scoped fixture another, so that fixture (e.g. a whole closed-loop
    evaluation) is built once, on one worker, not once per worker."""
    by_module: dict[str, list[pytest.Item]] = {}
    for item in items:
        by_module.setdefault(item.nodeid.split("::", 1)[0], []).append(item)
    ordered = sorted(
        by_module.values(),
        key=lambda its: (
            not its[0].nodeid.startswith(_REAL_AUTOPILOT_DIR),  # the longest chain starts first
            -max(map(_timeout_s, its)),
        ),
    )
    items[:] = [item for its in ordered for item in its]
    if not config.pluginmanager.hasplugin("xdist"):
        return
    for module, its in by_module.items():
        group = None
        if module.startswith(_REAL_AUTOPILOT_DIR):
            group = _REAL_AUTOPILOT_GROUP
        elif any(map(_shares_a_fixture, its)):
            group = module
        for item in its:
            if group is not None and item.get_closest_marker("xdist_group") is None:
                item.add_marker(pytest.mark.xdist_group(group))
