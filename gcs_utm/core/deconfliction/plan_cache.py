"""The local conversions (and top speeds) of the plans Tactical Deconfliction sees.

Keyed by the plan object's identity, an entry lives exactly as long as its plan: a weak
reference drops it when the plan is freed. Nobody can ask for a freed plan again (a new plan
at the same address is another object), so the cache holds the plans still in use, the
operations' current plans and the candidates of the decisions under way, and lets every
other candidate go with its decision. Holding every candidate until a size bound instead
(about 1,300 verified candidates an hour in ``gcs-utm bench soak``, each with its waypoints
and local arrays) kept thousands of dead plans alive for hours and grew the process.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable

from gcs_utm.core.deconfliction.geometry import LocalPlan, max_speeds, plan_to_local
from gcs_utm.geo import LocalFrame
from gcs_utm.model import FlightPlan

MAX_ENTRIES = 4096
"""Backstop: the cache starts over when this many plans in use are cached at once."""


class PlanCache:
    """``plan`` -> its :class:`LocalPlan` and (horizontal, vertical) top speeds, computed
    once per plan object and forgotten with it (see the module doc)."""

    def __init__(self, frame: LocalFrame) -> None:
        self.frame = frame
        self._refs: dict[int, weakref.ref[FlightPlan]] = {}
        self._local: dict[int, LocalPlan] = {}
        self._speeds: dict[int, tuple[float, float]] = {}

    def __len__(self) -> int:
        """Plans cached (each one still alive)."""
        return len(self._refs)

    def local(self, plan: FlightPlan) -> LocalPlan:
        key = self._key(plan)
        hit = self._local.get(key)
        if hit is None:
            hit = self._local[key] = plan_to_local(plan, self.frame)
        return hit

    def remember(self, plan: FlightPlan, local: LocalPlan) -> None:
        """``plan``'s local form, known already (a candidate just converted from it)."""
        self._local[self._key(plan)] = local

    def max_speeds(self, plan: FlightPlan) -> tuple[float, float]:
        key = self._key(plan)
        hit = self._speeds.get(key)
        if hit is None:
            hit = self._speeds[key] = max_speeds(self.local(plan))
        return hit

    def _key(self, plan: FlightPlan) -> int:
        """``plan``'s key, watched from now on so that its entries go when it goes."""
        key = id(plan)
        ref = self._refs.get(key)
        if ref is not None and ref() is plan:
            return key
        if len(self._refs) >= MAX_ENTRIES:
            self._refs.clear()
            self._local.clear()
            self._speeds.clear()
        self._forget(key)
        self._refs[key] = weakref.ref(plan, self._dropped(key))
        return key

    def _dropped(self, key: int) -> Callable[[weakref.ref[FlightPlan]], None]:
        """The callback of ``key``'s weak reference: forget the entries of the plan freed
        (unless the key was taken over since, which only a backstop clear can cause)."""

        def forget(ref: weakref.ref[FlightPlan]) -> None:
            if self._refs.get(key) is ref:
                self._forget(key)

        return forget

    def _forget(self, key: int) -> None:
        self._refs.pop(key, None)
        self._local.pop(key, None)
        self._speeds.pop(key, None)
