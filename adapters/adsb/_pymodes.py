"""The one place that touches pyModeS (untyped): decoding one hex frame into a plain dict.

pyModeS 3 errors (``pyModeS.DecodeError`` and subclasses) are translated to
:class:`~adapters.adsb.errors.ModeSFrameError` here.
"""

from __future__ import annotations

from typing import Any

import pyModeS

from adapters.adsb.errors import ModeSFrameError


def decode_reference(frame: str, reference: tuple[float, float]) -> dict[str, Any]:
    """Decode one frame; airborne (and surface) CPR resolved against ``reference`` (lat, lon)."""
    try:
        result = pyModeS.decode(frame, reference=reference, surface_ref=reference)
    except (pyModeS.DecodeError, ValueError) as exc:
        raise ModeSFrameError(frame, str(exc)) from exc
    return dict(result)


# PipeDecoder's per-ICAO tables (pyModeS 3): what :meth:`PairDecoder.forget` clears. A name
# missing in another pyModeS version is skipped; ``_state`` is the one that must exist.
_PER_ICAO_TABLES = (
    "_state",
    "_pending_even",
    "_pending_odd",
    "_trusted_icaos",
    "_adsb_altitude",
    "_adsb_velocity",
    "_position_history",
    "_airborne_position_reference",
    "_bootstrap",
)


class PairDecoder:
    """pyModeS's stateful ``PipeDecoder`` (even/odd CPR pairs, no reference needed).

    Its per-ICAO state expires after ``idle_s`` (pyModeS ``eviction_ttl``), but pyModeS only
    sweeps when a frame comes: :meth:`evict_idle` sweeps without one, and :meth:`forget`
    drops chosen addresses (the caller's cap)."""

    def __init__(self, idle_s: float = 300.0) -> None:
        self._pipe: Any = pyModeS.PipeDecoder(eviction_ttl=idle_s)

    def decode(self, frame: str, t_s: float) -> dict[str, Any]:
        try:
            result = self._pipe.decode(frame, timestamp=t_s)
        except (pyModeS.DecodeError, ValueError) as exc:
            raise ModeSFrameError(frame, str(exc)) from exc
        out = dict(result)
        if "error" in out:
            raise ModeSFrameError(frame, str(out["error"]))
        return out

    def last_heard_t_s(self) -> dict[str, float]:
        """ICAO address (as pyModeS spells it) -> when its state was last written."""
        return {
            icao: float(st.get("_last_seen", float("inf")))
            for icao, st in self._pipe._state.items()
        }

    def size(self) -> int:
        """Addresses with any state (the largest per-ICAO table)."""
        return max(len(getattr(self._pipe, name, ())) for name in _PER_ICAO_TABLES)

    def forget(self, icaos: list[str]) -> None:
        """Drop every state of ``icaos`` (any case: pyModeS spells them upper-case)."""
        keys = [icao.upper() for icao in icaos]
        for name in _PER_ICAO_TABLES:
            table = getattr(self._pipe, name, None)
            if isinstance(table, dict):
                for icao in keys:
                    table.pop(icao, None)

    def evict_idle(self, now_s: float) -> int:
        """pyModeS's own expiry sweep at ``now_s``; returns how many addresses it dropped."""
        before = len(self._pipe._state)
        self._pipe._evict_expired(now_s)
        return before - len(self._pipe._state)
