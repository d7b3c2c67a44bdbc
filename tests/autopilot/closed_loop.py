"""The closed loop against real autopilots: pilots fly crossing missions, ``gcs-utm serve
--headless --auto-accept`` watches them on its own links, and the flown separation is measured
from the autopilots' own positions (see pilot.py)."""

from __future__ import annotations

import asyncio
import math
import sqlite3
import subprocess
import sys
import time
from collections.abc import Awaitable, Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

from gcs_utm.app import OperatorMode, Runtime, serve
from gcs_utm.geo import haversine_m
from gcs_utm.model import FlightPlan, Operation
from gcs_utm.settings import Settings
from gcs_utm.store import Store
from tests.autopilot.pilot import PilotLink, Sample, local_m, mission_items, offset_deg

MIN_H_M, MIN_V_M = 50.0, 15.0  # config/default.toml separation minima
FLOOR_M = 10.0  # [deconfliction] min_height_above_home_m


@dataclass(frozen=True)
class Crossing:
    """Two UAS ``leg_m`` west and south of ``origin`` flying through it to as far beyond."""

    origin: tuple[float, float]
    ground_amsl_m: float
    leg_m: float = 220.0
    cruise_agl_m: float = 30.0

    def starts(self) -> list[tuple[float, float]]:
        lat0, lon0 = self.origin
        return [offset_deg(lat0, lon0, -self.leg_m, 0.0), offset_deg(lat0, lon0, 0.0, -self.leg_m)]

    def ends(self) -> list[tuple[float, float]]:
        lat0, lon0 = self.origin
        return [offset_deg(lat0, lon0, self.leg_m, 0.0), offset_deg(lat0, lon0, 0.0, self.leg_m)]


@dataclass(frozen=True)
class Outcome:
    """What the closed loop did: store rows, the serve log and the flown closest approach."""

    threat_kinds: list[str]
    recommendation_states: list[str]
    mission_totals_before: list[int]
    mission_totals_after: list[int]
    closest_h_m: float
    closest_v_m: float
    log: str
    below_floor: list[str]

    @property
    def flown_loss(self) -> bool:
        return self.closest_h_m < MIN_H_M and self.closest_v_m < MIN_V_M


def upload_crossing(pilots: list[PilotLink], crossing: Crossing) -> None:
    """Each pilot uploads its leg (PX4: AMSL from its home; ArduPilot: above home)."""
    for p, start, end in zip(pilots, crossing.starts(), crossing.ends(), strict=True):
        assert p.home is not None
        alt = crossing.cruise_agl_m + (p.home[2] if p.autopilot == "px4" else 0.0)
        p.upload(
            mission_items(p.sys_id, start, [(*start, alt), (*end, alt)], autopilot=p.autopilot)
        )


def _config(path: Path, crossing: Crossing, links: list[str]) -> Path:
    quoted = ", ".join(f'"{link}"' for link in links)
    path.write_text(
        f"""
[airspace]
origin_lat_deg = {crossing.origin[0]}
origin_lon_deg = {crossing.origin[1]}
ground_elevation_amsl_m = {crossing.ground_amsl_m}

[mavlink]
links = [{quoted}]
"""
    )
    return path


def rows(db: Path, sql: str) -> list[tuple[object, ...]]:
    """Rows of the store, read-only beside the running service ([] before its schema)."""
    if not db.exists():
        return []
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=5.0)
    try:
        return list(con.execute(sql))
    except sqlite3.OperationalError:
        return []
    finally:
        con.close()


def file_operations(db: Path, *ops: Operation) -> None:
    """Save ``ops`` and their plans in the store at ``db`` (before serve starts on it)."""
    with Store(db) as store:
        for op in ops:
            store.save_operation(op)
            store.save_plan(op.plan)


@contextmanager
def serve_process(
    cfg: Path, db: Path, log_path: Path, speed: float, *, verbose: bool = True
) -> Iterator[subprocess.Popen[bytes]]:
    """``gcs-utm [-v] serve --headless --auto-accept`` on ``cfg`` and ``db`` at ``speed``, its
    output in ``log_path``, for the block. A failure in the block (an assertion, a timeout)
    comes back with the log's last 4000 characters, and so does serve gone by its end; serve
    is stopped (SIGTERM, waited for up to 30 s) however the block ends."""
    with log_path.open("wb") as log:
        proc = subprocess.Popen(
            [sys.executable, "-m", "gcs_utm", *(["-v"] if verbose else []), "serve",
             "--headless", "--auto-accept", "--config", str(cfg), "--db", str(db),
             "--speed", str(speed)],
            stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
        )  # fmt: skip
    try:
        yield proc
        assert proc.poll() is None, "gcs-utm serve exited"
    except (AssertionError, TimeoutError) as exc:
        tail = log_path.read_text(errors="replace")[-4000:]
        raise AssertionError(f"{exc}\n--- gcs-utm serve log\n{tail}") from exc
    finally:
        if proc.poll() is None:
            proc.terminate()
            proc.wait(timeout=30)


async def until(cond: Callable[[], object], timeout_s: float, what: str) -> None:
    """Until ``cond()`` holds (checked every 0.05 s): an AssertionError naming ``what`` after
    ``timeout_s`` wall seconds."""
    end = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > end:
            raise AssertionError(f"timed out after {timeout_s} s: {what}")
        await asyncio.sleep(0.05)


T = TypeVar("T")


async def serve_while(
    settings: Settings,
    db: Path,
    scenario: Callable[[Runtime], Awaitable[T]],
    speed: float,
    record_dir: Path | None = None,
) -> T:
    """``gcs-utm serve`` in this process on ``settings`` and ``db`` at ``speed`` (nobody
    answers: ``OperatorMode.NONE``, nothing commanded), stopped once ``scenario``, started
    on its runtime, ends. The scenario's failure is raised again; else serve must have exited
    with 0. Returns what the scenario returned."""
    stop = asyncio.Event()
    tasks: list[asyncio.Task[T]] = []

    async def guarded(rt: Runtime) -> T:
        try:
            return await scenario(rt)
        finally:
            stop.set()

    async def on_runtime(rt: Runtime) -> None:
        tasks.append(asyncio.create_task(guarded(rt)))

    code = await serve(
        settings,
        db_path=db,
        operator=OperatorMode.NONE,
        headless=False,
        stop=stop,
        on_runtime=on_runtime,
        speed=speed,
        record_dir=record_dir,
    )
    assert tasks, f"gcs-utm serve exited with {code} before its runtime was up"
    result = await tasks[0]  # its assertion, if any
    assert code == 0, f"gcs-utm serve exited with {code}"
    return result


def _wait_operations(db: Path, n: int, timeout_s: float, proc: subprocess.Popen[bytes]) -> None:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if proc.poll() is not None:
            raise AssertionError("gcs-utm serve exited early")
        if len(rows(db, "SELECT id FROM operations")) >= n:
            return
        time.sleep(0.5)
    raise AssertionError(f"fewer than {n} operations filed after {timeout_s} s")


def closest(a: list[Sample], b: list[Sample], origin: tuple[float, float]) -> tuple[float, float]:
    """Over time-matched samples (within 0.1 s wall), the (horizontal, vertical) separation
    where the pair comes closest against the cylinder minima."""
    worst, worst_score = (math.inf, math.inf), math.inf
    j = 0
    for s in a:
        while j + 1 < len(b) and abs(b[j + 1].t_s - s.t_s) <= abs(b[j].t_s - s.t_s):
            j += 1
        if not b or abs(b[j].t_s - s.t_s) > 0.1:
            continue
        ea, na = local_m(*origin, s.lat_deg, s.lon_deg)
        eb, nb = local_m(*origin, b[j].lat_deg, b[j].lon_deg)
        dh = math.hypot(ea - eb, na - nb)
        dv = abs(s.alt_amsl_m - b[j].alt_amsl_m)
        score = max(dh / MIN_H_M, dv / MIN_V_M)  # < 1: loss of separation
        if score < worst_score:
            worst_score, worst = score, (dh, dv)
    return worst


def _total(p: PilotLink) -> int:
    return p.mission_current[-1][2] if p.mission_current else 0


def fly(
    pilots: list[PilotLink],
    crossing: Crossing,
    links: list[str],
    speed: float,
    tmp_path: Path,
    flight_timeout_s: float = 150.0,
) -> Outcome:
    """Start serve on ``links``, wait for its two operations, start both flights, follow them
    until both reach their ends (or the timeout), stop serve and collect the outcome."""
    db = tmp_path / "store.sqlite"
    log_path = tmp_path / "serve.log"
    cfg = _config(tmp_path / "serve.toml", crossing, links)
    for p in pilots:  # the mission size the pilot uploaded, as the autopilot reports it
        p.poll(1.0)
    before = [_total(p) for p in pilots]
    with serve_process(cfg, db, log_path, speed, verbose=False) as proc:
        _wait_operations(db, 2, 40.0, proc)
        # ArduCopters take off one after the other (arming can be refused for a while
        # after boot) and hover in GUIDED; both missions then start together, so the
        # crossing does not depend on how long each arming took on a loaded machine
        for p in pilots:
            p.arm_and_start(takeoff_agl_m=crossing.cruise_agl_m, auto=False)
        for p in pilots:
            if p.autopilot != "px4":
                p.set_mode(3)  # AUTO
        _follow(pilots, crossing, flight_timeout_s)
    dh, dv = closest(pilots[0].samples, pilots[1].samples, crossing.origin)
    return Outcome(
        threat_kinds=[str(r[0]) for r in rows(db, "SELECT kind FROM threats")],
        recommendation_states=[str(r[0]) for r in rows(db, "SELECT state FROM recommendations")],
        mission_totals_before=before,
        mission_totals_after=[_total(p) for p in pilots],
        closest_h_m=dh,
        closest_v_m=dv,
        log=log_path.read_text(errors="replace"),
        below_floor=below_floor(db),
    )


def _from_vehicle(plan: FlightPlan) -> bool:
    """Whether a stored plan version was filed from the vehicle's mission (vehicle_ops.py)."""
    return plan.reason.startswith(("from the vehicle's mission", "re-timed"))


def below_floor(db: Path) -> list[str]:
    """Waypoints of the plans the UTM generated (every recommendation's alternatives) lower
    than FLOOR_M above the operation's home (its home at arming), other than the vehicle's own
    (its position when planned, any waypoint of a plan filed from its mission: its take-off
    point on the ground): none may be (issue 31)."""
    out: list[str] = []
    with Store(db) as store:
        ops = {o.id: o for o in store.load_operations()}
        recs = store.load_recommendations(latest_only=False)
        own = {
            # the versions filed from the vehicle's mission (vehicle_ops.py), re-timed ones too
            o: [w for p in store.load_plans(o) if _from_vehicle(p) for w in p.waypoints]
            for o in ops
        }
    for rec in recs:
        op = ops.get(rec.operation_id)
        if op is None or op.home is None:
            continue
        floor_m = op.home.alt_amsl_m + FLOOR_M
        for alt in (*rec.alternatives, *((rec.selected,) if rec.selected else ())):
            # the first waypoint is where the vehicle was when planned: not generated
            for w in alt.plan.waypoints[1:] if alt.plan else ():
                mine = any(
                    haversine_m(w.lat_deg, w.lon_deg, v.lat_deg, v.lon_deg) < 1.0
                    and abs(w.alt_amsl_m - v.alt_amsl_m) < 1.0
                    for v in own[op.id]
                )
                if not mine and w.alt_amsl_m < floor_m - 0.01:
                    out.append(f"{rec.id} {alt.maneuver}: {w} below {floor_m:.2f} m")
    return out


def _follow(pilots: list[PilotLink], crossing: Crossing, timeout_s: float) -> None:
    ends = crossing.ends()
    deadline = time.monotonic() + timeout_s
    done = [False] * len(pilots)
    while time.monotonic() < deadline and not all(done):
        for k, p in enumerate(pilots):
            p.poll(0.02)
            if p.samples:
                s = p.samples[-1]
                e, n = local_m(*ends[k], s.lat_deg, s.lon_deg)
                done[k] = done[k] or math.hypot(e, n) < 10.0
