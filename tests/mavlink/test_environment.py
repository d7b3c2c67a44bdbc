"""Importing gcs-utm leaves the process environment alone: the MAVLink 2 modules are the
v20 dialects themselves, so no module sets ``MAVLINK20`` for the whole process (it would
change what an embedding application's own ``pymavlink.mavutil`` connections speak)."""

from __future__ import annotations

import os
import subprocess
import sys


def test_importing_the_mavlink_modules_sets_no_environment_variable() -> None:
    env = {k: v for k, v in os.environ.items() if k != "MAVLINK20"}
    code = (
        "import os\n"
        "import adapters.mavlink.wire, adapters.tlog._mavlink, sitl._mav\n"
        "import gcs_utm.app, gcs_utm.bench.fuzz, gcs_utm.bench.ingest\n"
        "from adapters.mavlink.wire import mav\n"
        "assert mav.WIRE_PROTOCOL_VERSION == '2.0'\n"
        "print(os.environ.get('MAVLINK20', 'unset'))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "unset", out
