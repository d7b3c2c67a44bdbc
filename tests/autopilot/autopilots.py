"""Real PX4 and ArduPilot SITL processes for tests (the builds in ``../shared``).

The real autopilots bind fixed ports (PX4 instance i: UDP 18570+i -> 14550, 14580+i;
ArduPilot instance i: TCP 5760+10i), so they only run inside a private network namespace:
``tests/check.sh`` runs pytest under ``unshare --net`` with ``lo`` up, and ``tests/netns.sh``
does the same for a single command (``bash tests/netns.sh .venv/bin/python -m pytest ...``).

PX4's build tree ships its module commands (``px4-param``, ``px4-commander``, ...) as symlinks
to ``px4``; a copy of ``../shared`` may hold them flattened into plain 3-byte files without
execute bits, and then PX4's start script fails ("px4-param: Permission denied", "no autostart
file found"). :func:`px4_bin_dir` therefore lays a private ``bin/`` with a copy of the binary
and fresh symlinks; nothing in ``../shared`` is written.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import shutil
import signal
import subprocess
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tests.autopilot.pilot import close_open_links

REPO = Path(__file__).resolve().parents[2]
SHARED = Path(os.environ.get("GCS_UTM_SHARED", REPO.parent / "shared"))
PX4_DIR = SHARED / "px4-sitl"
ARDUPILOT_DIR = SHARED / "ardupilot-sitl"

PX4_AIRFRAMES = {"quad": (10040, "sihsim_quadx"), "plane": (10041, "sihsim_airplane")}
ARDUPILOT_VEHICLES = {
    "copter": ("arducopter", "+", "copter.parm"),
    "plane": ("arduplane", "plane", "plane.parm"),
}

# What PX4 v1.15.2's SIH plane (airframe 10041) needs to fly, set over MAVLink after boot (each
# takes effect at once). Measured here, and PX4 PR 24034 (after v1.15.2) names the same faults:
# - the airframe drives outputs 3-6 (aileron, elevator, rudder, motor) while SIH reads roll,
#   pitch, yaw and throttle from outputs 1-4: outputs 1-2 stay unassigned (NaN), the simulation
#   diverges the moment it is armed ("angular velocity no longer valid", flight termination,
#   "Disarmed by lockdown");
# - the roll and pitch torques of the aileron and elevator are reversed: it rolls over right
#   after lift-off ("Attitude failure (roll)", failsafe, "Disarmed by failsafe");
# - SIH holds a grounded plane's pitch at 0 and, at SIH_T_MAX 6 N, it tops out at 12 m/s on the
#   runway without lifting off: 12 N gets it airborne at about 15 m/s;
# - gcs-utm's plans end at their last waypoint (no landing pattern), which PX4's fixed-wing
#   default MIS_TKO_LAND_REQ 2 refuses ("Landing waypoint/pattern required").
PX4_SIH_PLANE_PARAMS: dict[str, float | int] = {
    "PWM_MAIN_FUNC1": 201,  # servo 1: aileron
    "PWM_MAIN_FUNC2": 202,  # servo 2: elevator
    "PWM_MAIN_FUNC3": 203,  # servo 3: rudder
    "PWM_MAIN_FUNC4": 101,  # motor 1
    "PWM_MAIN_FUNC5": 0,
    "PWM_MAIN_FUNC6": 0,
    "CA_SV_CS0_TRQ_R": 0.5,  # was -0.5
    "CA_SV_CS1_TRQ_P": -1.0,  # was 1
    "SIH_T_MAX": 12.0,  # the simulated motor's thrust, N (was 6)
    "MIS_TKO_LAND_REQ": 0,  # no landing required in a mission
}

SITL_ROOT = Path(os.environ.get("GCS_UTM_SITL_ROOT", "/var/tmp"))
_serial = itertools.count()

# PX4 SIH's default start point (SIH_LOC_LAT0/LON0/H0 in v1.15).
PX4_DEFAULT_HOME = (45.4671160, -73.7578370, 32.34)
# ArduPilot run.sh's default home: lat, lon, ground AMSL m, heading deg.
ARDUPILOT_DEFAULT_HOME = (40.6597, -3.5969, 675.0, 0.0)


def private_netns() -> bool:
    """True when this process's network namespace has no interface but loopback (what
    ``unshare --net`` gives): nothing else on the machine can hold the autopilots' ports."""
    try:
        lines = Path("/proc/self/net/dev").read_text().splitlines()[2:]
    except OSError:
        return False
    names = {line.split(":", 1)[0].strip() for line in lines if ":" in line}
    return names == {"lo"}


def unavailable_reason(kind: str) -> str:
    """Why a real ``kind`` ("px4" or "ardupilot") SITL cannot run here, or '' when it can."""
    folder = PX4_DIR if kind == "px4" else ARDUPILOT_DIR
    if not folder.is_dir():
        return f"no real {kind} SITL: {folder} is absent (it ships in ../shared beside the clone)"
    if not private_netns():
        return (
            f"real {kind} SITL binds fixed ports: run pytest in a private network namespace "
            "(bash tests/check.sh, or bash tests/netns.sh <command>)"
        )
    return ""


def px4_bin_dir(root: Path) -> Path:
    """A private PX4 ``bin/`` under ``root`` (copied once per root): the binary, its module
    symlinks and ``px4-alias.sh``."""
    out = root / "px4-bin"
    if (out / "px4").exists():
        return out
    out.mkdir(parents=True, exist_ok=True)
    src = PX4_DIR / "bin"
    shutil.copy2(src / "px4", out / "px4")
    (out / "px4").chmod(0o755)
    for f in src.iterdir():
        if f.name == "px4-alias.sh":
            shutil.copy2(f, out / f.name)
            (out / f.name).chmod(0o644)
        elif f.name.startswith("px4-"):
            (out / f.name).symlink_to("px4")
    return out


# PX4's SITL start script boosts seven GCS-link streams to 50 Hz for a local ground station
# (px4-rc.mavlink: ATTITUDE, ATTITUDE_QUATERNION, ATTITUDE_TARGET, LOCAL_POSITION_NED,
# POSITION_TARGET_LOCAL_NED, SERVO_OUTPUT_RAW, GLOBAL_POSITION_INT; RC_CHANNELS at 20 Hz):
# 367 datagrams/s measured at speed 1, times the speed factor (1,850/s a PX4 at 5). gcs-utm
# reads only GLOBAL_POSITION_INT of them; on a loaded 2-core machine the rest flooded its
# reader (docs/autopilots.md, "PX4 SITL under load"). The tests' PX4 keeps GLOBAL_POSITION_INT
# at 50 Hz (the tests compare PX4's own positions 0.05 s apart) and leaves the others at the
# rates of PX4's normal GCS mode, as a telemetry radio link has them.
PX4_GCS_STREAMS_KEPT = ("GLOBAL_POSITION_INT",)


def px4_etc_dir(root: Path) -> Path:
    """A private copy of PX4's ``etc/`` under ``root`` (made once per root) whose GCS link
    streams at 50 Hz only :data:`PX4_GCS_STREAMS_KEPT`."""
    out = root / "px4-etc"
    rc = out / "init.d-posix" / "px4-rc.mavlink"
    if rc.exists():
        return out
    shutil.copytree(PX4_DIR / "etc", out, dirs_exist_ok=True)
    kept = [
        line
        for line in rc.read_text().splitlines(keepends=True)
        if not _dropped_stream(line.strip())
    ]
    rc.write_text("".join(kept))
    return out


def _dropped_stream(line: str) -> bool:
    """A ``mavlink stream`` line of px4-rc.mavlink the tests' PX4 leaves out: the GCS link's
    boosted streams but :data:`PX4_GCS_STREAMS_KEPT`, and the SIH display link's (200 Hz of
    HIL_ACTUATOR_CONTROLS to a jMAVSim display nobody runs: CPU PX4 needs under load)."""
    if not line.startswith("mavlink stream "):
        return False
    if "$udp_sihsim_port_local" in line:
        return True
    gcs = "-u $udp_gcs_port_local" in line
    return gcs and not any(f" -s {name} " in line for name in PX4_GCS_STREAMS_KEPT)


def launcher(
    kind: str, start: Callable[..., SitlProcess], root: Path, failed: Callable[[], bool]
) -> Iterator[Callable[..., SitlProcess]]:
    """The body of the ``px4``/``ardupilot`` fixtures: yields ``launch(**kwargs)``, which starts
    an autopilot with ``start(root, **kwargs)``. When the test ends, passed or failed, the pilot
    links it left open are closed and every process it started is stopped (each one even if
    stopping another raised); with ``failed()`` their logs are printed."""
    started: list[SitlProcess] = []

    def launch(**kwargs: Any) -> SitlProcess:
        p = start(root, **kwargs)
        started.append(p)
        return p

    try:
        yield launch
    finally:
        close_open_links()
        errors: list[BaseException] = []
        for p in started:
            try:
                p.stop()
            except BaseException as exc:  # stop the others first, then raise it
                errors.append(exc)
            if failed():
                print(f"\n=== {kind} instance {p.instance} logs\n{p.log_tail()}")
        if errors:
            raise errors[0]


@dataclass
class SitlProcess:
    """One running autopilot. ``workdir`` holds its parameters and logs."""

    kind: str
    instance: int
    sys_id: int
    workdir: Path
    proc: subprocess.Popen[bytes]
    log_paths: list[Path] = field(default_factory=list)
    owned_dir: Path | None = None  # removed by stop() (after its logs are kept)
    saved_logs: str = ""

    @property
    def alive(self) -> bool:
        return self.proc.poll() is None

    def log_tail(self, n_chars: int = 3000) -> str:
        """The end of its logs, for failure messages."""
        if self.saved_logs:
            return self.saved_logs
        parts = []
        for p in self.log_paths:
            with contextlib.suppress(OSError):
                parts.append(f"--- {p.name}\n{p.read_text(errors='replace')[-n_chars:]}")
        return "\n".join(parts)

    def stop(self, timeout_s: float = 10.0) -> None:
        """SIGTERM, then SIGKILL after ``timeout_s``; always reaps the process. With
        ``GCS_UTM_KEEP_SITL_DIRS`` set, its working directory is copied there once stopped."""
        if self.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(timeout=timeout_s)
        keep = os.environ.get("GCS_UTM_KEEP_SITL_DIRS")  # its console, logs, ULog: kept
        if keep and self.workdir.exists():
            name = f"{self.kind}-{self.instance}-{os.getpid()}-{time.time():.0f}"
            shutil.copytree(self.workdir, Path(keep) / name, dirs_exist_ok=True)
        if self.owned_dir is not None and self.owned_dir.exists():
            self.saved_logs = self.log_tail()
            shutil.rmtree(self.owned_dir, ignore_errors=True)


def start_px4(
    root: Path,
    *,
    instance: int = 0,
    airframe: str = "quad",
    home: tuple[float, float] | None = None,
    speed: float = 1.0,
    workdir: Path | None = None,
) -> SitlProcess:
    """Start PX4 SITL instance ``instance`` (MAV_SYS_ID instance+1; GCS link from UDP
    18570+instance to 127.0.0.1:14550). ``home`` is (lat_deg, lon_deg); the ground stays at
    SIH_LOC_H0 (32.34 m AMSL by default). ``speed`` is PX4_SIM_SPEED_FACTOR."""
    if airframe not in PX4_AIRFRAMES:
        raise ValueError(f"PX4 airframe must be one of {sorted(PX4_AIRFRAMES)}, got {airframe!r}")
    autostart, model = PX4_AIRFRAMES[airframe]
    private_tmp = _private_tmp_works()
    owned = None
    if workdir is None and private_tmp:
        owned = SITL_ROOT / f"gcs-utm-px4-{os.getpid()}-{next(_serial)}"
    wd = workdir or owned or root / f"px4-{instance}"
    wd.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ)
    env.update(
        PX4_SYS_AUTOSTART=str(autostart),
        PX4_SIMULATOR="sihsim",
        PX4_SIM_MODEL=model,
        PX4_SIM_SPEED_FACTOR=f"{speed:g}",
    )
    if home is not None:
        env["PX4_HOME_LAT"] = str(round(home[0] * 1e7))
        env["PX4_HOME_LON"] = str(round(home[1] * 1e7))
    out, err = wd / "out.log", wd / "err.log"
    private = owned or (wd.parent if workdir and private_tmp else root)
    binary, etc = px4_bin_dir(private) / "px4", px4_etc_dir(private)
    # Real paths: a symlink under /tmp (e.g. ../shared) would dangle under PX4's own /tmp.
    binary, etc, wd = binary.resolve(), etc.resolve(), wd.resolve()
    argv = [str(binary), "-i", str(instance), "-d", str(etc)]
    if private_tmp:
        argv = private_tmp_argv(argv, keep=(binary.parent, etc, wd), cwd=wd)
    with out.open("wb") as o, err.open("wb") as e:
        proc = subprocess.Popen(
            argv,
            cwd=wd,
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=o,
            stderr=e,
            start_new_session=True,
        )
    return SitlProcess("px4", instance, instance + 1, wd, proc, [out, err], owned)


# PX4 keeps its lock socket and lock file in /tmp (``/tmp/px4-sock-I``, ``/tmp/px4_lock-I``):
# two PX4 instance I on one machine (two test runs, two helpers) collide there whatever
# their network namespaces. Each PX4 therefore runs in a private mount namespace with a fresh
# tmpfs on /tmp. Whatever PX4 needs that lives under /tmp itself (a clone with ../shared in a
# temporary folder, pytest's tmp_path) is bound back at the same path inside that tmpfs: the
# shell cds to /tmp first, so "." still names the real /tmp once the tmpfs hides it.
# Arguments: $1 the directory to run in, $2 the count n of paths to keep (relative to /tmp),
# then the n paths, then the command.
_PRIVATE_TMP_SCRIPT = """set -e
wd=$1; n=$2; shift 2
cd /tmp
mount -t tmpfs gcs-utm-px4-tmp /tmp
while [ "$n" -gt 0 ]; do
  mkdir -p "/tmp/$1"
  mount --no-canonicalize --bind "./$1" "/tmp/$1"
  n=$((n - 1)); shift
done
cd "$wd"
exec "$@"
"""


def private_tmp_argv(argv: list[str], *, keep: Sequence[Path], cwd: Path) -> list[str]:
    """``argv`` run with a fresh tmpfs on /tmp in a private mount namespace, in ``cwd``; the
    directories ``keep`` (and ``cwd``) stay reachable at their paths when under /tmp."""
    tmp = Path(os.path.realpath("/tmp"))
    under: list[Path] = []
    for path in sorted(
        {Path(os.path.realpath(p)) for p in (*keep, cwd)}, key=lambda p: len(p.parts)
    ):
        if path.is_relative_to(tmp) and not any(path.is_relative_to(u) for u in under):
            under.append(path)
    rel = [str(p.relative_to(tmp)) for p in under]
    return [
        "unshare", "--mount", "--propagation", "private",
        "sh", "-c", _PRIVATE_TMP_SCRIPT, "gcs-utm-px4-tmp", str(cwd), str(len(rel)), *rel, *argv,
    ]  # fmt: skip


def _private_tmp_works() -> bool:
    """Whether PX4 can get its own /tmp here (root, or user namespaces, and unshare)."""
    argv = private_tmp_argv(["true"], keep=(), cwd=Path("/"))
    try:
        done = subprocess.run(argv, capture_output=True, timeout=10, check=False)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return done.returncode == 0


def start_ardupilot(
    root: Path,
    *,
    instance: int = 0,
    vehicle: str = "copter",
    home: tuple[float, float, float, float] = ARDUPILOT_DEFAULT_HOME,
    speed: float = 1.0,
    workdir: Path | None = None,
    defaults: tuple[Path, ...] = (),
    extra_args: tuple[str, ...] = (),
) -> SitlProcess:
    """Start ArduPilot SITL instance ``instance`` (SYSID_THISMAV instance+1; MAVLink on TCP
    5760+10*instance). It waits for a client on that port before its clock starts.
    ``home`` is (lat_deg, lon_deg, ground_amsl_m, heading_deg); ``defaults`` are parameter
    files loaded after the vehicle's, ``extra_args`` more command-line options (e.g.
    ``--serial5=sim:adsb``)."""
    if vehicle not in ARDUPILOT_VEHICLES:
        raise ValueError(
            f"ArduPilot vehicle must be one of {sorted(ARDUPILOT_VEHICLES)}, got {vehicle!r}"
        )
    binary, model, parm = ARDUPILOT_VEHICLES[vehicle]
    wd = workdir or root / f"ardupilot-{instance}"
    wd.mkdir(parents=True, exist_ok=True)
    log = wd / "out.log"
    home_text = ",".join(f"{v:g}" for v in home)
    with log.open("wb") as o:
        proc = subprocess.Popen(
            [
                str(ARDUPILOT_DIR / "bin" / binary),
                "--model",
                model,
                "--speedup",
                f"{speed:g}",
                "--defaults",
                ",".join([str(ARDUPILOT_DIR / parm), *map(str, defaults)]),
                "--home",
                home_text,
                "-I",
                str(instance),
                "--sysid",
                str(instance + 1),
                *extra_args,
            ],
            cwd=wd,
            stdin=subprocess.DEVNULL,
            stdout=o,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
    return SitlProcess("ardupilot", instance, instance + 1, wd, proc, [log])


def wait_tcp_listening(port: int, timeout_s: float = 20.0) -> None:
    """Block until something listens on 127.0.0.1:``port`` (ArduPilot's SERIAL0), without
    connecting: a connect would take SITL's single client slot."""
    deadline = time.monotonic() + timeout_s
    hex_port = f":{port:04X}"
    while time.monotonic() < deadline:
        with contextlib.suppress(OSError):
            for line in Path("/proc/net/tcp").read_text().splitlines()[1:]:
                cols = line.split()
                if cols[1].endswith(hex_port) and cols[3] == "0A":  # 0A: LISTEN
                    return
        time.sleep(0.05)
    raise TimeoutError(f"nothing listens on TCP {port} after {timeout_s} s")
