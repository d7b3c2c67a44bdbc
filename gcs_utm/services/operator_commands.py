"""Operator commands: hold, land, return to launch and resume mission for one UAS, asked for by
a person (dashboard keys, the headless line prompt, MQTT ``commands``, ``gcs-utm pilot``).

One entry point, :meth:`OperatorCommands.command`, that every channel uses:

- the request is checked first and refused with a reason (audited, in the event log, returned
  to the channel) when the vehicle cannot do it: unknown UAS, an operator that does not fly it
  (MQTT: only its own operator or ``admin``), no vehicle link (nothing heard for
  ``link_timeout_s``), no status yet, disarmed or on the ground (:mod:`.flight_state`; resume
  needs an armed vehicle with a mission), an autopilot without that mode
  (:func:`adapters.mavlink.modes.set_mode_params`, the table the command uses);
- a command that passes goes through the same path as Emergency Management's commands
  (:meth:`Usm.execute_command`: the hub's mode change or NAV_LAND with COMMAND_ACK, its own
  ``command_<kind>`` audit entry and operation state);
- an acknowledged command is then verified: the vehicle's HEARTBEAT mode (its status) must
  show the commanded mode within ``confirm_s`` clock seconds (``confirmed``), else the
  outcome says it was only ``acknowledged`` and which mode the vehicle reports;
- a request id seen again from the same operator (a station re-sending until it hears back)
  is not sent twice: the first outcome is returned again (not a refusal as another cluster
  instance's: after a takeover the UAS may be this instance's when the id comes again).

Mapping (adapters/mavlink/commands.py): hold = PX4 AUTO.LOITER, ArduCopter BRAKE, ArduPlane
LOITER; land = PX4 NAV_LAND, ArduCopter LAND, ArduPlane DO_LAND_START else a landing mission
ahead; rtl = PX4 AUTO.RTL, ArduPilot RTL; resume = PX4 AUTO.MISSION, ArduPilot AUTO.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass
from enum import Enum

from adapters.mavlink.modes import set_mode_params
from gcs_utm.clock import Clock
from gcs_utm.messages import FlightMode, LinkHealth, VehicleStatus
from gcs_utm.model import (
    AuditEntry,
    Autopilot,
    Command,
    CommandKind,
    Operation,
    OperationId,
    SysId,
    VehicleKind,
)
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.flight_state import FlightState

COMMANDS: dict[str, CommandKind] = {
    "hold": CommandKind.HOLD,
    "land": CommandKind.LAND,
    "rtl": CommandKind.RTL,
    "resume": CommandKind.RESUME,
}
"""The operator's commands by the name every channel uses."""

_MODE_OF = {
    CommandKind.HOLD: FlightMode.HOLD,
    CommandKind.RTL: FlightMode.RTL,
    CommandKind.RESUME: FlightMode.MISSION,
}
_CONFIRMING: dict[CommandKind, frozenset[FlightMode]] = {
    CommandKind.HOLD: frozenset({FlightMode.HOLD}),
    CommandKind.RTL: frozenset({FlightMode.RTL}),
    CommandKind.RESUME: frozenset({FlightMode.MISSION, FlightMode.TAKEOFF}),
    # a plane without a landing sequence lands through a landing mission (AUTO)
    CommandKind.LAND: frozenset({FlightMode.LAND}),
}
_PLANE_LAND = frozenset({FlightMode.LAND, FlightMode.MISSION})
_POLL_S = 0.1  # clock seconds between two looks at the vehicle's mode
_REMEMBERED_IDS = 256  # request ids kept per service for repeats


class Outcome(Enum):
    CONFIRMED = "confirmed"  # acknowledged, and the vehicle reports the mode
    ACKNOWLEDGED = "acknowledged"  # acknowledged, the mode not (yet) reported
    FAILED = "failed"  # sent, not acknowledged (refused by the autopilot, no answer)
    REFUSED = "refused"  # not sent: the reason says why


@dataclass(frozen=True, slots=True, kw_only=True)
class CommandResult:
    """What became of one operator command."""

    uas: str
    command: str
    outcome: Outcome
    reason: str = ""
    request_id: str = ""
    mode: str = ""  # the mode the vehicle reports at the end ("" when unknown)
    # refused because another cluster instance commands this UAS (``OperatorCommands.gate``):
    # over MQTT that instance answers, so this refusal is not published
    elsewhere: bool = False

    @property
    def ok(self) -> bool:
        return self.outcome in (Outcome.CONFIRMED, Outcome.ACKNOWLEDGED)

    def text(self) -> str:
        """One line for the operator."""
        head = f"{self.command} {self.uas}: {self.outcome.value}"
        return f"{head} ({self.reason})" if self.reason else head


@dataclass(frozen=True, slots=True)
class VehicleView:
    """What the commands read of the USM (its own dictionaries, read at each request)."""

    statuses: Callable[[], Mapping[SysId, VehicleStatus]]
    health: Callable[[], Mapping[SysId, LinkHealth]]
    flight: Callable[[SysId], FlightState | None]
    linked: Callable[[], bool]  # a vehicle port is attached


class OperatorCommands:
    """See the module docstring. ``execute`` is the USM's ``execute_command``; ``record`` and
    ``log_event`` its audit and event log."""

    def __init__(
        self,
        airspace: Airspace,
        clock: Clock,
        view: VehicleView,
        *,
        execute: Callable[[Command, str], Awaitable[bool]],
        record: Callable[[object], None],
        log_event: Callable[[str, str], None],
        confirm_s: float = 5.0,
        link_timeout_s: float = 5.0,
    ) -> None:
        self.airspace = airspace
        self.clock = clock
        self.view = view
        self._execute = execute
        self._record = record
        self._log_event = log_event
        self.confirm_s = confirm_s
        self.link_timeout_s = link_timeout_s
        self._done: OrderedDict[tuple[str, str], CommandResult] = OrderedDict()
        self._running: set[tuple[str, str]] = set()
        self.results: list[CommandResult] = []  # every outcome, in order (tests, reports)
        # a cluster member's rule (gcs_utm.cluster.commands): why this instance may not
        # command the UAS named (its operation here, or None), "" when it may; None: always
        self.gate: Callable[[str, Operation | None], str] | None = None

    def operation_of(self, uas: str) -> Operation | None:
        """The operation named ``uas`` (an operation id, else a system id: ``3`` or
        ``sys3``)."""
        ops = self.airspace.operations
        op = ops.get(OperationId(uas))
        if op is not None:
            return op
        digits = uas.removeprefix("sys")
        if digits.isdigit():
            return self.airspace.by_sys_id(SysId(int(digits)))
        return None

    def problem(self, uas: str, command: str, *, operator: str, source: str) -> str:
        """Why ``command`` cannot be sent to ``uas`` now ("" when it can)."""
        kind = COMMANDS.get(command)
        if kind is None:
            return f"unknown command {command!r}; expected one of {', '.join(COMMANDS)}"
        op = self.operation_of(uas)
        if op is None:
            return f"unknown UAS {uas!r}"
        if source == "mqtt" and operator not in (op.operator, "admin"):
            return f"operator {operator!r} does not fly {op.id}"
        if op.sys_id is None or not self.view.linked():
            return f"no vehicle link for {op.id}"
        return self._vehicle_problem(op.sys_id, kind)

    def _vehicle_problem(self, sys_id: SysId, kind: CommandKind) -> str:
        status = self.view.statuses().get(sys_id)
        if status is None:
            return f"no link: nothing heard from sysid {sys_id}"
        return self._link_problem(sys_id) or self._mode_problem(status, kind)

    def _link_problem(self, sys_id: SysId) -> str:
        health = self.view.health().get(sys_id)
        if health is None:
            return ""
        silent_s = self.clock.now_s() - health.last_heard_t_s
        if silent_s > self.link_timeout_s:
            return f"no link: sysid {sys_id} last heard {silent_s:.0f} s ago"
        return ""

    def _mode_problem(self, status: VehicleStatus, kind: CommandKind) -> str:
        """The autopilot has no such mode, or the vehicle is not in a state to take it."""
        sys_id = status.sys_id
        if status.autopilot is Autopilot.UNKNOWN:
            return f"sysid {sys_id}: unknown autopilot, its modes are not known"
        mode = _MODE_OF.get(kind)
        if (
            mode is not None
            and set_mode_params(status.autopilot, status.vehicle_kind, mode) is None
        ):
            return f"{_name(status)} has no {mode.value} mode"
        if not status.armed:
            return f"sysid {sys_id} is disarmed"
        if kind is CommandKind.RESUME:
            return "" if status.mission_total else f"sysid {sys_id} has no mission to resume"
        flight = self.view.flight(sys_id)
        if flight is not None and flight.on_ground:
            return f"sysid {sys_id} is on the ground"
        return ""

    async def command(
        self,
        uas: str,
        command: str,
        *,
        operator: str,
        source: str,
        request_id: str = "",
    ) -> CommandResult:
        """Check, send, verify and audit one command (see the module docstring)."""
        key = (operator, request_id)
        if request_id:
            done = self._done.get(key)
            if done is not None or key in self._running:
                self._log_event("operator", f"{command} {uas} id {request_id} again: not re-sent")
                return done or CommandResult(
                    uas=uas,
                    command=command,
                    outcome=Outcome.ACKNOWLEDGED,
                    reason="already being sent",
                    request_id=request_id,
                )
            self._running.add(key)
        try:
            result = await self._command(uas, command, operator, source, request_id)
        finally:
            self._running.discard(key)
        if request_id and not result.elsewhere:  # another instance's may become ours
            self._done[key] = result
            while len(self._done) > _REMEMBERED_IDS:
                self._done.popitem(last=False)
        self.results.append(result)
        return result

    async def _command(
        self, uas: str, command: str, operator: str, source: str, request_id: str
    ) -> CommandResult:
        elsewhere = ""
        if self.gate is not None and command in COMMANDS:
            elsewhere = self.gate(uas, self.operation_of(uas))
        reason = elsewhere or self.problem(uas, command, operator=operator, source=source)
        op = None if reason else self.operation_of(uas)
        if op is None or op.sys_id is None:
            result = CommandResult(
                uas=uas,
                command=command,
                outcome=Outcome.REFUSED,
                reason=reason,
                request_id=request_id,
                elsewhere=bool(elsewhere),
            )
            self._audit(result, operator, source, uas)
            return result
        kind = COMMANDS[command]
        before = self.view.statuses().get(op.sys_id)
        sent = await self._execute(
            Command(kind=kind, operation_id=op.id), f"operator {operator} ({source})"
        )
        if not sent:
            result = CommandResult(
                uas=op.id,
                command=command,
                outcome=Outcome.FAILED,
                reason="not acknowledged by the vehicle (see the command event)",
                request_id=request_id,
            )
        else:
            was = before.mode if before is not None else FlightMode.UNKNOWN
            result = await self._verify(op.id, op.sys_id, kind, command, request_id, was=was)
        self._audit(result, operator, source, op.id)
        return result

    async def _verify(
        self,
        op_id: OperationId,
        sys_id: SysId,
        kind: CommandKind,
        command: str,
        request_id: str,
        *,
        was: FlightMode,
    ) -> CommandResult:
        """Wait for the vehicle's status to report the commanded mode (``was``: its mode
        before the command)."""
        end_s = self.clock.now_s() + self.confirm_s
        while True:
            status = self.view.statuses().get(sys_id)
            mode = status.mode if status is not None else FlightMode.UNKNOWN
            wanted = _CONFIRMING[kind]
            if kind is CommandKind.LAND and _plane(status) and was is not FlightMode.MISSION:
                wanted = _PLANE_LAND  # its landing mission: AUTO, when it was not in AUTO
            if mode in wanted:
                return CommandResult(
                    uas=op_id,
                    command=command,
                    outcome=Outcome.CONFIRMED,
                    reason=f"vehicle reports {mode.value}",
                    request_id=request_id,
                    mode=mode.value,
                )
            if self.clock.now_s() >= end_s:
                return CommandResult(
                    uas=op_id,
                    command=command,
                    outcome=Outcome.ACKNOWLEDGED,
                    reason=f"vehicle still reports {mode.value} after {self.confirm_s:g} s",
                    request_id=request_id,
                    mode=mode.value,
                )
            await self.clock.sleep(_POLL_S)

    def _audit(self, result: CommandResult, operator: str, source: str, subject: str) -> None:
        self._record(
            AuditEntry(
                t_s=self.clock.now_s(),
                actor=f"operator:{operator}",
                action=f"operator_{result.command}",
                subject=subject,
                detail={
                    "source": source,
                    "id": result.request_id,
                    "outcome": result.outcome.value,
                    "reason": result.reason,
                    "mode": result.mode,
                },
            )
        )
        self._log_event("operator", f"{result.text()} by {operator} ({source})")


def _plane(status: VehicleStatus | None) -> bool:
    return status is not None and status.vehicle_kind is VehicleKind.FIXED_WING


def _name(status: VehicleStatus) -> str:
    if status.autopilot is Autopilot.ARDUPILOT:
        return "ArduPlane" if _plane(status) else "ArduCopter"
    return str(status.autopilot.value)


def parse_command_line(text: str) -> tuple[str, str] | None:
    """``hold UAS1`` -> (``hold``, ``UAS1``); None when the line is not an operator command
    (``return`` and ``rtl`` are the same command)."""
    words = text.split()
    if len(words) != 2:
        return None
    name = words[0].lower()
    name = "rtl" if name == "return" else name
    if name not in COMMANDS:
        return None
    return name, words[1]


__all__ = [
    "COMMANDS",
    "CommandResult",
    "OperatorCommands",
    "Outcome",
    "VehicleView",
    "parse_command_line",
]
