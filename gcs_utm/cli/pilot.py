"""``gcs-utm pilot --operator NAME``: a remote pilot station on the terminal.

It runs the project's reference client (:class:`adapters.mqtt.station.PilotStation`, see
docs/mqtt.md "Answer delivery") as operator NAME with the broker settings of the ``[mqtt]``
section of ``--config`` (the user name and password there are the pilot's own broker
credentials; an empty user name means the operator name). It prints each recommendation
addressed to the operator as it arrives (:mod:`gcs_utm.cli.pilot_text`), reads ``a`` /
``a N`` / ``r`` from stdin, sends the answer and prints gcs-utm's acknowledgement; the
station keeps re-sending an unacknowledged answer, across broker restarts. Operator commands
are typed too: ``hold UAS1`` (``land``, ``rtl``, ``resume``) asks for a confirmation, ``y``
sends it on the operator's ``commands`` topic and gcs-utm's outcome is printed. End of input
(Ctrl-D) or Ctrl-C exits with 0.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import sys
import threading
from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # the command imports them when it runs: `--help` stays fast
    from adapters.mqtt.config import MqttConfig
    from adapters.mqtt.station import PilotStation
    from gcs_utm.clock import Clock

Write = Callable[[str], None]

# how often the connection state is looked at (a message is printed on each change)
_WATCH_S = 0.2


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "pilot", help="remote pilot station: show recommendations over MQTT and answer them"
    )
    p.add_argument("--operator", required=True, help="operator name (its broker user name)")
    p.add_argument("--config", type=Path, default=None, help="settings TOML ([mqtt] section)")
    p.add_argument(
        "--resend-s",
        type=float,
        default=5.0,
        help="re-send an unacknowledged answer this often (s, default 5)",
    )
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import dataclasses

    from adapters.mqtt.topics import valid_operator
    from gcs_utm.config import ConfigError
    from gcs_utm.settings import load_settings

    if not valid_operator(args.operator):
        print(
            f"gcs-utm pilot: --operator {args.operator!r}: expected letters, digits, '_', '.' "
            "or '-' (the operator's broker user name and topic level)",
            file=sys.stderr,
        )
        return 2
    if not args.resend_s > 0.0:
        print(f"gcs-utm pilot: --resend-s must be positive, got {args.resend_s}", file=sys.stderr)
        return 2
    try:
        try:
            mqtt = load_settings(args.config).mqtt
        except ConfigError as exc:
            print(f"gcs-utm pilot: {exc}", file=sys.stderr)
            return 2
        if not mqtt.username:
            mqtt = dataclasses.replace(mqtt, username=args.operator)
        return asyncio.run(_main(mqtt, args.operator, args.resend_s))
    except KeyboardInterrupt:  # Ctrl-C: the station has been closed by asyncio.run
        print("\npilot station stopped", flush=True)
        return 0


def _write(text: str) -> None:
    print(text, flush=True)


async def _main(config: MqttConfig, operator: str, resend_s: float) -> int:
    lines: asyncio.Queue[str | None] = asyncio.Queue()
    _read_stdin_into(lines, asyncio.get_running_loop())
    return await run_pilot(config, operator, lines, _write, resend_s=resend_s)


def _read_stdin_into(lines: asyncio.Queue[str | None], loop: asyncio.AbstractEventLoop) -> None:
    """Read stdin lines in a daemon thread (a blocked read must not keep the process alive
    at exit; a terminal, pipe or file all work), None at end of input."""

    def read() -> None:
        try:
            for line in sys.stdin:
                loop.call_soon_threadsafe(lines.put_nowait, line)
            loop.call_soon_threadsafe(lines.put_nowait, None)
        except RuntimeError:  # the loop has closed (Ctrl-C): nobody to hand the line to
            return

    threading.Thread(target=read, name="pilot-stdin", daemon=True).start()


async def run_pilot(
    config: MqttConfig,
    operator: str,
    lines: asyncio.Queue[str | None],
    write: Write,
    *,
    resend_s: float = 5.0,
    clock: Clock | None = None,
) -> int:
    """The pilot station until ``lines`` gives None (end of input): 0. ``clock`` stamps the
    answers (wall-clock time by default)."""
    from adapters.mqtt.station import PilotStation
    from gcs_utm.clock import RealClock

    station_clock = clock or RealClock()
    async with PilotStation(config, operator, station_clock, resend_s=resend_s) as station:
        console = _Console(station, write)
        watcher = asyncio.create_task(_watch(station, config, write))
        try:
            await console.serve(lines)
        finally:
            watcher.cancel()
            await console.close()
            with contextlib.suppress(asyncio.CancelledError):
                await watcher
    write("pilot station stopped")
    return 0


async def _watch(station: PilotStation, config: MqttConfig, write: Write) -> None:
    """One line on each change of the connection: connected, or cannot connect to the
    broker (the station keeps retrying with backoff)."""
    where = f"{config.host}:{config.port}"
    write(f"connecting to the MQTT broker {where} as operator {station.operator} ...")
    was: bool | None = None
    while True:
        now = station.connected
        if now and was is not True:
            write(f"connected to {where}; waiting for recommendations")
        elif not now and station.last_error and was is not False:
            write(
                f"cannot connect to the MQTT broker {where}: {station.last_error}; "
                "retrying (Ctrl-D or Ctrl-C to quit)"
            )
        if now or station.last_error:
            was = now
        await asyncio.sleep(_WATCH_S)


class _Console:
    """Shows recommendations and state changes, takes typed answers; each answer is
    delivered by a task of its own (it may wait for gcs-utm)."""

    def __init__(self, station: PilotStation, write: Write) -> None:
        self._station = station
        self._write = write
        self._current: dict[str, Any] | None = None  # the recommendation an answer is for
        self._versions: dict[str, int] = {}  # the latest version shown, by recommendation id
        self._deliveries: set[asyncio.Task[None]] = set()
        self._armed: tuple[str, str] | None = None  # an operator command waiting for its yes

    async def serve(self, lines: asyncio.Queue[str | None]) -> None:
        station = self._station
        rec_get = asyncio.create_task(station.recommendations.get())
        status_get = asyncio.create_task(station.statuses.get())
        line_get = asyncio.create_task(lines.get())
        try:
            while True:
                waiting = {rec_get, status_get, line_get}
                done, _ = await asyncio.wait(waiting, return_when=asyncio.FIRST_COMPLETED)
                if rec_get in done:
                    self.show(rec_get.result())
                    rec_get = asyncio.create_task(station.recommendations.get())
                if status_get in done:
                    self.on_status(status_get.result())
                    status_get = asyncio.create_task(station.statuses.get())
                if line_get in done:
                    line = line_get.result()
                    if line is None:
                        return
                    self.on_line(line)
                    line_get = asyncio.create_task(lines.get())
        finally:
            for task in (rec_get, status_get, line_get):
                task.cancel()

    def show(self, rec: dict[str, Any]) -> None:
        from gcs_utm.cli.pilot_text import recommendation_text

        rec_id = str(rec.get("recommendation_id"))
        version = int(rec.get("version", -1))
        shown = self._versions.get(rec_id)
        if shown is not None and version <= shown:
            return  # re-published after a reconnect (or older): already shown
        if shown is not None:
            self._write(f"recommendation {rec_id} v{shown} superseded by v{version}")
        self._current = rec
        self._versions[rec_id] = version
        self._write(recommendation_text(rec))

    def on_status(self, status: dict[str, Any]) -> None:
        from gcs_utm.cli.pilot_text import status_text

        rec_id = str(status.get("recommendation_id"))
        if rec_id not in self._versions:
            return  # not one this station showed (e.g. before it started)
        self._write(status_text(status))
        current = self._current
        if (
            current is not None
            and str(current.get("recommendation_id")) == rec_id
            and current.get("version") == status.get("version")
            and status.get("state") in ("expired", "superseded")
        ):
            self._current = None

    def on_line(self, line: str) -> None:
        from gcs_utm.cli.pilot_text import HELP, alternative_index, parse_choice

        if not line.strip() or self._operator_command(line.strip()):
            return
        rec = self._current
        if line.strip().lower() in ("d", "details"):
            from gcs_utm.cli.pilot_text import recommendation_text

            self._write(recommendation_text(rec, details=True) if rec else "nothing shown")
            return
        try:
            choice = parse_choice(line)
            if rec is None:
                self._write(f"no recommendation to answer now; {HELP}")
                return
            index = alternative_index(rec, choice.row) if choice.accept else None
        except ValueError as exc:
            self._write(str(exc))
            return
        task = asyncio.create_task(self._deliver(rec, choice.accept, index))
        self._deliveries.add(task)
        task.add_done_callback(self._deliveries.discard)

    def _operator_command(self, text: str) -> bool:
        """``hold UAS1`` (``land``, ``rtl``, ``resume``) then ``y``: True when the line was
        about an operator command (asked, sent or cancelled)."""
        from gcs_utm.services.operator_commands import parse_command_line

        armed, self._armed = self._armed, None
        if armed is not None:
            if text.lower() in ("y", "yes"):
                self._start(self._command(*armed))
                return True
            self._write(f"{armed[0]} {armed[1]} cancelled")
            if text.lower() in ("n", "no"):
                return True
        parsed = parse_command_line(text)
        if parsed is None:
            return False
        self._armed = parsed
        self._write(f"{parsed[0]} {parsed[1]}? type y + Enter to send it, anything else cancels")
        return True

    def _start(self, coro: Coroutine[Any, Any, None]) -> None:
        task = asyncio.create_task(coro)
        self._deliveries.add(task)
        task.add_done_callback(self._deliveries.discard)

    async def _command(self, command: str, uas: str) -> None:
        """Send one operator command until gcs-utm answers; print its outcome."""
        import uuid

        station = self._station
        rid = uuid.uuid4().hex[:12]
        self._write(f"sending {command} for {uas} (id {rid})")
        said_waiting = False
        while True:
            try:
                ack = await station.command(
                    uas, command, request_id=rid, timeout_s=station.resend_s
                )
            except TimeoutError:
                if not said_waiting:
                    self._write(f"no outcome from gcs-utm yet for {command} {uas}; waiting")
                    said_waiting = True
                continue
            tail = f" ({ack.reason})" if ack.reason else ""
            self._write(f"gcs-utm: {command} {ack.uas or uas} {ack.outcome}{tail}")
            return

    async def _deliver(self, rec: dict[str, Any], accept: bool, index: int | None) -> None:
        from gcs_utm.cli.pilot_text import ack_text
        from gcs_utm.messages import PilotDecision

        station = self._station
        rec_id, version = str(rec["recommendation_id"]), int(rec["version"])
        decision = PilotDecision.ACCEPT if accept else PilotDecision.REJECT
        option = ""
        if accept:
            option = " (proposed option)" if index is None else f" (alternative_index {index})"
        self._write(f"sending {decision.value}{option} for recommendation {rec_id} v{version}")
        said_waiting = False
        while True:
            try:
                ack = await station.answer(
                    rec_id,
                    version,
                    decision,
                    alternative_index=index,
                    timeout_s=station.resend_s,
                )
            except TimeoutError:
                if not said_waiting:
                    self._write(
                        f"no acknowledgement from gcs-utm yet; re-sending every "
                        f"{station.resend_s:g} s until it answers"
                    )
                    said_waiting = True
                continue
            self._write(ack_text(ack.outcome, ack.state, ack.reason, rec_id, version))
            return

    async def close(self) -> None:
        for rec_id, version in self._station.unacknowledged:
            self._write(f"answer to recommendation {rec_id} v{version} not acknowledged yet")
        for task in list(self._deliveries):
            task.cancel()
        for task in list(self._deliveries):
            with contextlib.suppress(asyncio.CancelledError):
                await task


__all__ = ["register", "run_pilot"]
