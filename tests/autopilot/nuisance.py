"""The mixed nuisance-alert soak against the real autopilots (issue 31).

``gcs-utm serve --headless --auto-accept`` (a real process, its store on disk) watches four
real autopilots from ``../shared`` (``GCS_UTM_SHARED``), a PX4 SIH quad, a PX4 SIH plane,
an ArduCopter and an ArduPlane, each flown by its own pilot in cycles of normal missions
(nuisance_fleet.py). Injected, at fractions of the soak's simulated length T:

- a **link drop** from 0.25 T, once the ArduCopter is airborne: gcs-utm's link to it
  (through ``TcpCut``) drops every byte for ``link_drop_s`` (longer than the staleness
  limit), then carries them again;
- a **reboot**: the PX4 quad's process is stopped and started again on the same working
  directory (a power cycle) at its first landing after 0.4 T;
- a **serve kill -9** at 0.6 T, restarted on the same store 2 s later.

After T no vehicle starts another flight; those in the air are followed to their landing
(``land_at_end``), then serve is stopped (SIGTERM) and every threat in the store is judged:

- **expected**: a COMMUNICATION_FAILURE of the vehicle whose link was cut, detected while it
  was cut (between the cut and its restore plus the staleness limit), or of the rebooted
  vehicle while its process was down; it must be closed;
- **false**: any other threat (a pilot flying a normal mission in an empty sky would call
  it a false alarm).

The verdict passes when no threat is false, none is open, every injection happened and the
link drop was detected. Run it (the autopilots bind fixed ports: a private namespace)::

    bash tests/netns.sh .venv/bin/python -m tests.autopilot.nuisance --minutes 30 --speed 1 \
        --json out.json

``--vehicles arduplane`` (names of nuisance_fleet.VEHICLES, comma-separated) flies a subset:
the link drop needs the ArduCopter and the reboot the PX4 quad, so a subset without them
skips them. It prints the JSON report and exits 1 when the verdict fails. ``test_nuisance_soak.py``
runs a short one in the suite.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tests.autopilot.autopilots import REPO, unavailable_reason
from tests.autopilot.closed_loop import rows
from tests.autopilot.nuisance_fleet import ORIGIN, VEHICLES, Flyer, TcpCut, VehicleDef

CUT_PORT = 15782  # TcpCut's listening port, gcs-utm's link to the ArduCopter


@dataclass(frozen=True)
class SoakConfig:
    """How long (simulated s), how fast, and when things are injected."""

    minutes: float = 30.0
    speed: float = 2.0
    stale_after_s: float | None = None  # simulated; default 5 s of wall time at ``speed``
    link_drop_s: float | None = None  # simulated; default 3 x the staleness limit, >= 30 s
    rest_s: float = 20.0  # simulated seconds on the ground between flights
    land_at_end: bool = True
    reboot: bool = True
    kill_serve: bool = True
    vehicles: tuple[str, ...] = ()  # names (nuisance_fleet.VEHICLES) to fly; () for all

    def fleet(self) -> tuple[VehicleDef, ...]:
        """The vehicles flown: a subset skips the injections whose vehicle is not in it (the
        link drop needs the ArduCopter, the reboot the PX4 quad)."""
        return tuple(v for v in VEHICLES if not self.vehicles or v.name in self.vehicles)

    @property
    def length_s(self) -> float:
        return self.minutes * 60.0

    @property
    def stale_s(self) -> float:
        return self.stale_after_s if self.stale_after_s is not None else 5.0 * self.speed

    @property
    def drop_s(self) -> float:
        return self.link_drop_s if self.link_drop_s is not None else max(30.0, 3.0 * self.stale_s)


@dataclass
class Events:
    """What was injected, in serve's store terms (threat ids seen before/after each window)."""

    log: list[str] = field(default_factory=list)
    cut_window: tuple[set[str], set[str]] | None = None  # threat ids before the cut, after
    reboot_window: tuple[set[str], set[str]] | None = None
    serve_killed: int = 0
    flight_errors: list[str] = field(default_factory=list)
    t0: float = field(default_factory=time.monotonic)

    def say(self, text: str) -> None:
        line = f"[{time.monotonic() - self.t0:7.1f} s] {text}"
        self.log.append(line)
        print(line, file=sys.stderr, flush=True)


def _write_config(path: Path, cfg: SoakConfig) -> Path:
    links = ["udpin:127.0.0.1:14550"]
    for v in cfg.fleet():
        if v.autopilot == "ardupilot":
            port = CUT_PORT if v.airframe == "copter" else v.serial1_port
            links.append(f"tcp:127.0.0.1:{port}")
    quoted = ", ".join(f'"{link}"' for link in links)
    path.write_text(
        f"""
[airspace]
origin_lat_deg = {ORIGIN[0]}
origin_lon_deg = {ORIGIN[1]}
ground_elevation_amsl_m = {ORIGIN[2]}

[tracking]
stale_after_s = {cfg.stale_s}

[mavlink]
links = [{quoted}]
"""
    )
    return path


class Serve:
    """``gcs-utm serve --headless --auto-accept`` as a process over one store."""

    def __init__(self, workdir: Path, cfg: SoakConfig) -> None:
        self.db = workdir / "store.sqlite"
        self.log_path = workdir / "serve.log"
        self.config = _write_config(workdir / "serve.toml", cfg)
        self.speed = cfg.speed
        self.proc: subprocess.Popen[bytes] | None = None

    def start(self) -> None:
        with self.log_path.open("ab") as log:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "gcs_utm", "-v", "serve", "--headless", "--auto-accept",
                 "--config", str(self.config), "--db", str(self.db), "--speed", f"{self.speed:g}"],
                stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, cwd=REPO,
            )  # fmt: skip

    def kill9(self) -> None:
        assert self.proc is not None
        os.kill(self.proc.pid, signal.SIGKILL)
        self.proc.wait(10.0)

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(30.0)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10.0)

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def threat_ids(self) -> set[str]:
        return {str(r[0]) for r in rows(self.db, "SELECT id FROM threats")}


def _wait(cond: Callable[[], bool], timeout_s: float, what: str, serve: Serve) -> None:
    end = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > end:
            raise TimeoutError(f"timed out after {timeout_s:.0f} s: {what}")
        if not serve.alive():
            raise RuntimeError("gcs-utm serve exited")
        time.sleep(0.2)


def run_soak(cfg: SoakConfig, workdir: Path) -> dict[str, Any]:
    """Boot the fleet and serve, fly and inject for ``cfg.minutes`` simulated minutes, then
    judge every threat in the store (see the module docstring). Returns the report."""
    reason = unavailable_reason("px4") or unavailable_reason("ardupilot")
    if reason:
        raise RuntimeError(reason)
    workdir.mkdir(parents=True, exist_ok=True)
    ev = Events()
    serve = Serve(workdir, cfg)
    flyers = [
        Flyer(v, workdir, cfg.speed, cfg.rest_s, ev.say, land_before_stop=cfg.land_at_end)
        for v in cfg.fleet()
    ]
    copter = next((f for f in flyers if f.v.airframe == "copter"), None)
    cut: TcpCut | None = None
    threads: list[threading.Thread] = []
    try:
        for f in flyers:
            f.boot()  # one after the other: four booting at once starve each other
            ev.say(f"{f.v.name} ready")
        if copter is not None:
            cut = TcpCut(CUT_PORT, copter.v.serial1_port)
        serve.start()
        for f in flyers:
            t = threading.Thread(target=f.run, name=f.v.name, daemon=True)
            t.start()
            threads.append(t)
        try:  # the pilots wait for their operations to be filed, as the operator would
            _wait(lambda: len(rows(serve.db, "SELECT id FROM operations")) >= len(flyers),
                  120.0, "an operation for each vehicle", serve)  # fmt: skip
        except TimeoutError as exc:
            ev.say(f"{exc}: flying anyway")
        ev.t0 = time.monotonic()
        for f in flyers:
            f.go.set()
        _schedule(cfg, ev, serve, flyers, cut)
        for f in flyers:
            f.stop.set()
        if cfg.land_at_end:  # the longest mission, ArduPlane's, takes about 330 simulated s
            end = time.monotonic() + 600.0 / cfg.speed + 30.0
            for t in threads:
                t.join(max(0.0, end - time.monotonic()))
        ev.say("soak over")
        ev.flight_errors = [f.error for f in flyers if f.error]  # before the shutdown
    finally:
        for f in flyers:
            f.stop.set()
        serve.stop()
        for t in threads:
            t.join(10.0)
        for f in flyers:
            f.shutdown()
        if cut is not None:
            cut.close()
    return judge(serve, ev, flyers, cfg, copter.v.sys_id if copter is not None else None)


def _schedule(
    cfg: SoakConfig, ev: Events, serve: Serve, flyers: list[Flyer], cut: TcpCut | None
) -> None:
    """The injections, at their fractions of the simulated length (see the module)."""
    sim = lambda: (time.monotonic() - ev.t0) * cfg.speed  # noqa: E731
    copter = next((f for f in flyers if f.v.airframe == "copter"), None)
    quad = next((f for f in flyers if f.v.airframe == "quad"), None)
    pending = {"cut", "reboot", "kill"} - (set() if cfg.reboot else {"reboot"})
    if not cfg.kill_serve:
        pending.discard("kill")
    if copter is None or cut is None:
        pending.discard("cut")
    if quad is None:
        pending.discard("reboot")
    # past T only for an injection not done yet (the link drop waits for a flying copter)
    while sim() < cfg.length_s or (pending - {"reboot"} and sim() < 1.5 * cfg.length_s):
        if not serve.alive():
            raise RuntimeError("gcs-utm serve exited")
        if "cut" in pending and sim() >= 0.25 * cfg.length_s and copter and copter.airborne:
            assert cut is not None
            pending.discard("cut")
            before = serve.threat_ids()
            ev.say(f"link drop: {copter.v.name} cut for {cfg.drop_s:.0f} simulated s")
            cut.cut.set()
            time.sleep(cfg.drop_s / cfg.speed)
            cut.cut.clear()
            ev.say(f"link drop: {copter.v.name} restored ({cut.dropped_bytes} bytes dropped)")
            time.sleep(cfg.stale_s / cfg.speed)
            ev.cut_window = (before, serve.threat_ids())
        if "reboot" in pending and sim() >= 0.4 * cfg.length_s and quad is not None:
            pending.discard("reboot")
            quad.reboot_after_landing = True
            ev.say(f"reboot: {quad.v.name} at its next landing")
        if "kill" in pending and sim() >= 0.6 * cfg.length_s:
            pending.discard("kill")
            ev.say("serve: kill -9")
            serve.kill9()
            ev.serve_killed += 1
            time.sleep(2.0)
            serve.start()
            ev.say("serve: restarted on the same store")
        time.sleep(0.2)


def judge(
    serve: Serve, ev: Events, flyers: list[Flyer], cfg: SoakConfig, cut_sys_id: int | None
) -> dict[str, Any]:
    """Every threat in the store, classified (module docstring), and the verdict."""
    op_sys = {}
    for op_id, doc in rows(serve.db, "SELECT id, doc FROM operations"):
        op_sys[str(op_id)] = json.loads(str(doc)).get("sys_id")
    cut_new = ev.cut_window[1] - ev.cut_window[0] if ev.cut_window else set()
    threats = []
    for tid, kind, status, detected, doc in rows(
        serve.db, "SELECT id, kind, status, detected_at_s, doc FROM threats ORDER BY detected_at_s"
    ):
        d = json.loads(str(doc))
        sys_ids = [op_sys.get(str(u)) for u in d.get("uas_ids", [])]
        why = "false: not caused by an injection"
        expected = False
        if kind == "COMMUNICATION_FAILURE" and tid in cut_new and cut_sys_id in sys_ids:
            expected, why = True, "expected: the link drop"
        threats.append(
            {"id": tid, "kind": kind, "status": status, "detected_at_s": detected,
             "sys_ids": sys_ids, "message": d.get("message", ""), "expected": expected,
             "why": why}
        )  # fmt: skip
    by_kind: dict[str, dict[str, int]] = {}
    for t in threats:
        k = by_kind.setdefault(t["kind"], {"open": 0, "closed": 0})
        k["closed" if t["status"] == "closed" else "open"] += 1
    false = [t for t in threats if not t["expected"]]
    still_open = [t for t in threats if t["status"] != "closed"]
    drop_seen = any(t["expected"] for t in threats)
    quad = next((f for f in flyers if f.v.airframe == "quad"), None)
    problems = [f"{len(false)} false threat(s)"] if false else []
    if still_open:
        problems.append(f"{len(still_open)} threat(s) open at the end")
    if cut_sys_id is None:
        pass  # no ArduCopter in the fleet: no link drop
    elif ev.cut_window is None:
        problems.append("the link drop was not injected")
    elif not drop_seen:
        problems.append("the link drop raised no COMMUNICATION_FAILURE")
    if cfg.reboot and quad is not None and not quad.rebooted_at:
        problems.append("the reboot was not injected")
    if cfg.kill_serve and not ev.serve_killed:
        problems.append("serve was not killed")
    problems += ev.flight_errors
    if cfg.land_at_end:
        problems += [f"{f.v.name} did not land by the end" for f in flyers if f.airborne]
    audit = rows(
        serve.db,
        "SELECT action, subject, detail FROM audit WHERE action LIKE 'threat%' ORDER BY seq",
    )
    return {
        "verdict": "fail" if problems else "pass",
        "problems": problems,
        "speed": cfg.speed,
        "simulated_minutes": cfg.minutes,
        "stale_after_s": cfg.stale_s,
        "link_drop_s": cfg.drop_s,
        "threats_by_kind": by_kind,
        "threats": threats,
        "threat_audit": [list(map(str, a)) for a in audit],
        "recommendations": [
            list(map(str, r))
            for r in rows(serve.db, "SELECT id, version, state FROM recommendations")
        ],
        "flights": {f.v.name: {"takeoffs": f.takeoffs, "landings": f.flights} for f in flyers},
        "injections": {
            "link_drop": ev.cut_window is not None,
            "reboot": bool(quad is not None and quad.rebooted_at),
            "serve_kill9": ev.serve_killed,
        },
        "events": ev.log,
    }


def _interrupt(signum: int, _frame: object) -> None:
    raise KeyboardInterrupt(f"signal {signum}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tests.autopilot.nuisance", description=__doc__)
    ap.add_argument("--minutes", type=float, default=30.0, help="simulated length (default 30)")
    ap.add_argument("--speed", type=float, default=2.0, help="speed factor of every autopilot")
    ap.add_argument("--workdir", type=Path, default=None, help="store, logs (default: a temp dir)")
    ap.add_argument("--json", type=Path, default=None, help="also write the report here")
    names = [v.name for v in VEHICLES]
    ap.add_argument(
        "--vehicles", default="", help=f"comma-separated subset of {','.join(names)} (default all)"
    )
    args = ap.parse_args(argv)
    chosen = tuple(n for n in args.vehicles.split(",") if n)
    unknown = sorted(set(chosen) - set(names))
    if unknown:
        ap.error(f"--vehicles: unknown {', '.join(unknown)}; choose from {', '.join(names)}")
    # SIGTERM (and SIGINT, ignored in a background job) stop the soak through its cleanup
    signal.signal(signal.SIGTERM, _interrupt)
    if args.minutes <= 0 or args.speed <= 0:
        ap.error("--minutes and --speed must be positive")
    workdir = (
        args.workdir
        or Path(os.environ.get("GCS_UTM_SITL_ROOT", "/var/tmp")) / f"gcs-utm-nuisance-{os.getpid()}"
    )
    cfg = SoakConfig(minutes=args.minutes, speed=args.speed, vehicles=chosen)
    report = run_soak(cfg, workdir)
    report["workdir"] = str(workdir)
    text = json.dumps(report, indent=2)
    print(text)
    if args.json is not None:
        args.json.write_text(text)
    return 0 if report["verdict"] == "pass" else 1


if __name__ == "__main__":
    sys.exit(main())
