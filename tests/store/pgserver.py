"""The private PostgreSQL server of the tests: Debian's binaries (``/usr/lib/postgresql/*/bin``,
installed by ``.ci/run``), ``initdb`` into a temporary folder, listening on a unix socket in
it only (no TCP port to collide with another run). PostgreSQL refuses to run as root, so as
root the server runs as the ``postgres`` user the Debian package creates.

``start()`` returns None with the reason when no server can be started here; the test fixtures
then skip with that reason. Not shipped and not for production: a deployment runs its own
PostgreSQL (docs/scale-out.md). From a checkout, ``python -m tests.store.pgserver`` starts a
durable one for ``gcs-utm bench cluster --url`` and prints its URL until Ctrl-C.
"""

from __future__ import annotations

import contextlib
import glob
import importlib.util
import itertools
import os
import pwd
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

_counter = itertools.count(1)


def _bindir() -> Path | None:
    found = sorted(
        glob.glob("/usr/lib/postgresql/*/bin/initdb"),
        key=lambda p: (
            int(Path(p).parent.parent.name) if Path(p).parent.parent.name.isdigit() else 0
        ),
    )
    if found:
        return Path(found[-1]).parent
    initdb = shutil.which("initdb")
    return Path(initdb).parent if initdb else None


@dataclass
class PgServer:
    """A running private server; ``url(db)`` is a libpq URL over its unix socket."""

    bindir: Path
    root: Path
    proc: subprocess.Popen[bytes]
    argv: list[str]
    uid: int | None
    gid: int | None
    user: str = "gcs"
    admin_db: str = "postgres"
    _dbs: list[str] = field(default_factory=list)

    @property
    def socket_dir(self) -> Path:
        return self.root

    def url(self, db: str) -> str:
        return f"postgresql://{self.user}@/{db}?host={self.socket_dir}"

    def create_database(self, prefix: str = "t") -> str:
        """A new empty database; returns its URL."""
        import psycopg

        name = f"{prefix}_{os.getpid()}_{next(_counter)}"
        with psycopg.connect(self.url(self.admin_db), autocommit=True) as conn:
            conn.execute(f'CREATE DATABASE "{name}"'.encode())
        self._dbs.append(name)
        return self.url(name)

    def halt(self) -> None:
        """Stop the server ("fast" shutdown: clients are disconnected), keeping its data."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10)

    def restart(self) -> None:
        """Stop, then start again on the same data (what a database failover looks like to
        its clients: every connection is cut)."""
        self.halt()
        self.proc = _spawn(self.argv, self.root, self.uid, self.gid)
        if not _wait_ready(self, 30.0):
            raise RuntimeError(f"postgres did not come back: {self.log_tail()}")

    def log_tail(self) -> str:
        return (self.root / "server.log").read_text(errors="replace")[-500:].strip()

    def stop(self) -> None:
        self.halt()
        shutil.rmtree(self.root, ignore_errors=True)


def _spawn(
    argv: list[str], root: Path, uid: int | None, gid: int | None
) -> subprocess.Popen[bytes]:
    with open(root / "server.log", "ab") as log:
        return subprocess.Popen(
            argv, stdout=log, stderr=subprocess.STDOUT, cwd=root, user=uid, group=gid
        )


def _wait_ready(server: PgServer, timeout_s: float) -> bool:
    import psycopg

    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if server.proc.poll() is not None:
            return False
        with contextlib.suppress(psycopg.OperationalError):
            psycopg.connect(server.url("postgres"), connect_timeout=2).close()
            return True
        time.sleep(0.1)
    return False


def _as_user() -> tuple[int | None, int | None, str | None]:
    """(uid, gid) of the ``postgres`` user when root must drop to it (None, None when not
    root), and the reason when it cannot."""
    if os.geteuid() != 0:
        return None, None, None
    try:
        pw = pwd.getpwnam("postgres")
    except KeyError:
        return None, None, "running as root and there is no 'postgres' user to run the server as"
    return pw.pw_uid, pw.pw_gid, None


def start(*, durable: bool = False) -> tuple[PgServer | None, str]:
    """Start a private server. ``durable`` False turns fsync off (the tests kill clients, not
    the server, so the server's own disk flushes only cost time on a shared machine)."""
    if importlib.util.find_spec("psycopg") is None:
        return None, "psycopg is not installed (pip install 'gcs-utm[postgres]')"
    bindir = _bindir()
    if bindir is None:
        return None, "no PostgreSQL server binaries (apt-get install postgresql)"
    uid, gid, why = _as_user()
    if why is not None:
        return None, why
    root = Path(tempfile.mkdtemp(prefix="gcs-pg-"))
    if uid is not None and gid is not None:
        os.chown(root, uid, gid)
    data = root / "data"
    init = subprocess.run(
        [
            str(bindir / "initdb"),
            "-D",
            str(data),
            "-A",
            "trust",
            "-U",
            "gcs",
            "-E",
            "UTF8",
            "--no-sync",
            "--no-instructions",
        ],
        capture_output=True,
        cwd=root,
        check=False,
        user=uid,
        group=gid,
    )
    if init.returncode != 0:
        shutil.rmtree(root, ignore_errors=True)
        return None, f"initdb failed: {init.stderr.decode(errors='replace').strip()[-300:]}"
    opts = ["-c", "listen_addresses=", "-k", str(root), "-c", "max_connections=200"]
    if not durable:
        opts += ["-c", "fsync=off", "-c", "full_page_writes=off"]
    argv = [str(bindir / "postgres"), "-D", str(data), *opts]
    server = PgServer(
        bindir=bindir, root=root, proc=_spawn(argv, root, uid, gid), argv=argv, uid=uid, gid=gid
    )
    if _wait_ready(server, 30.0):
        return server, ""
    why = f"postgres did not start (exit {server.proc.poll()}): {server.log_tail()}"
    server.stop()
    return None, why


def main() -> int:
    """Start a durable private server with one database, print its URL and keep it until
    Ctrl-C or SIGTERM (a PostgreSQL for ``gcs-utm bench cluster --url``)."""
    # also when started in the background, where SIGINT comes ignored
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    server, why = start(durable=True)
    if server is None:
        print(f"no PostgreSQL: {why}", file=sys.stderr)
        return 1
    try:
        print(server.create_database("bench"), flush=True)
        server.proc.wait()
    except KeyboardInterrupt:
        pass
    finally:
        server.stop()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
