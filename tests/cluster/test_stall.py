"""A stalled owner fences itself: ``gcs-utm serve --cluster`` owning a region and tracking a
vehicle is stopped (SIGSTOP) past its lease, a standby takes the region over, and on SIGCONT
the stale owner files nothing (its vehicle's track went stale meanwhile: a lost-link threat
would be its first act) and exits with code 3 within a bounded time."""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import time
from pathlib import Path

import pytest

from gcs_utm.cluster import lease
from gcs_utm.store import open_store
from tests.cluster.test_border_conflict import (
    _config,
    _free_port,
    _scenario,
    _start,
    _start_broker,
    _wait,
)
from tests.store.conftest import raw_execute

EXIT_WITHIN_S = 5.0


def _holders(url: str) -> dict[str, str]:
    with open_store(url) as s:
        return {r: h.split("#")[0] for r, h in lease.owners(s).items()}


@pytest.mark.slow
@pytest.mark.timeout(180)
def test_an_owner_stalled_past_its_lease_files_nothing_and_exits_3(
    pg_url: str, tmp_path: Path
) -> None:
    mosquitto = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
    if not os.path.exists(mosquitto):
        pytest.skip("mosquitto not installed (apt-get install mosquitto)")
    mqtt_port = _free_port()
    conf = tmp_path / "mosquitto.conf"
    conf.write_text(f"listener {mqtt_port} 127.0.0.1\nallow_anonymous true\n")
    logs = [tmp_path / n for n in ("a.log", "b.log", "sitl.log", "broker.log")]
    procs: list[subprocess.Popen[bytes]] = []
    try:
        procs.append(_start_broker(mosquitto, conf, logs[3], mqtt_port))
        port_a, port_b = _free_port(socket.SOCK_DGRAM), _free_port(socket.SOCK_DGRAM)
        cfg_a, cfg_b = (
            _config(
                tmp_path / f"{name.lower()}.toml",
                url=pg_url,
                mqtt_port=mqtt_port,
                link_port=port,
                instance=name,
                region=region,
                priority=1,
            )
            for name, region, port in (("A", "c0r0", port_a), ("B", "c1r0", port_b))
        )
        for cfg in (cfg_a, cfg_b):  # a short staleness: a stall makes the track stale
            cfg.write_text(cfg.read_text() + "[tracking]\nstale_after_s = 2.0\n")
        serve = ["serve", "--cluster", "--headless", "--auto-accept"]
        a = _start([*serve, "--config", str(cfg_a)], logs[0])
        procs.append(a)
        procs.append(_start([*serve, "--config", str(cfg_b)], logs[1]))
        _wait(lambda: _holders(pg_url) == {"c0r0": "A", "c1r0": "B"}, 60.0, "regions held", logs)
        sc = _scenario(tmp_path / "uas1.toml", "UAS1", 1, (-700.0, -100.0), 0.0, 5.0)
        procs.append(
            _start(["sitl", "--ephemeral-ports", str(sc), "--gcs", f"127.0.0.1:{port_a}"], logs[2])
        )

        def tracked() -> bool:
            return bool(raw_execute(pg_url, "SELECT 1 FROM tracks_latest LIMIT 1"))

        _wait(tracked, 60.0, "A tracks UAS1", logs)
        (epoch_a,) = {
            int(str(h).split("#")[1])
            for (h,) in raw_execute(pg_url, "SELECT holder FROM region_leases")
            if str(h).startswith("A#")
        }

        def threats_of_a() -> int:
            rows = raw_execute(pg_url, f"SELECT COUNT(*) FROM threats WHERE epoch = {epoch_a}")
            return int(str(rows[0][0]))

        before = threats_of_a()
        a.send_signal(signal.SIGSTOP)
        _wait(lambda: _holders(pg_url).get("c0r0") == "B", 15.0, "B takes c0r0 over", logs)
        time.sleep(2.5)  # a stall long enough for A's track of UAS1 to go stale
        woke = time.monotonic()
        a.send_signal(signal.SIGCONT)
        try:
            code = a.wait(EXIT_WITHIN_S + 5.0)
        except subprocess.TimeoutExpired:
            pytest.fail(f"A did not exit after waking\n{logs[0].read_text()[-3000:]}")
        took_s = time.monotonic() - woke
        assert code == 3, logs[0].read_text()[-3000:]
        assert took_s <= EXIT_WITHIN_S, (took_s, logs[0].read_text()[-3000:])
        assert threats_of_a() == before, raw_execute(
            pg_url, f"SELECT kind, doc FROM threats WHERE epoch = {epoch_a}"
        )
        # it stops on whichever it sees first after waking: its own lease deadline (self-fenced)
        # or the lease round finding the region taken (lost); either way exit 3, nothing filed
        stop_line = logs[0].read_text()
        assert "self-fenced" in stop_line or "lost: this instance stops" in stop_line, stop_line
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                os.kill(p.pid, signal.SIGCONT)
                p.send_signal(signal.SIGTERM)
            try:
                p.wait(20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(10)
