"""ArduPlane's LAND keeps the pilot's landing sequence (issue 31.4): DO_LAND_START that went
unanswered is not followed by the landing mission, which would replace the sequence; one
that ArduPlane refused (it has no sequence) is (adapters/mavlink/commands.py)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from adapters.mavlink.commands import Commands
from adapters.mavlink.mission import MAV_CMD_DO_LAND_START, MAV_CMD_NAV_LAND, MissionItem
from adapters.mavlink.transfer import CommandResult, UploadResult
from gcs_utm.model import (
    Autopilot,
    Command,
    CommandKind,
    OperationId,
    Position,
    SysId,
    VehicleKind,
)

MAV_RESULT_FAILED = 4


def _mission(landing: bool) -> list[MissionItem]:
    """Home, a waypoint and (``landing``) DO_LAND_START, the approach and NAV_LAND."""
    items = [
        MissionItem(seq=0, command=16, x=406597000, y=-35969000, z=675.0),
        MissionItem(seq=1, command=16, x=406697000, y=-35969000, z=735.0),
    ]
    if landing:
        items += [
            MissionItem(seq=2, command=MAV_CMD_DO_LAND_START, x=406597000, y=-36069000),
            MissionItem(seq=3, command=16, x=406557000, y=-36019000, z=705.0),
            MissionItem(seq=4, command=MAV_CMD_NAV_LAND, x=406597000, y=-35969000, z=675.0),
        ]
    return items


@dataclass
class _State:
    mission: list[MissionItem]
    autopilot: Autopilot = Autopilot.ARDUPILOT
    kind: VehicleKind = VehicleKind.FIXED_WING
    key: str = "plane"
    last_position: Position | None = field(
        default_factory=lambda: Position(lat_deg=40.6697, lon_deg=-3.5969, alt_amsl_m=735.0)
    )


class _Transfers:
    """DO_LAND_START answered with ``result`` (None: no answer); the home read from item 0."""

    def __init__(self, state: _State, result: int | None) -> None:
        self.link = type("Link", (), {"state": lambda _self, _sys_id: state})()
        self.state, self.result = state, result

    async def send_command_long(self, _st: Any, command: int, *_a: Any) -> CommandResult:
        assert command == MAV_CMD_DO_LAND_START
        error = "no COMMAND_ACK" if self.result is None else "MAV_RESULT 4"
        return CommandResult(ok=False, result=self.result, attempts=3, error=error)

    async def download_mission(self, _key: Any) -> list[MissionItem]:
        return self.state.mission


class _Uploads:
    def __init__(self) -> None:
        self.sent: list[list[MissionItem]] = []

    async def upload_items(self, _key: Any, items: list[MissionItem], **_kw: Any) -> Any:
        self.sent.append(items)
        return UploadResult(ok=True, verified=True, attempts=1, items=len(items), duration_s=0.0)


async def _land(landing: bool, result: int | None) -> tuple[CommandResult, _Uploads]:
    uploads = _Uploads()
    commands = Commands(_Transfers(_State(_mission(landing)), result), uploads)  # type: ignore[arg-type]
    res = await commands.send_command(
        SysId(1), Command(operation_id=OperationId("plane"), kind=CommandKind.LAND)
    )
    return res, uploads


async def test_unanswered_do_land_start_keeps_the_landing_sequence() -> None:
    res, uploads = await _land(landing=True, result=None)
    assert uploads.sent == []  # no landing mission over the pilot's sequence
    assert not res.ok and "landing sequence kept" in res.error


async def test_refused_or_without_a_sequence_the_landing_mission_flies() -> None:
    for landing, result in ((True, MAV_RESULT_FAILED), (False, None)):
        res, uploads = await _land(landing=landing, result=result)
        assert [[it.command for it in sent] for sent in uploads.sent] == [[16, MAV_CMD_NAV_LAND]]
        assert res.ok, res
