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


class PairDecoder:
    """pyModeS's stateful ``PipeDecoder`` (even/odd CPR pairs, no reference needed)."""

    def __init__(self) -> None:
        self._pipe: Any = pyModeS.PipeDecoder()

    def decode(self, frame: str, t_s: float) -> dict[str, Any]:
        try:
            result = self._pipe.decode(frame, timestamp=t_s)
        except (pyModeS.DecodeError, ValueError) as exc:
            raise ModeSFrameError(frame, str(exc)) from exc
        out = dict(result)
        if "error" in out:
            raise ModeSFrameError(frame, str(out["error"]))
        return out
