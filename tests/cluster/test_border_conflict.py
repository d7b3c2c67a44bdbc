"""Two instances, one airspace: ``gcs-utm serve --cluster`` twice on one PostgreSQL and one
mosquitto, each with one built-in vehicle (``gcs-utm sitl``) flying towards the other across
the region border. The tracks cross over MQTT, so the loss of separation is seen by both;
the owner of the higher-priority UAS decides (one threat), the recommendation for the other
UAS is filed in the store and proposed, accepted and uploaded by that UAS's owner. Then the
owner of the first region is killed with SIGKILL and the other takes its region over."""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from gcs_utm.cluster import lease
from gcs_utm.store import open_store
from tests.store.conftest import raw_execute

REPO = Path(__file__).resolve().parents[2]
ORIGIN = (40.65974645776713, -3.59689676974471, 675.0)


def _free_port(kind: int = socket.SOCK_STREAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _scenario(
    path: Path, op: str, sys_id: int, east: tuple[float, float], north_m: float, speed_mps: float
) -> Path:
    lat, lon, ground = ORIGIN
    path.write_text(
        f"""
[scenario]
name = "{op}"
description = "one vehicle of the border test"
duration_s = 300.0

[airspace]
origin_lat_deg = {lat}
origin_lon_deg = {lon}
ground_elevation_amsl_m = {ground}

[[operations]]
id = "{op}"
sys_id = {sys_id}
priority = 1
vehicle = "multirotor"
autopilot = "px4"
cruise_speed_mps = {speed_mps}
flight_geometry_m = 10.0
operational_volume_m = 30.0
max_climb_rate_mps = 3.0
endurance_s = 1200.0
start_s = 0.0
home = {{ east_m = {east[0]}, north_m = {north_m}, alt_agl_m = 0.0 }}
waypoints = [
    {{ east_m = {east[0]}, north_m = {north_m}, alt_agl_m = 80.0 }},
    {{ east_m = {east[1]}, north_m = {north_m}, alt_agl_m = 80.0 }},
]
"""
    )
    return path


def _config(
    path: Path,
    *,
    url: str,
    mqtt_port: int,
    link_port: int,
    instance: str,
    region: str,
    priority: int,
) -> Path:
    lat, lon, ground = ORIGIN
    path.write_text(
        f"""
[airspace]
origin_lat_deg = {lat}
origin_lon_deg = {lon}
ground_elevation_amsl_m = {ground}
[mavlink]
links = ["udpin:127.0.0.1:{link_port}"]
[usm]
default_priority = {priority}
[mqtt]
host = "127.0.0.1"
port = {mqtt_port}
[store]
url = "{url}"
[cluster]
instance = "{instance}"
region = "{region}"
west_m = -2000.0
south_m = -1000.0
cell_m = 2000.0
columns = 2
rows = 1
halo_m = 1000.0
lease_s = 2.0
renew_s = 0.5
"""
    )
    return path


def _start(args: list[str], log: Path) -> subprocess.Popen[bytes]:
    with open(log, "ab") as fh:
        return subprocess.Popen(
            [sys.executable, "-m", "gcs_utm", *args],
            stdin=subprocess.DEVNULL,
            stdout=fh,
            stderr=subprocess.STDOUT,
            env={**os.environ, "PYTHONPATH": str(REPO), "PYTHONUNBUFFERED": "1"},
        )


def _wait(cond: Callable[[], bool], timeout_s: float, what: str, logs: list[Path]) -> float:
    start = time.monotonic()
    while time.monotonic() - start < timeout_s:
        if cond():
            return time.monotonic() - start
        time.sleep(0.25)
    tails = "\n".join(f"--- {p.name}\n{p.read_text()[-2500:]}" for p in logs if p.exists())
    raise AssertionError(f"not within {timeout_s} s: {what}\n{tails}")


def _tid(rows: list[tuple[object, ...]]) -> str:
    return str(rows[0][0])


def _rows(url: str, sql: str) -> list[tuple[object, ...]]:
    return raw_execute(url, sql)


@pytest.mark.timeout(240)
def test_border_conflict_is_decided_once_and_survives_kill_9(pg_url: str, tmp_path: Path) -> None:
    mosquitto = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
    if not os.path.exists(mosquitto):
        pytest.skip("mosquitto not installed (apt-get install mosquitto)")
    mqtt_port = _free_port()
    conf = tmp_path / "mosquitto.conf"
    conf.write_text(f"listener {mqtt_port} 127.0.0.1\nallow_anonymous true\n")
    procs: list[subprocess.Popen[bytes]] = []
    logs = [tmp_path / n for n in ("a.log", "b.log", "sitl-a.log", "sitl-b.log", "broker.log")]
    try:
        procs.append(_start_broker(mosquitto, conf, logs[4], mqtt_port))
        port_a, port_b = _free_port(socket.SOCK_DGRAM), _free_port(socket.SOCK_DGRAM)
        cfg_a = _config(
            tmp_path / "a.toml",
            url=pg_url,
            mqtt_port=mqtt_port,
            link_port=port_a,
            instance="A",
            region="c0r0",
            priority=1,
        )
        cfg_b = _config(
            tmp_path / "b.toml",
            url=pg_url,
            mqtt_port=mqtt_port,
            link_port=port_b,
            instance="B",
            region="c1r0",
            priority=10,
        )
        serve = ["serve", "--cluster", "--headless", "--auto-accept"]
        procs.append(_start([*serve, "--config", str(cfg_a)], logs[0]))
        procs.append(_start([*serve, "--config", str(cfg_b)], logs[1]))

        def holders() -> dict[str, str]:
            with open_store(pg_url) as s:
                return {r: h.split("#")[0] for r, h in lease.owners(s).items()}

        _wait(lambda: holders() == {"c0r0": "A", "c1r0": "B"}, 60.0, "both regions held", logs)
        # UAS1 (A's, west of the border) flies east, UAS2 (B's) flies west: head on
        sc_a = _scenario(tmp_path / "uas1.toml", "UAS1", 1, (-700.0, 700.0), 0.0, 8.0)
        sc_b = _scenario(tmp_path / "uas2.toml", "UAS2", 2, (900.0, -900.0), 0.0, 8.0)
        sitl = ["sitl", "--ephemeral-ports"]
        procs.append(_start([*sitl, str(sc_a), "--gcs", f"127.0.0.1:{port_a}"], logs[2]))
        procs.append(_start([*sitl, str(sc_b), "--gcs", f"127.0.0.1:{port_b}"], logs[3]))

        def los_threats() -> list[tuple[object, ...]]:
            return _rows(pg_url, "SELECT id, epoch FROM threats WHERE kind = 'LOSS_OF_SEPARATION'")

        _wait(lambda: bool(los_threats()), 120.0, "a loss of separation threat", logs)

        def applied() -> list[tuple[object, ...]]:
            return _rows(
                pg_url,
                "SELECT id, version, operation_id, epoch FROM recommendations "
                "WHERE state = 'applied'",
            )

        _wait(lambda: bool(applied()), 90.0, "a recommendation applied", logs)
        epoch = {
            str(h).split("#")[0]: int(str(h).split("#")[1])
            for (h,) in _rows(pg_url, "SELECT holder FROM region_leases")
        }
        # one threat, decided by B (UAS2 has the higher priority), none by A
        assert [(str(i), e) for i, e in los_threats()] == [(_tid(los_threats()), epoch["B"])]
        recs = _rows(
            pg_url,
            "SELECT id, version, operation_id, state, epoch FROM recommendations "
            "ORDER BY id, version",
        )
        # B filed the recommendation for A's UAS1; A proposed it as v2 and uploaded it
        assert [(v, op, e) for _i, v, op, _st, e in recs] == [
            (1, "sys1", epoch["B"]),
            (2, "sys1", epoch["A"]),
        ], recs
        assert recs[1][3] == "applied"
        assert len({i for i, *_ in recs}) == 1
        answers = _rows(pg_url, "SELECT recommendation_id, version, decision FROM answers")
        assert answers == [(recs[0][0], 2, "accept")], answers
        # kill -9 of A: B takes its region over and resumes its operation from the store
        killed = time.monotonic()
        procs[1].send_signal(signal.SIGKILL)
        procs[1].wait(10)
        _wait(lambda: holders().get("c0r0") == "B", 10.0, "B takes c0r0 over", logs)

        def gained() -> list[tuple[object, ...]]:
            where = "action = 'region_gained' AND subject = 'c0r0'"
            return _rows(pg_url, f"SELECT actor, detail FROM audit WHERE {where}")

        # the takeover is complete once B has resumed the region and recorded it: the lease
        # row changes first, the audit row follows through B's store writer
        remaining_s = 10.0 - (time.monotonic() - killed)
        _wait(lambda: len(gained()) == 2, max(remaining_s, 0.0), "B resumes c0r0", logs)
        gained_rows = gained()
        assert [str(a).split("#")[0] for a, _d in gained_rows] == ["A", "B"]
        assert '"sys1"' in str(gained_rows[1][1])
        assert _rows(pg_url, "SELECT COUNT(*) FROM threats WHERE kind = 'LOSS_OF_SEPARATION'") == [
            (1,)
        ]
        assert _rows(pg_url, "SELECT COUNT(*) FROM recommendations") == [(2,)]
    finally:
        for p in reversed(procs):  # vehicles and instances first, the broker last
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
            try:
                p.wait(20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(10)


def _start_broker(binary: str, conf: Path, log: Path, port: int) -> subprocess.Popen[bytes]:
    with open(log, "ab") as fh:
        proc = subprocess.Popen([binary, "-c", str(conf)], stdout=fh, stderr=subprocess.STDOUT)
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            return proc
        except OSError:
            time.sleep(0.05)
    proc.kill()
    raise RuntimeError("mosquitto did not start listening")
