"""PX4's private /tmp (no real autopilot needed): a fresh tmpfs hides the other runs' lock
sockets, while the folders PX4 needs keep their paths and contents even when they live under
/tmp themselves (a clone with ../shared in a temporary folder)."""

from __future__ import annotations

import subprocess
import tempfile
from pathlib import Path

import pytest

from tests.autopilot.autopilots import _private_tmp_works, private_tmp_argv


@pytest.mark.skipif(not _private_tmp_works(), reason="no private mount namespace here")
def test_folders_under_tmp_stay_and_the_rest_of_tmp_is_hidden() -> None:
    with tempfile.TemporaryDirectory(dir="/tmp") as tmp:
        root = Path(tmp)
        etc = root / "shared" / "px4-sitl" / "etc"
        etc.mkdir(parents=True)
        (etc / "rcS").write_text("startup\n")
        work = root / "main" / "px4-0"
        work.mkdir(parents=True)
        (root / "px4-sock-0").write_text("another run's lock\n")
        script = f"cat {etc / 'rcS'} && echo written > out && ls -a {root}"
        argv = private_tmp_argv(["sh", "-c", script], keep=(etc,), cwd=work)
        done = subprocess.run(argv, capture_output=True, text=True, timeout=30, check=False)
        assert done.returncode == 0, done.stderr
        lines = done.stdout.split()
        assert lines[0] == "startup"  # PX4's startup file is there
        assert "px4-sock-0" not in lines  # what else is in /tmp is not
        assert (work / "out").read_text() == "written\n"  # it wrote into the real work dir
