"""The operator's command keys on the dashboard: pick a UAS, press a command key, confirm.

- ``u`` selects the next UAS (the operations in the table's order, by id);
- ``h`` hold, ``l`` land, ``t`` return to launch, ``m`` resume mission arm that command for
  the selected UAS: the command line asks for a confirmation;
- ``y`` or the same key again confirms (two keys in all); ``Esc``, another UAS, or
  ``confirm_s`` wall seconds without an answer cancel it;
- the confirmed command goes to :meth:`Usm.operator_command` (the same path and audit as
  EM's commands, refused with a reason when the vehicle cannot do it) in a task of its own,
  and its outcome (confirmed, acknowledged, failed, refused and why) is shown on the line.

The state lives here, out of the Textual app, so the prompt's keys and these stay apart.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable

from rich.markup import escape

from gcs_utm.services.operator_commands import CommandResult
from gcs_utm.services.usm import Usm

KEYS: dict[str, str] = {"h": "hold", "l": "land", "t": "rtl", "m": "resume"}
"""Command key -> operator command."""

_WORDS = {
    "hold": "HOLD (brake)",
    "land": "LAND",
    "rtl": "RETURN TO LAUNCH",
    "resume": "RESUME MISSION",
}
HELP = "u UAS  h hold  l land  t RTL  m resume"


class CommandKeys:
    """See the module docstring. ``on_done`` is called (no argument) when an outcome arrives."""

    def __init__(
        self,
        usm: Usm,
        *,
        operator: str,
        source: str = "dashboard",
        confirm_s: float = 10.0,
        monotonic: Callable[[], float] = time.monotonic,
        on_done: Callable[[], None] = lambda: None,
    ) -> None:
        self._usm = usm
        self._operator = operator
        self._source = source
        self._confirm_s = confirm_s
        self._monotonic = monotonic
        self._on_done = on_done
        self.selected: str | None = None
        self.armed: str | None = None  # the command waiting for its confirmation
        self._armed_at = 0.0
        self.note = ""  # the last outcome, or why a key did nothing
        self.results: list[CommandResult] = []
        self._tasks: set[asyncio.Task[None]] = set()

    def _uas_ids(self) -> list[str]:
        return sorted(self._usm.airspace.operations)

    def _current(self) -> str | None:
        """The selected UAS (the first one until the operator picks another)."""
        ids = self._uas_ids()
        if self.selected not in ids:
            self.selected = ids[0] if ids else None
        return self.selected

    def select_next(self) -> None:
        ids = self._uas_ids()
        if not ids:
            self.note = "no UAS to select"
            return
        now = self._current()
        self.selected = ids[(ids.index(now) + 1) % len(ids)] if now in ids else ids[0]
        self.armed = None  # a confirmation is for the UAS it was asked on
        self.note = ""

    def press(self, key: str) -> None:
        """A command key: arms its command, or confirms it when it is the armed one."""
        command = KEYS[key]
        if self._still_armed() == command:
            self.confirm()
            return
        uas = self._current()
        if uas is None:
            self.note = "no UAS to command"
            return
        self.armed, self._armed_at = command, self._monotonic()
        self.note = ""

    def _still_armed(self) -> str | None:
        if self.armed is not None and self._monotonic() - self._armed_at > self._confirm_s:
            self.armed = None
            self.note = f"not confirmed within {self._confirm_s:g} s: cancelled"
        return self.armed

    def confirm(self) -> bool:
        """Send the armed command (False when none is armed)."""
        command, uas = self._still_armed(), self._current()
        if command is None or uas is None:
            return False
        self.armed = None
        self.note = f"{command} {uas}: sending ..."
        task = asyncio.ensure_future(self._send(uas, command))
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        return True

    def cancel(self) -> None:
        if self.armed is not None:
            self.note = f"{self.armed} cancelled"
        self.armed = None

    async def _send(self, uas: str, command: str) -> None:
        result = await self._usm.operator_command(
            uas, command, operator=self._operator, source=self._source
        )
        self.results.append(result)
        self.note = result.text()
        self._on_done()

    def line(self) -> str:
        """The command line (rich markup): what is selected, what waits for a yes, the last
        outcome."""
        uas = self._current()
        command = self._still_armed()
        if uas is None:
            return f"[dim]no UAS[/]  {escape(self.note)}"
        if command is not None:
            key = next(k for k, c in KEYS.items() if c == command)
            return (
                f"[bold reverse yellow] {_WORDS[command]} {escape(uas)}? [/] "
                f"[bold]y[/] or [bold]{key}[/] again: yes   [bold]Esc[/]: no"
            )
        if self.note:  # the outcome first: the line may be narrow
            return f"UAS [bold]{escape(uas)}[/]  [bold]{escape(self.note)}[/]  [dim]{HELP}[/]"
        return f"UAS [bold]{escape(uas)}[/]  [dim]{HELP}[/]"

    async def drain(self) -> None:
        """Wait for the commands being sent (tests, shutdown)."""
        while self._tasks:
            await asyncio.gather(*list(self._tasks), return_exceptions=True)


LINE_HELP = "hold|land|rtl|resume <UAS> + Enter, then y + Enter: operator command"


class LineCommands:
    """Operator commands typed on a line prompt: ``hold UAS1`` (``land``, ``rtl`` or
    ``return``, ``resume``) asks for a confirmation, ``y`` on the next line sends it (anything
    else cancels it). The command runs in a task of its own; ``write`` prints its outcome."""

    def __init__(
        self, usm: Usm, *, operator: str, source: str, write: Callable[[str], None]
    ) -> None:
        self._usm = usm
        self._operator = operator
        self._source = source
        self._write = write
        self.armed: tuple[str, str] | None = None  # (command, UAS) waiting for its yes
        self.results: list[CommandResult] = []
        self._tasks: set[asyncio.Task[None]] = set()

    def handle(self, text: str) -> bool:
        """Take one typed line (stripped); False when it is not about a command."""
        from gcs_utm.services.operator_commands import parse_command_line

        armed, self.armed = self.armed, None
        if armed is not None:
            if text.lower() in ("y", "yes"):
                self._write(f"{armed[0]} {armed[1]}: sending ...")
                task = asyncio.ensure_future(self._send(*armed))
                self._tasks.add(task)
                task.add_done_callback(self._tasks.discard)
                return True
            self._write(f"{armed[0]} {armed[1]} cancelled")
            if text.lower() in ("n", "no"):
                return True
        parsed = parse_command_line(text)
        if parsed is None:
            return armed is not None and not text
        self.armed = parsed
        self._write(
            f"{_WORDS[parsed[0]]} {parsed[1]}? y + Enter sends it, anything else cancels it"
        )
        return True

    async def _send(self, command: str, uas: str) -> None:
        result = await self._usm.operator_command(
            uas, command, operator=self._operator, source=self._source
        )
        self.results.append(result)
        self._write(result.text())

    async def drain(self) -> None:
        while self._tasks:
            await asyncio.gather(*list(self._tasks), return_exceptions=True)


__all__ = ["HELP", "KEYS", "LINE_HELP", "CommandKeys", "LineCommands"]
