"""The service keeps the memory it frees (``gcs_utm.app.memory``): the monitoring cycle's
large arrays (the (N, K, 4) prediction is 195 MB at 100,000 UAS) reuse the last cycle's
pages instead of fresh ones the kernel must map and zero every cycle."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

_PROBE = """
import json, resource, sys
import numpy as np
retained = None
if sys.argv[1] == "retain":
    from gcs_utm.app.memory import retain_freed_memory
    retained = retain_freed_memory()
faults = []
for _ in range(4):
    r0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    a = np.ones((100_000, 61, 4))  # the prediction's size at 100,000 UAS
    del a
    faults.append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - r0)
print(json.dumps({"retained": retained, "faults": faults}))
"""


def _probe(mode: str) -> dict[str, object]:
    out = subprocess.run(
        [sys.executable, "-c", _PROBE, mode], capture_output=True, text=True, check=True
    )
    result: dict[str, object] = json.loads(out.stdout)
    return result


def test_a_freed_large_array_is_reused_without_page_faults() -> None:
    kept = _probe("retain")
    if not kept["retained"]:
        pytest.skip("the C library has no mallopt (not glibc)")
    default = _probe("default")
    kept_faults = kept["faults"]
    default_faults = default["faults"]
    assert isinstance(kept_faults, list) and isinstance(default_faults, list)
    # By default every allocation is a fresh mapping: at least one fault per 2 MB huge page.
    assert min(default_faults[1:]) >= 90
    # Kept: after the first allocation the same pages serve the next ones.
    assert max(kept_faults[1:]) < 10


def test_the_service_entry_point_keeps_freed_memory() -> None:
    if not _probe("retain")["retained"]:
        pytest.skip("the C library has no mallopt (not glibc)")
    probe = _PROBE.replace(
        "from gcs_utm.app.memory import retain_freed_memory\n    retained = retain_freed_memory()",
        "from gcs_utm.app import configure_interpreter\n    configure_interpreter()\n"
        "    retained = True",
    )
    assert probe != _PROBE
    out = subprocess.run(
        [sys.executable, "-c", probe, "retain"], capture_output=True, text=True, check=True
    )
    faults = json.loads(out.stdout)["faults"]
    assert max(faults[1:]) < 10
