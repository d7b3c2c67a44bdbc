"""The autopilot fixtures clean up after a failed test (no real autopilot needed): the pilot
links it left open are closed and every process it started is stopped, even when stopping
one of them fails. A socket left open is a ResourceWarning, i.e. an error, in whichever later
test the garbage collector happens to find it."""

from __future__ import annotations

import socket
import subprocess
from pathlib import Path

import pytest

from tests.autopilot.autopilots import SitlProcess, launcher
from tests.autopilot.pilot import PilotLink


def _sleeper(root: Path, **_: object) -> SitlProcess:
    proc = subprocess.Popen(["sleep", "60"], start_new_session=True)
    return SitlProcess("fake", 0, 1, root, proc)


def test_a_failed_test_leaves_no_link_open_and_no_process_running(tmp_path: Path) -> None:
    printed_logs: list[bool] = []
    body = launcher("fake", _sleeper, tmp_path, lambda: printed_logs.append(True) or True)
    with socket.create_server(("127.0.0.1", 0)) as server:
        launch = next(body)
        first, second = launch(), launch()
        link = PilotLink(0, autopilot="ardupilot", tcp_port=server.getsockname()[1])
        accepted, _ = server.accept()
        accepted.close()

        def broken_stop(timeout_s: float = 10.0) -> None:
            raise RuntimeError("stop failed")

        first.stop = broken_stop  # type: ignore[method-assign]
        # the test failed here, without closing its link: pytest resumes the fixture
        with pytest.raises(RuntimeError, match="stop failed"):
            next(body)
    try:
        assert link.sock.fileno() == -1, "the link a failed test left open was not closed"
        assert second.proc.poll() is not None, "a process was left running"
        assert len(printed_logs) == 2
    finally:
        SitlProcess.stop(first)
