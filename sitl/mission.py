"""Vehicle side of the MAVLink mission protocol, as PX4 implements it (sans-IO).

Upload: MISSION_COUNT -> MISSION_REQUEST_INT(seq) ... MISSION_ITEM(_INT) -> MISSION_ACK.
The vehicle re-requests the expected item every 250 ms and gives up after 5 s with a
STATUSTEXT (both wall-clock: the ground station runs on the wall clock whatever the sim speed).
The new mission replaces the old one atomically when the last item arrives; a repeated last
item (the ground missed our ACK) is answered with the same ACK. Download: MISSION_REQUEST_LIST
-> MISSION_COUNT -> MISSION_REQUEST(_INT) -> MISSION_ITEM(_INT) (MISSION_ITEM answers the old
MISSION_REQUEST) -> MISSION_ACK. Fence and rally transfers answer MAV_MISSION_UNSUPPORTED.

PX4 specifics kept: an unexpected item during an upload is ignored silently; a repeated
MISSION_COUNT restarts only before item 0 arrived (later: ERROR, the transfer goes on); a
download answers a request for the expected item or the one before it (a re-request) and
aborts with ERROR on any other. With ``ardupilot=True`` the server behaves as ArduPilot's
MissionItemProtocol instead: it re-requests every 1 s, NACKs an unexpected item with
MAV_MISSION_INVALID_SEQUENCE and keeps receiving, answers an item outside an upload with
MAV_MISSION_ERROR, restarts on a repeated MISSION_COUNT, denies downloads during an upload and
answers any in-range download request.

What each autopilot keeps of an accepted item (:func:`px4_stored`, :func:`ardupilot_stored`):
PX4 refuses an item without a position (DO_*) in a global frame (MAV_MISSION_UNSUPPORTED,
"IGN MISSION_ITEM: Invalid item") and keeps global items in their INT frames (0 -> 5,
3 -> 6), every param as sent (NaN included). ArduPilot takes DO items in any frame and
reports them in frame 0, stores a NaN param as 0, and keeps of a NAV_WAYPOINT only what its
packed command holds: ArduCopter the hold time in whole seconds (param1), ArduPlane the
acceptance and pass-by radii in whole metres up to 255 (param2/param3); of a NAV_LAND it
keeps the sign of param4 (-1 or 1), of a NAV_LOITER_TIME the sign of param3 (its direction,
not its radius). An upload is refused with MAV_MISSION_NO_SPACE while the
host's mission storage is not ready (``MissionHost.storage_ready``: ArduPilot for about 1.5
simulated seconds after boot).

The server never touches sockets: it calls `MissionHost.send(peer, name, **fields)`; `peer`
is opaque (the vehicle's link object) and `now_s` is passed in.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, Protocol

from sitl._mav import Inbound, const

REREQUEST_S = 0.25  # PX4 MAVLINK_MISSION_RETRY_TIMEOUT_DEFAULT
AP_REREQUEST_S = 1.0  # ArduPilot MissionItemProtocol: 1000 ms + stream slowdown
PROTOCOL_TIMEOUT_S = 5.0  # PX4 MAVLINK_MISSION_PROTOCOL_TIMEOUT_DEFAULT
REPEAT_ACK_WINDOW_S = 5.0  # how long a repeated last item is still answered

ACCEPTED = const("MAV_MISSION_ACCEPTED")
ERROR = const("MAV_MISSION_ERROR")
UNSUPPORTED_FRAME = const("MAV_MISSION_UNSUPPORTED_FRAME")
UNSUPPORTED = const("MAV_MISSION_UNSUPPORTED")
NO_SPACE = const("MAV_MISSION_NO_SPACE")
DENIED = const("MAV_MISSION_DENIED")
INVALID = const("MAV_MISSION_INVALID")
INVALID_PARAM5_X = const("MAV_MISSION_INVALID_PARAM5_X")
INVALID_PARAM6_Y = const("MAV_MISSION_INVALID_PARAM6_Y")
INVALID_SEQUENCE = const("MAV_MISSION_INVALID_SEQUENCE")
TYPE_MISSION = const("MAV_MISSION_TYPE_MISSION")

FRAME_GLOBAL = const("MAV_FRAME_GLOBAL")
FRAME_MISSION = const("MAV_FRAME_MISSION")
FRAME_GLOBAL_REL = const("MAV_FRAME_GLOBAL_RELATIVE_ALT")
FRAME_GLOBAL_INT = const("MAV_FRAME_GLOBAL_INT")
FRAME_GLOBAL_REL_INT = const("MAV_FRAME_GLOBAL_RELATIVE_ALT_INT")
GLOBAL_FRAMES = frozenset({FRAME_GLOBAL, FRAME_GLOBAL_REL, FRAME_GLOBAL_INT, FRAME_GLOBAL_REL_INT})
RELATIVE_FRAMES = frozenset({FRAME_GLOBAL_REL, FRAME_GLOBAL_REL_INT})

CMD_WAYPOINT = const("MAV_CMD_NAV_WAYPOINT")
CMD_LOITER_UNLIM = const("MAV_CMD_NAV_LOITER_UNLIM")
CMD_LOITER_TIME = const("MAV_CMD_NAV_LOITER_TIME")
CMD_RTL = const("MAV_CMD_NAV_RETURN_TO_LAUNCH")
CMD_LAND = const("MAV_CMD_NAV_LAND")
CMD_TAKEOFF = const("MAV_CMD_NAV_TAKEOFF")
CMD_CHANGE_SPEED = const("MAV_CMD_DO_CHANGE_SPEED")
CMD_LAND_START = const("MAV_CMD_DO_LAND_START")
CMD_DO_JUMP = const("MAV_CMD_DO_JUMP")  # param1 the item to jump to, param2 the repeat count
NAV_COMMANDS = frozenset(
    {CMD_WAYPOINT, CMD_LOITER_UNLIM, CMD_LOITER_TIME, CMD_RTL, CMD_LAND, CMD_TAKEOFF}
)
POSITIONAL = frozenset({CMD_WAYPOINT, CMD_LOITER_UNLIM, CMD_LOITER_TIME, CMD_LAND, CMD_TAKEOFF})
SUPPORTED_COMMANDS = NAV_COMMANDS | {CMD_CHANGE_SPEED, CMD_LAND_START, CMD_DO_JUMP}
DO_COMMANDS = SUPPORTED_COMMANDS - NAV_COMMANDS
_INT_FRAME = {FRAME_GLOBAL: FRAME_GLOBAL_INT, FRAME_GLOBAL_REL: FRAME_GLOBAL_REL_INT}


@dataclass(frozen=True, slots=True)
class RawItem:
    """A mission item as MISSION_ITEM_INT carries it (x/y in degE7 for global frames)."""

    seq: int
    frame: int
    command: int
    current: int
    autocontinue: int
    param1: float
    param2: float
    param3: float
    param4: float
    x: int
    y: int
    z: float

    @property
    def lat_deg(self) -> float:
        return self.x / 1e7

    @property
    def lon_deg(self) -> float:
        return self.y / 1e7


def item_from_message(msg: Inbound) -> RawItem:
    """Build a RawItem from MISSION_ITEM_INT or the float MISSION_ITEM."""
    if msg.type == "MISSION_ITEM":
        frame = msg.i("frame")
        x_f, y_f = msg.f("x"), msg.f("y")
        # Float MISSION_ITEM carries degrees in global frames; keep non-global values as is.
        if frame in GLOBAL_FRAMES:
            x, y = round(x_f * 1e7), round(y_f * 1e7)
        else:
            x, y = round(x_f), round(y_f)
        frame = {FRAME_GLOBAL: FRAME_GLOBAL_INT, FRAME_GLOBAL_REL: FRAME_GLOBAL_REL_INT}.get(
            frame, frame
        )
    else:
        frame, x, y = msg.i("frame"), msg.i("x"), msg.i("y")
    return RawItem(
        seq=msg.i("seq"),
        frame=frame,
        command=msg.i("command"),
        current=msg.i("current"),
        autocontinue=msg.i("autocontinue"),
        param1=msg.f("param1"),
        param2=msg.f("param2"),
        param3=msg.f("param3"),
        param4=msg.f("param4"),
        x=x,
        y=y,
        z=msg.f("z"),
    )


def validate_item(item: RawItem) -> int:
    """MAV_MISSION_RESULT for one item, as ArduPilot's checks would answer (the frame of an
    item without a position is not looked at)."""
    if item.command not in SUPPORTED_COMMANDS:
        return UNSUPPORTED
    if item.command in POSITIONAL:
        result = _position_result(item)
        if result != ACCEPTED:
            return result
    if any(math.isinf(p) for p in (item.param1, item.param2, item.param3)):
        return INVALID
    return ACCEPTED


def _position_result(item: RawItem) -> int:
    """MAV_MISSION_RESULT for the position of an item that has one: a global frame, latitude
    and longitude in range, a finite altitude (a take-off may leave it NaN)."""
    if item.frame not in GLOBAL_FRAMES:
        return UNSUPPORTED_FRAME
    if not -90e7 <= item.x <= 90e7:
        return INVALID_PARAM5_X
    if not -180e7 <= item.y <= 180e7:
        return INVALID_PARAM6_Y
    if not math.isfinite(item.z) and item.command != CMD_TAKEOFF:
        return INVALID
    return ACCEPTED


def validate_px4_item(item: RawItem) -> int:
    """MAV_MISSION_RESULT for one item as PX4 answers: ArduPilot's checks, and an item
    without a position must be in MAV_FRAME_MISSION."""
    if item.command in DO_COMMANDS and item.frame != FRAME_MISSION:
        return UNSUPPORTED
    return validate_item(item)


def px4_stored(item: RawItem) -> RawItem:
    """What PX4 keeps of an accepted item: global frames become their INT variants."""
    return replace(item, frame=_INT_FRAME.get(item.frame, item.frame))


def _zero_nan(v: float) -> float:
    return 0.0 if math.isnan(v) else v


def ardupilot_stored(item: RawItem, *, fixed_wing: bool) -> RawItem:
    """What ArduPilot keeps of an accepted item (see the module docstring)."""
    it = replace(
        item,
        param1=_zero_nan(item.param1),
        param2=_zero_nan(item.param2),
        param3=_zero_nan(item.param3),
        param4=_zero_nan(item.param4),
    )
    if it.command not in POSITIONAL and it.command != CMD_LAND_START:  # (stored with its frame)
        it = replace(it, frame=FRAME_GLOBAL)
    elif it.frame in (FRAME_GLOBAL_INT, FRAME_GLOBAL_REL_INT):
        it = replace(it, frame=FRAME_GLOBAL if it.frame == FRAME_GLOBAL_INT else FRAME_GLOBAL_REL)
    if it.command == CMD_DO_JUMP:  # the target and the repeat count (int16), nothing else
        it = replace(it, param1=float(int(it.param1)), param2=float(int(it.param2)), param3=0.0,
                     param4=0.0)  # fmt: skip
    if it.command == CMD_LAND:  # only the sign of param4 is kept (deep-stall direction)
        it = replace(it, param4=-1.0 if it.param4 < 0.0 else 1.0)
    if it.command == CMD_LOITER_TIME:  # the radius is not stored: its sign, the direction
        it = replace(it, param3=-1.0 if it.param3 < 0.0 else 1.0)
    if it.command == CMD_WAYPOINT:
        if fixed_wing:
            acc = float(min(255, max(0, int(it.param2))))
            passby = float(min(255, max(0, int(it.param3))))
            it = replace(it, param1=0.0, param2=acc, param3=passby, param4=0.0)
        else:
            hold = float(min(65535, max(0, int(it.param1))))
            it = replace(it, param1=hold, param2=0.0, param3=0.0, param4=0.0)
    return it


class MissionHost(Protocol):
    def mission_items(self) -> list[RawItem]: ...
    def accept_mission(self, items: list[RawItem], flagged_current: int | None) -> None: ...
    def clear_mission(self) -> None: ...
    def set_current(self, seq: int) -> bool: ...
    def statustext(self, severity: int, text: str) -> None: ...
    def send(self, peer: object, name: str, **fields: Any) -> None: ...
    def count(self, counter: str) -> None: ...
    def storage_ready(self) -> bool: ...


@dataclass(slots=True)
class _Upload:
    peer: object
    sys_id: int
    comp_id: int
    count: int
    expected: int
    items: list[RawItem]
    last_rx_s: float
    last_req_s: float
    use_int: bool


@dataclass(slots=True)
class _Download:
    peer: object
    sys_id: int
    comp_id: int
    count: int
    last_rx_s: float
    next_seq: int = 0  # PX4's _transfer_seq: the request it expects next


class MissionServer:
    """One transfer at a time, as PX4's MavlinkMissionManager."""

    def __init__(
        self,
        host: MissionHost,
        *,
        max_items: int,
        validator: Callable[[RawItem], int] | None = None,
        ardupilot: bool = False,
    ) -> None:
        self._host = host
        self._ap = ardupilot
        self._rerequest_s = AP_REREQUEST_S if ardupilot else REREQUEST_S
        self._max_items = max_items
        self._validate = validator or (validate_item if ardupilot else validate_px4_item)
        self._up: _Upload | None = None
        self._down: _Download | None = None
        # (peer, sys, comp, count, t) of the last finished upload, for repeated last items
        self._last_done: tuple[int, int, int, float] | None = None

    @property
    def busy(self) -> bool:
        return self._up is not None

    def reset(self) -> None:
        """The vehicle rebooted: transfers in progress are gone."""
        self._up = None
        self._down = None
        self._last_done = None

    def handle(self, peer: object, msg: Inbound, now_s: float) -> bool:
        """Process one mission-protocol message; False if it is not one."""
        handler = _HANDLERS.get(msg.type)
        if handler is None:
            return False
        handler(self, peer, msg, now_s)
        return True

    def _on_ack(self, peer: object, msg: Inbound, now_s: float) -> None:
        """The GCS ends our download (whatever the result)."""
        if self._down is not None and self._down.sys_id == msg.src_system:
            self._down = None

    def _on_clear_all(self, peer: object, msg: Inbound, now_s: float) -> None:
        mtype = msg.i("mission_type")
        if mtype != TYPE_MISSION:
            self._ack(peer, msg.src_system, msg.src_component, UNSUPPORTED, mtype)
        elif self._up is not None:
            self._ack(peer, msg.src_system, msg.src_component, ERROR)
        else:
            self._host.clear_mission()
            self._ack(peer, msg.src_system, msg.src_component, ACCEPTED)

    def _on_set_current(self, peer: object, msg: Inbound, now_s: float) -> None:
        seq = msg.i("seq")
        if not self._host.set_current(seq):
            self._host.statustext(
                const("MAV_SEVERITY_ERROR"), f"WPM: MISSION_SET_CURRENT seq {seq} out of bounds"
            )
            self._host.count("mission_bad_seq")

    def tick(self, now_s: float) -> None:
        up = self._up
        if up is not None:
            if now_s - up.last_rx_s > PROTOCOL_TIMEOUT_S:
                self._up = None
                self._host.count("uploads_failed")
                self._host.statustext(
                    const("MAV_SEVERITY_CRITICAL"), "Mission upload: operation timeout"
                )
            elif now_s - up.last_req_s >= self._rerequest_s:
                up.last_req_s = now_s
                self._host.count("mission_rerequests")
                self._request(up)
        down = self._down
        if down is not None and now_s - down.last_rx_s > PROTOCOL_TIMEOUT_S:
            self._down = None

    # -- upload ---------------------------------------------------------------------------
    def _on_count(self, peer: object, msg: Inbound, now_s: float) -> None:
        mtype = msg.i("mission_type")
        src, comp = msg.src_system, msg.src_component
        if mtype != TYPE_MISSION:
            self._ack(peer, src, comp, UNSUPPORTED, mtype)
            return
        if self._up is not None and self._up.sys_id != src:
            self._ack(peer, src, comp, DENIED if self._ap else ERROR)  # busy with another GCS
            return
        if self._up is not None and not self._ap and self._up.expected > 0:
            self._ack(peer, src, comp, ERROR)  # PX4: "WPM: REJ. CMD: Busy", transfer goes on
            return
        count = msg.i("count")
        if count > self._max_items or not self._host.storage_ready():
            self._host.count("uploads_failed")
            self._ack(peer, src, comp, NO_SPACE)
            return
        if count == 0:
            self._up = None
            self._host.clear_mission()
            self._host.count("uploads_ok")
            self._ack(peer, src, comp, ACCEPTED)
            return
        self._up = _Upload(peer, src, comp, count, 0, [], now_s, now_s, True)
        self._request(self._up)

    def _request(self, up: _Upload) -> None:
        name = "MISSION_REQUEST_INT" if up.use_int else "MISSION_REQUEST"
        self._host.send(
            up.peer,
            name,
            target_system=up.sys_id,
            target_component=up.comp_id,
            seq=up.expected,
            mission_type=TYPE_MISSION,
        )

    def _on_item(self, peer: object, msg: Inbound, now_s: float) -> None:
        src, comp = msg.src_system, msg.src_component
        mtype = msg.i("mission_type")
        seq = msg.i("seq")
        up = self._up
        if up is None or up.sys_id != src:
            done = self._last_done
            if self._ap:
                self._host.count("mission_unexpected_item")
                self._ack(peer, src, comp, ERROR)  # ArduPilot: not receiving
            elif (
                done is not None
                and done[0] == src
                and seq == done[2] - 1
                and now_s - done[3] < REPEAT_ACK_WINDOW_S
            ):
                self._host.count("mission_repeated_ack")
                self._ack(peer, src, comp, ACCEPTED)
            else:
                self._host.count("mission_unexpected_item")
            return
        if mtype != TYPE_MISSION:
            self._fail(up, UNSUPPORTED)
            return
        up.last_rx_s = now_s
        up.peer = peer
        if seq != up.expected:
            if seq < up.expected:
                self._host.count("mission_duplicate_item")  # an answer to a re-request
            else:
                self._host.count("mission_bad_seq")
            if self._ap:
                self._ack(peer, src, comp, INVALID_SEQUENCE)  # and keep receiving
            return  # PX4 ignores an item it did not ask for
        item = item_from_message(msg)
        result = self._validate(item)
        if result != ACCEPTED:
            self._fail(up, result)
            return
        up.items.append(item)
        up.expected += 1
        if up.expected < up.count:
            up.last_req_s = now_s
            self._request(up)
            return
        self._up = None
        flagged = next((it.seq for it in up.items if it.current), None)
        self._host.accept_mission([replace(it, current=0) for it in up.items], flagged)
        self._host.count("uploads_ok")
        self._last_done = (src, comp, up.count, now_s)
        self._ack(peer, src, comp, ACCEPTED)

    def _fail(self, up: _Upload, result: int) -> None:
        self._up = None
        self._host.count("uploads_failed")
        self._ack(up.peer, up.sys_id, up.comp_id, result)

    def _ack(
        self, peer: object, sys_id: int, comp_id: int, result: int, mission_type: int = TYPE_MISSION
    ) -> None:
        self._host.send(
            peer,
            "MISSION_ACK",
            target_system=sys_id,
            target_component=comp_id,
            type=result,
            mission_type=mission_type,
        )

    # -- download -------------------------------------------------------------------------
    def _on_request_list(self, peer: object, msg: Inbound, now_s: float) -> None:
        src, comp = msg.src_system, msg.src_component
        mtype = msg.i("mission_type")
        if mtype != TYPE_MISSION:
            # PX4 would send an empty fence/rally list; we have none either.
            self._host.send(
                peer,
                "MISSION_COUNT",
                target_system=src,
                target_component=comp,
                count=0,
                mission_type=mtype,
            )
            return
        if self._ap and self._up is not None:
            self._ack(peer, src, comp, DENIED)
            return
        items = self._host.mission_items()
        self._down = _Download(peer, src, comp, len(items), now_s) if items else None
        self._host.send(
            peer,
            "MISSION_COUNT",
            target_system=src,
            target_component=comp,
            count=len(items),
            mission_type=TYPE_MISSION,
        )

    def _on_request(self, peer: object, msg: Inbound, now_s: float) -> None:
        src, comp = msg.src_system, msg.src_component
        seq = msg.i("seq")
        if self._up is not None and self._up.sys_id == src:
            if self._ap:
                self._ack(peer, src, comp, DENIED)
            return  # requests are ours to send during an upload
        items = self._host.mission_items()
        if msg.i("mission_type") != TYPE_MISSION or not 0 <= seq < len(items):
            self._host.count("mission_bad_seq")
            self._ack(peer, src, comp, ERROR if seq >= len(items) else INVALID_SEQUENCE)
            self._down = None
            return
        down = self._down
        if down is not None and not self._ap:
            if seq == down.next_seq:
                down.next_seq += 1
            elif seq != down.next_seq - 1:
                # PX4: "WPM: REJ. CMD: Req. WP was unexpected" (so no pipelined requests)
                self._host.count("mission_bad_seq")
                self._down = None
                self._ack(peer, src, comp, ERROR)
                return
        if down is not None:
            down.last_rx_s = now_s
        it = items[seq]
        common = dict(
            target_system=src,
            target_component=comp,
            seq=seq,
            command=it.command,
            current=it.current,
            autocontinue=it.autocontinue,
            param1=it.param1,
            param2=it.param2,
            param3=it.param3,
            param4=it.param4,
            z=it.z,
            mission_type=TYPE_MISSION,
        )
        if msg.type == "MISSION_REQUEST_INT":
            self._host.send(peer, "MISSION_ITEM_INT", frame=it.frame, x=it.x, y=it.y, **common)
        else:
            frame = {FRAME_GLOBAL_INT: FRAME_GLOBAL, FRAME_GLOBAL_REL_INT: FRAME_GLOBAL_REL}.get(
                it.frame, it.frame
            )
            scale = 1e-7 if it.frame in GLOBAL_FRAMES else 1.0
            self._host.send(
                peer, "MISSION_ITEM", frame=frame, x=it.x * scale, y=it.y * scale, **common
            )


_HANDLERS: dict[str, Callable[[MissionServer, object, Inbound, float], None]] = {
    "MISSION_COUNT": MissionServer._on_count,
    "MISSION_ITEM_INT": MissionServer._on_item,
    "MISSION_ITEM": MissionServer._on_item,
    "MISSION_REQUEST_LIST": MissionServer._on_request_list,
    "MISSION_REQUEST_INT": MissionServer._on_request,
    "MISSION_REQUEST": MissionServer._on_request,
    "MISSION_ACK": MissionServer._on_ack,
    "MISSION_CLEAR_ALL": MissionServer._on_clear_all,
    "MISSION_SET_CURRENT": MissionServer._on_set_current,
}
"""The mission-protocol messages :meth:`MissionServer.handle` answers, by message type."""
