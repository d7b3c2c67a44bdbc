"""Test-wide settings. On CI (``CI`` set) hypothesis runs derandomized: the same examples on
every run, so a red CI is reproducible; local runs keep exploring new examples. No example
has a time limit (hypothesis' default is 200 ms): speed is checked by benchmarks, and a
loaded machine made a trivial example fail on time."""

from __future__ import annotations

import os

from hypothesis import settings

settings.register_profile("local", deadline=None)
settings.register_profile("ci", deadline=None, derandomize=True, print_blob=True)
settings.load_profile("ci" if os.environ.get("CI") else "local")
