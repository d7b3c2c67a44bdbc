"""History survives restarts (issue 21, item 1), with real processes: the built-in vehicles
fly use case 2 (``gcs-utm sitl``: GNSS jamming on UAS1, a geofence conflict for UAS2) while
``gcs-utm serve`` runs on one store, is killed with SIGKILL twice and restarted. Every
threat and recommendation row a killed life wrote must be unchanged at the end but for what
a restart's review settles (issue 32 item 5: an open threat closed, with its reason; a
version still waiting for an answer superseded), and every life's ids must carry that life's
epoch (before the fix, each process counted from 1 again and its upserts overwrote the rows
of the previous one). No threat of a dead life stays open, and no command is proposed for
the same UAS by two lives (before the review, each life decided the jamming again)."""

from __future__ import annotations

import json
import os
import signal
import socket
import sqlite3
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from gcs_utm.store.ids import epoch_of

ROOT = Path(__file__).resolve().parents[2]
UC2 = ROOT / "config" / "scenarios" / "use_case_2.toml"

Rows = dict[str, list[tuple[object, ...]]]


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _rows(db: Path) -> Rows:
    if not db.exists():
        return {"threats": [], "recommendations": []}
    conn = sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=10.0)
    try:
        return {
            "threats": list(conn.execute("SELECT * FROM threats ORDER BY id")),
            "recommendations": list(
                conn.execute("SELECT * FROM recommendations ORDER BY id, version")
            ),
        }
    except sqlite3.OperationalError:  # not created or migrated yet
        return {"threats": [], "recommendations": []}
    finally:
        conn.close()


def _of_life(rows: Rows, epoch: int) -> Rows:
    # the epoch column is the last of both tables
    return {table: [r for r in rs if r[-1] == epoch] for table, rs in rows.items()}


def _settled_only(before: Rows, after: Rows) -> bool:
    """``after`` is ``before`` but for what a restart's review may settle: an open threat
    closed with its reason, a PROPOSED version superseded (every other column as it was)."""
    if [r[0:2] for r in before["threats"]] != [r[0:2] for r in after["threats"]]:
        return False
    for b, a in zip(before["threats"], after["threats"], strict=True):
        # (id, kind, status, detected_at_s, doc, epoch)
        if a != b and not (a[2] == "closed" and "closed: " in str(a[4]) and a[3] == b[3]):
            return False
    if [r[0:2] for r in before["recommendations"]] != [r[0:2] for r in after["recommendations"]]:
        return False
    for b, a in zip(before["recommendations"], after["recommendations"], strict=True):
        # (id, version, state, threat_id, operation_id, created_t_s, doc, epoch)
        if a != b and not (b[2] == "proposed" and a[2] == "superseded" and a[3:6] == b[3:6]):
            return False
    return True


def _commands(rows: Rows) -> list[tuple[object, str, object]]:
    """(life, operation, command kind) of every recommendation version with a command that
    was taken (accepted, uploading, applied). A command one life proposed and a kill left
    unanswered is superseded at the restart and rightly proposed again by the next life."""
    out = []
    for r in rows["recommendations"]:
        command = json.loads(str(r[6])).get("command")
        if command and r[2] in ("accepted", "uploading", "applied"):
            out.append((r[-1], str(r[4]), command.get("kind")))
    return out


def _wait(db: Path, ready: Callable[[Rows], bool], timeout_s: float, what: str) -> Rows:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        rows = _rows(db)
        if ready(rows):
            return rows
        time.sleep(0.5)
    raise AssertionError(f"timed out after {timeout_s:.0f} s waiting for {what}: {_rows(db)}")


def _start(args: list[str], log: Path) -> subprocess.Popen[bytes]:
    with open(log, "ab") as fh:
        return subprocess.Popen(
            [sys.executable, "-m", "gcs_utm.cli", *args],
            stdout=fh,
            stderr=subprocess.STDOUT,
            cwd=log.parent,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )


def _stop(proc: subprocess.Popen[bytes], sig: signal.Signals) -> None:
    if proc.poll() is None:
        proc.send_signal(sig)
    proc.wait(timeout=30)


@pytest.mark.timeout(300)
def test_two_kill9_restarts_leave_every_earlier_row_unchanged(tmp_path: Path) -> None:
    port = _free_udp_port()
    db = tmp_path / "utm.sqlite"
    cfg = tmp_path / "serve.toml"
    cfg.write_text(
        "[airspace]\n"
        "origin_lat_deg = 40.65974645776713\n"
        "origin_lon_deg = -3.59689676974471\n"
        "ground_elevation_amsl_m = 675.0\n"
        "[mavlink]\n"
        f'links = ["udpin:127.0.0.1:{port}"]\n'
        "[usm]\n"
        "restart_review_s = 5.0\n"
    )
    serve = ["serve", "--config", str(cfg), "--db", str(db), "--headless", "--auto-accept"]
    sitl_args = ["sitl", str(UC2), "--gcs", f"127.0.0.1:{port}", "--ephemeral-ports"]
    procs: list[subprocess.Popen[bytes]] = []
    try:
        procs.append(_start(serve, tmp_path / "serve-1.log"))
        procs.append(_start(sitl_args, tmp_path / "sitl.log"))
        # Life 1 sees the jamming (t ~ 12 s after the scenario's t0), proposes, applies.
        _wait(
            db,
            lambda r: bool(_of_life(r, 1)["recommendations"]),
            120.0,
            "a recommendation of life 1",
        )
        time.sleep(2.0)
        _stop(procs[0], signal.SIGKILL)
        life1 = _of_life(_rows(db), 1)

        procs[0] = _start(serve, tmp_path / "serve-2.log")
        # the jamming lasts 120 s: the new life raises its own threats about it
        _wait(db, lambda r: bool(_of_life(r, 2)["threats"]), 90.0, "a threat of life 2")
        time.sleep(2.0)
        _stop(procs[0], signal.SIGKILL)
        rows = _rows(db)
        assert _settled_only(life1, _of_life(rows, 1))
        life2 = _of_life(rows, 2)

        procs[0] = _start(serve, tmp_path / "serve-3.log")
        _wait(db, lambda r: bool(_of_life(r, 3)["threats"]), 90.0, "a threat of life 3")
        _wait(
            db,
            lambda r: all(t[2] == "closed" for t in r["threats"] if t[-1] in (1, 2)),
            60.0,
            "the threats of the dead lives closed",
        )
        _stop(procs[0], signal.SIGTERM)
        assert procs[0].returncode == 0, (tmp_path / "serve-3.log").read_text()[-3000:]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait(timeout=30)

    final = _rows(db)
    assert _settled_only(life1, _of_life(final, 1))
    assert _settled_only(life2, _of_life(final, 2))
    assert life1["threats"] and life1["recommendations"] and life2["threats"]
    commands = _commands(final)  # (which ones depends on the timing of the kills)
    for _life, op, kind in commands:
        lives = {life for life, o, k in commands if (o, k) == (op, kind)}
        assert len(lives) == 1, f"{kind} for {op} taken in lives {sorted(lives)}"
    for table, rs in final.items():
        for row in rs:
            row_id, epoch = str(row[0]), row[-1]
            assert epoch_of(row_id) == epoch, f"{table} row {row_id!r} written by life {epoch}"
    conn = sqlite3.connect(db)
    try:
        assert [e for (e,) in conn.execute("SELECT epoch FROM lives ORDER BY epoch")] == [1, 2, 3]
        assert conn.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    finally:
        conn.close()
