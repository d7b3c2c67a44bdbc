"""Failover that holds, end to end: three ``gcs-utm serve --cluster`` instances (owners A and
B, standby C) on one PostgreSQL and one mosquitto, two built-in vehicles behind a MAVLink
router that feeds every instance (:mod:`tests.cluster.router`). PostgreSQL restarts, then A
is killed (``kill -9``): B takes A's region over and keeps tracking A's vehicle through the
router, without a lost-link threat or an emergency geofence. Then B stalls (SIGSTOP) past its
lease: C takes both regions, and B, woken, files nothing and exits with code 3."""

from __future__ import annotations

import asyncio
import json
import os
import shutil
import signal
import socket
import subprocess
import time
from pathlib import Path

import aiomqtt
import pytest

from gcs_utm.cluster import lease
from gcs_utm.store import open_store
from tests.cluster.router import UdpFanout
from tests.cluster.test_border_conflict import (
    _config,
    _free_port,
    _scenario,
    _start,
    _start_broker,
    _wait,
)
from tests.store.conftest import raw_execute
from tests.store.pgserver import PgServer

WITHIN_S = 5.0


def _holders(url: str) -> dict[str, str]:
    with open_store(url) as s:
        return {r: h.split("#")[0] for r, h in lease.owners(s).items()}


def _one(url: str, sql: str) -> object:
    return raw_execute(url, sql)[0][0]


def _operator_command(
    mqtt_port: int, uas: str, command: str, request_id: str, settle_s: float = 1.0
) -> list[dict[str, object]]:
    """An operator's command over MQTT (as ``gcs-utm pilot`` sends it, operator ``admin``):
    every answer on the status topic for ``request_id``, collected until ``settle_s`` after
    the first (at most 15 s)."""

    async def exchange() -> list[dict[str, object]]:
        answers: list[dict[str, object]] = []
        async with aiomqtt.Client("127.0.0.1", mqtt_port, identifier="test-station") as client:
            await client.subscribe("gcs_utm/operators/admin/status", qos=1)
            body = {
                "schema_version": 1,
                "type": "operator_command",
                "uas": uas,
                "command": command,
                "id": request_id,
                "t_s": time.time(),
            }
            await client.publish("gcs_utm/operators/admin/commands", json.dumps(body), qos=1)
            loop = asyncio.get_running_loop()
            end = loop.time() + 15.0
            messages = aiter(client.messages)
            while loop.time() < end:
                try:
                    msg = await asyncio.wait_for(anext(messages), end - loop.time())
                except TimeoutError:
                    break
                doc = json.loads(bytes(msg.payload))  # type: ignore[arg-type]
                if doc.get("type") == "command_status" and doc.get("id") == request_id:
                    answers.append(doc)
                    end = min(end, loop.time() + settle_s)
        return answers

    return asyncio.run(exchange())


def _submit_plan(mqtt_port: int, op_id: str, like: str, url: str) -> None:
    """A pilot files a plan over MQTT (operator ``admin``), the waypoints of operation
    ``like`` as stored."""
    with open_store(url) as s:
        (plan,) = [op.plan for op in s.load_operations() if op.id == like]
    body = {
        "schema_version": 1,
        "type": "flight_plan",
        "operation_id": op_id,
        "t_s": time.time(),
        "waypoints": [
            {"lat_deg": w.lat_deg, "lon_deg": w.lon_deg, "alt_amsl_m": w.alt_amsl_m, "t_s": w.t_s}
            for w in plan.waypoints
        ],
    }

    async def send() -> None:
        async with aiomqtt.Client("127.0.0.1", mqtt_port, identifier="test-planner") as client:
            await client.publish("gcs_utm/operators/admin/flight_plans", json.dumps(body), qos=1)

    asyncio.run(send())


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_kill_stall_and_database_restart_leave_one_decider_and_tracked_vehicles(
    pg_server: PgServer, pg_url: str, tmp_path: Path
) -> None:
    mosquitto = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
    if not os.path.exists(mosquitto):
        pytest.skip("mosquitto not installed (apt-get install mosquitto)")
    mqtt_port = _free_port()
    conf = tmp_path / "mosquitto.conf"
    conf.write_text(f"listener {mqtt_port} 127.0.0.1\nallow_anonymous true\n")
    names = ("A", "B", "C")
    logs = [tmp_path / f"{n.lower()}.log" for n in names]
    logs += [tmp_path / "sitl1.log", tmp_path / "sitl2.log", tmp_path / "broker.log"]
    procs: list[subprocess.Popen[bytes]] = []
    ports = [_free_port(socket.SOCK_DGRAM) for _ in names]
    router = UdpFanout(ports)
    try:
        procs.append(_start_broker(mosquitto, conf, logs[5], mqtt_port))
        serve = ["-v", "serve", "--cluster", "--headless", "--auto-accept"]
        inst: dict[str, subprocess.Popen[bytes]] = {}
        for name, region, port, log in zip(names, ("c0r0", "c1r0", ""), ports, logs, strict=False):
            cfg = _config(
                tmp_path / f"{name}.toml",
                url=pg_url,
                mqtt_port=mqtt_port,
                link_port=port,
                instance=name,
                region=region or "c0r0",
                priority=1,
            )
            if not region:  # C: a standby with no region of its own
                cfg.write_text(cfg.read_text().replace('region = "c0r0"\n', ""))
            # the operators' MQTT interface on every instance (one client id each)
            cfg.write_text(
                cfg.read_text().replace(
                    "[mqtt]\n", f'[mqtt]\nenabled = true\nclient_id = "gcs-utm-{name}"\n'
                )
            )
            inst[name] = _start([*serve, "--config", str(cfg)], log)
            procs.append(inst[name])
            if name == "B":
                _wait(lambda: len(_holders(pg_url)) == 2, 60.0, "A and B hold regions", logs)
        assert _holders(pg_url) == {"c0r0": "A", "c1r0": "B"}
        # UAS1 departs in A's region, UAS2 in B's; both well apart, both behind the router
        sitl = ["sitl", "--ephemeral-ports", "--gcs", f"127.0.0.1:{router.vehicle_port}"]
        for op, sys_id, east, north_m, log in (
            ("UAS1", 1, (-900.0, -300.0), 0.0, logs[3]),
            ("UAS2", 2, (900.0, 300.0), 800.0, logs[4]),
        ):
            sc = _scenario(tmp_path / f"{op}.toml", op, sys_id, east, north_m, 4.0)
            procs.append(_start([*sitl, str(sc)], log))

        def track_t(track_id: str) -> float:
            rows = raw_execute(pg_url, f"SELECT t_s FROM tracks_latest WHERE id = '{track_id}'")
            return float(str(rows[0][0])) if rows else 0.0

        _wait(lambda: track_t("sys1") > 0 and track_t("sys2") > 0, 90.0, "both tracked", logs)
        # every instance hears both vehicles; each files only its own region's
        filed = {n: logs[i].read_text() for i, n in enumerate(names)}
        assert "sys1 filed from sysid 1" in filed["A"] and "sys2 filed" not in filed["A"]
        assert "sys2 filed from sysid 2" in filed["B"] and "sys1 filed" not in filed["B"]
        assert "filed from sysid" not in filed["C"]
        # the standby (no region) watches both vehicles as the operations their owners
        # filed: ordinary vehicle tracks, not intruders sysid:<n>@<address>
        _wait(
            lambda: all(
                f"watching {op} of another instance (heard)" in logs[2].read_text()
                for op in ("sys1", "sys2")
            ),
            10.0,
            "C watches both vehicles",
            logs,
        )
        # a plan filed over MQTT reaches every instance: filed by the holder of its region only
        _submit_plan(mqtt_port, "PLAN-B", "sys2", pg_url)
        elsewhere = "SELECT actor FROM audit WHERE action = 'mqtt_elsewhere' AND subject = 'PLAN-B'"
        _wait(
            lambda: (
                len(raw_execute(pg_url, elsewhere)) == 2
                and "PLAN-B filed over MQTT" in logs[1].read_text()
            ),
            10.0,
            "B files the plan, A and C pass",
            logs,
        )
        assert all("PLAN-B filed" not in logs[i].read_text() for i in (0, 2))
        rows_before = {
            t: int(str(_one(pg_url, f"SELECT COUNT(*) FROM {t}")))
            for t in ("operations", "flight_plans", "threats", "recommendations")
        }
        # PostgreSQL restarts (every connection cut), then A dies
        pg_server.restart()
        inst["A"].send_signal(signal.SIGKILL)
        inst["A"].wait(10)
        killed = time.monotonic()
        _wait(lambda: _holders(pg_url).get("c0r0") in ("B", "C"), WITHIN_S, "c0r0 taken", logs)
        took_s = time.monotonic() - killed
        new_owner = _holders(pg_url)["c0r0"]
        assert took_s <= WITHIN_S
        t_kill = track_t("sys1")
        # the new owner tracks A's vehicle through the router: its track goes on
        _wait(lambda: track_t("sys1") > t_kill + 3.0, 15.0, "sys1 still tracked", logs)
        for name in names[1:]:
            assert inst[name].poll() is None, logs[names.index(name)].read_text()[-3000:]
        # the new owner commands A's vehicle through the router; it alone answers (every
        # instance hears the MQTT command), and the vehicle acknowledges and reports HOLD
        answers = _operator_command(mqtt_port, "sys1", "hold", "after-takeover")
        assert [a["outcome"] for a in answers] == ["confirmed"], answers
        assert answers[0]["mode"] == "hold", answers
        other = next(n for n in ("B", "C") if n != new_owner)
        assert "hold sys1: confirmed" in logs[names.index(new_owner)].read_text()
        assert "hold sys1: refused" in logs[names.index(other)].read_text()
        # then B stalls past its lease: C, the standby left, takes whatever B holds
        epoch_b = int(
            str(_one(pg_url, "SELECT holder FROM region_leases WHERE holder LIKE 'B#%'")).split(
                "#"
            )[1]
        )

        def threats_of_b() -> int:
            return int(str(_one(pg_url, f"SELECT COUNT(*) FROM threats WHERE epoch = {epoch_b}")))

        before_b = threats_of_b()
        inst["B"].send_signal(signal.SIGSTOP)
        _wait(lambda: set(_holders(pg_url).values()) == {"C"}, 15.0, "C holds every region", logs)
        t_stall = {t: track_t(t) for t in ("sys1", "sys2")}
        woke = time.monotonic()
        inst["B"].send_signal(signal.SIGCONT)
        assert inst["B"].wait(WITHIN_S + 5.0) == 3, logs[1].read_text()[-3000:]
        assert time.monotonic() - woke <= WITHIN_S
        assert threats_of_b() == before_b
        # C decides for both regions and tracks both vehicles through the router
        _wait(lambda: all(track_t(t) > t_stall[t] + 3.0 for t in t_stall), 15.0, "C tracks", logs)
        assert _holders(pg_url) == {"c0r0": "C", "c1r0": "C"}
        assert inst["C"].poll() is None, logs[2].read_text()[-3000:]
        # an intruder track a vehicle got before its operation was filed is not fed since
        intruders = raw_execute(pg_url, "SELECT id, t_s FROM tracks_latest WHERE id LIKE 'sysid:%'")
        assert all(float(str(t)) < t_kill for _, t in intruders), intruders
        lost = raw_execute(pg_url, "SELECT id FROM threats WHERE kind = 'COMMUNICATION_FAILURE'")
        assert lost == [], lost
        assert raw_execute(pg_url, "SELECT id FROM geofences WHERE active = 1") == []
        for table, n in rows_before.items():
            assert int(str(_one(pg_url, f"SELECT COUNT(*) FROM {table}"))) >= n, table
        assert new_owner in ("B", "C")
        assert router.forwarded > 0
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
        router.close()
