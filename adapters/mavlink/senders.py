"""Bounds of the hub's per-sender state (sans-IO): which entries to forget, and when.

Every source address a link hears gets a parser (pymavlink keeps ~20 KB per instance) and
every (address, sysid, compid) that sends a vehicle frame a :class:`VehicleState`. Anybody can
send from a new port or with a new identity, so both tables are bounded:

- **cap**: when a table is full (``max_senders`` addresses per link, ``max_vehicles`` states
  per hub) and a new entry comes, the least recently heard eighth is forgotten at once (one
  sort per eighth of the table, not one scan per new entry);
- **idle**: an entry not heard for ``sender_idle_s`` is forgotten by the periodic sweep, so a
  flood that stopped leaves nothing behind.

Forgetting is cheap to undo: a vehicle that is heard again is discovered again. What is
forgotten is counted (``senders_evicted``, ``vehicles_evicted``). Entries the caller must keep
(a vehicle in the middle of a mission transfer) are skipped by ``keep``.
"""

from __future__ import annotations

import heapq
import logging
from collections.abc import Callable, Hashable, Mapping
from dataclasses import dataclass
from typing import TypeVar

from adapters.mavlink.config import MavlinkConfig
from adapters.mavlink.vehicle import Events, VehicleInfo, VehicleState
from gcs_utm.messages import VehicleKey
from gcs_utm.model import PositionLane, SysId
from gcs_utm.ratelog import RateLimitedLog

_log = logging.getLogger(__name__)

K = TypeVar("K", bound=Hashable)


def idle_keys(
    last_t_s: Mapping[K, float],
    now_s: float,
    idle_s: float,
    keep: Callable[[K], bool] | None = None,
) -> list[K]:
    """Keys last heard ``idle_s`` or more before ``now_s`` (except those ``keep`` keeps)."""
    cutoff = now_s - idle_s
    return [k for k, t in last_t_s.items() if t <= cutoff and (keep is None or not keep(k))]


def over_cap_keys(
    last_t_s: Mapping[K, float],
    cap: int,
    keep: Callable[[K], bool] | None = None,
) -> list[K]:
    """With ``len(last_t_s) >= cap`` (a new entry is coming): the least recently heard keys
    to forget so that ``cap - cap // 8`` remain (at least one goes); else nothing."""
    n = len(last_t_s)
    if n < cap:
        return []
    target = max(0, cap - max(1, cap // 8))
    candidates = [k for k in last_t_s if keep is None or not keep(k)]
    return heapq.nsmallest(n - target, candidates, key=last_t_s.__getitem__)


Address = tuple[str, int]
StateKey = tuple[str, Address | None, int, int]  # (link, source address, sysid, compid)


@dataclass(slots=True)
class SenderCounters:
    senders_evicted: int = 0  # source addresses forgotten (cap or idle)
    vehicles_evicted: int = 0  # vehicle states forgotten (cap or idle)
    sysid_zero: int = 0  # frames from system id 0 (a broadcast address, never a vehicle)
    sysid_claims: int = 0  # frames from a sender claiming a system id bound elsewhere
    sysid_collisions: int = 0  # without sysid_binding: a 2nd vehicle with a system id
    address_changes: int = 0  # a bound vehicle heard from a new address after silence


class Senders:
    """The hub's vehicle states and the binding of each system id to where it was first
    heard. Invariant (``sysid_binding``, the default): every state of a system id is on the
    link and address it is bound to, so a state found for a frame's (link, address, sysid,
    compid) is always a legitimate sender. ``by_sysid[s]`` is the state that commands to
    ``s`` go to: its first discovered autopilot component (:meth:`discovered`), else the first
    state made.

    A frame from another (link, address) claiming a bound system id is refused
    (:meth:`new_state` returns None) and counted; the caller raises the security event. The
    exception is a move: on the same link, once the bound vehicle has been silent for
    ``address_move_s``, a sender from the same host (another port: NAT rebinding, a restarted
    bridge or SITL) is taken to be the same vehicle and the binding follows it; from another
    host only when the vehicle's frames are signed (a key in ``signing_keys``: they were
    verified before they got here), else it is a claim like any other. Without
    ``sysid_binding`` a claim makes a vehicle of its own instead (counted in
    ``sysid_collisions``), reachable by its :class:`VehicleKey`; ``by_sysid`` stays with the
    first."""

    def __init__(
        self,
        config: MavlinkConfig,
        events: Events,
        lane: PositionLane | None,
        busy: Callable[[VehicleState], bool],
        ratelog: RateLimitedLog | None = None,
    ) -> None:
        self.config = config
        self.ratelog = ratelog
        self.events = events
        self.lane = lane
        self.busy = busy  # states that must not be forgotten now (a transfer in progress)
        self.counters = SenderCounters()
        self.states: dict[StateKey, VehicleState] = {}
        self.by_sysid: dict[int, VehicleState] = {}
        self.addr: dict[int, Address | None] = {}  # id(state) -> its source address
        self.on_forget: list[Callable[[VehicleState], None]] = []
        self._keyed = frozenset(int(s) for s in config.signing_keys)

    def new_state(
        self, link: str, addr: Address | None, sys_id: int, comp_id: int, t_s: float
    ) -> VehicleState | None:
        """The state for a frame with no state yet, or None when the frame must be dropped
        (system id 0, or a claim on a system id bound elsewhere: counted)."""
        if sys_id == 0:
            self.counters.sysid_zero += 1
            return None
        owner = self.by_sysid.get(sys_id)
        if owner is not None and (owner.key.link, self.addr.get(id(owner))) != (link, addr):
            silent_s = t_s - owner.last_heard_t_s
            if (
                owner.key.link == link
                and silent_s >= self.config.address_move_s
                and (sys_id in self._keyed or _host(self.addr.get(id(owner))) == _host(addr))
            ):
                moved = self._move(owner, link, addr, comp_id)
                if moved is not None:
                    return moved
            elif self.config.sysid_binding:
                self.counters.sysid_claims += 1
                return None
            elif comp_id == owner.key.comp_id:
                self.counters.sysid_collisions += 1
                _log.info("sysid %d also at %s on %s (another vehicle)", sys_id, addr, link)
        if len(self.states) >= self.config.max_vehicles:
            self.trim()
        address = "" if addr is None else f"{addr[0]}:{addr[1]}"
        key = VehicleKey(link=link, address=address, sys_id=SysId(sys_id), comp_id=comp_id)
        st = VehicleState(key, self.config, t_s, self.lane, ratelog=self.ratelog)
        self.states[(link, addr, sys_id, comp_id)] = st
        self.addr[id(st)] = addr
        if sys_id not in self.by_sysid:
            self.by_sysid[sys_id] = st
        return st

    def discovered(self, st: VehicleState) -> None:
        """``st`` sent its first autopilot HEARTBEAT: commands to its system id go to it
        unless another autopilot component already has them."""
        owner = self.by_sysid.get(st.sys_id)
        if owner is None or (owner.info is None and owner.key.address == st.key.address):
            self.by_sysid[st.sys_id] = st

    def _move(
        self, owner: VehicleState, link: str, addr: Address | None, comp_id: int
    ) -> VehicleState | None:
        """Rebind ``owner``'s system id to ``addr``; the owner itself when ``comp_id`` is
        its component (re-keyed, its identity kept), else None (a new state is made)."""
        sys_id = int(owner.sys_id)
        old_addr = self.addr.get(id(owner))
        address = "" if addr is None else f"{addr[0]}:{addr[1]}"
        self.counters.address_changes += 1
        _log.warning(
            "sysid %d moved on %s: %s -> %s (silent for %.1f s or more)",
            sys_id,
            link,
            owner.key.address,
            address,
            self.config.address_move_s,
        )
        for k, st in list(self.states.items()):
            if k[0] == owner.key.link and k[1] == old_addr and k[2] == sys_id:
                del self.states[k]
                if st is not owner:
                    self._drop(st)
        if owner.key.comp_id != comp_id:
            self._drop(owner)
            return None
        key = VehicleKey(link=link, address=address, sys_id=SysId(sys_id), comp_id=comp_id)
        owner.key = key
        if owner.info is not None:
            owner.info = VehicleInfo(
                key=key,
                autopilot=owner.info.autopilot,
                vehicle_kind=owner.info.vehicle_kind,
                mav_type=owner.info.mav_type,
                first_heard_t_s=owner.info.first_heard_t_s,
            )
            self.events.on_vehicle(owner.info)
        self.states[(link, addr, sys_id, comp_id)] = owner
        self.addr[id(owner)] = addr
        return owner

    def _drop(self, st: VehicleState) -> None:
        """Forget ``st`` everywhere but ``states`` (the caller removes it there)."""
        self.addr.pop(id(st), None)
        if self.by_sysid.get(st.sys_id) is st:
            del self.by_sysid[st.sys_id]
            # another component at the same address keeps the binding
            for other in self.states.values():
                if other.sys_id == st.sys_id:
                    self.by_sysid[st.sys_id] = other
                    break
        for hook in self.on_forget:
            hook(st)

    def forget(self, keys: list[StateKey]) -> int:
        for k in keys:
            st = self.states.pop(k, None)
            if st is not None:
                self._drop(st)
        self.counters.vehicles_evicted += len(keys)
        return len(keys)

    def trim(self) -> int:
        """Make room for one more state (module docstring: cap)."""
        last = {k: st.last_heard_t_s for k, st in self.states.items()}
        return self.forget(
            over_cap_keys(last, self.config.max_vehicles, lambda k: self.busy(self.states[k]))
        )

    def evict_idle(self, now_s: float) -> int:
        """Forget the states not heard for ``sender_idle_s`` (module docstring: idle)."""
        last = {k: st.last_heard_t_s for k, st in self.states.items()}
        idle = idle_keys(
            last, now_s, self.config.sender_idle_s, lambda k: self.busy(self.states[k])
        )
        return self.forget(idle)

    def on_link(self, link: str) -> list[VehicleState]:
        return [st for k, st in self.states.items() if k[0] == link]


def _host(addr: Address | None) -> str | None:
    return None if addr is None else addr[0]
