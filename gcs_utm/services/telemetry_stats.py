"""Telemetry accounting of the USM: per-source counts and delays (:class:`TelemetryStats`),
the same kept in arrays for the position lane (:class:`LaneStats`), and per-vehicle lookups.

Delays are receipt minus capture time, in clock seconds (see :class:`TelemetryStats`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
import numpy.typing as npt

from gcs_utm.model import LANE_STRIDE, Measurement, SysId

_LANE_FOLD_ENTRIES = 512
"""Lane entries kept before they are added to their sources' statistics (in one pass with
NumPy, ~0.3 ms; reading :attr:`Usm.telemetry` adds them at once)."""
_LANE_RECEIPT = 1  # fields of a PositionLane entry (gcs_utm.model.LANE_STRIDE)
_LANE_CAPTURE = 2


@dataclass(slots=True)
class TelemetryStats:
    """Per-source counts and delays (receipt minus capture, in clock seconds).

    Delays are not clamped at zero: a negative minimum means the vehicle clock runs ahead of
    ours (a clock mapping error), which a clamp would hide."""

    count: int = 0
    first_capture_t_s: float = 0.0
    last_capture_t_s: float = 0.0
    delay_sum_s: float = 0.0
    delay_min_s: float = math.inf
    delay_max_s: float = -math.inf

    def add(self, m: Measurement) -> None:
        t = m.capture_t_s
        if self.count == 0:
            self.first_capture_t_s = t
        self.count += 1
        self.last_capture_t_s = max(self.last_capture_t_s, t)
        delay = m.receipt_t_s - t
        self.delay_sum_s += delay
        self.delay_min_s = min(self.delay_min_s, delay)
        self.delay_max_s = max(self.delay_max_s, delay)

    def combined(self, other: TelemetryStats) -> TelemetryStats:
        """Both sets of reports in one (a source that reached us both ways)."""
        if not other.count:
            return self
        if not self.count:
            return other
        return TelemetryStats(
            count=self.count + other.count,
            first_capture_t_s=min(self.first_capture_t_s, other.first_capture_t_s),
            last_capture_t_s=max(self.last_capture_t_s, other.last_capture_t_s),
            delay_sum_s=self.delay_sum_s + other.delay_sum_s,
            delay_min_s=min(self.delay_min_s, other.delay_min_s),
            delay_max_s=max(self.delay_max_s, other.delay_max_s),
        )

    def as_dict(self, speed: float) -> dict[str, float | int]:
        span = self.last_capture_t_s - self.first_capture_t_s
        # delays are measured on the (possibly sped-up) clock: divide by the speed to get
        # wall-clock seconds, which is what a link's latency really is
        scale = 1.0 / speed if speed not in (0.0, float("inf")) else 1.0
        return {
            "messages": self.count,
            "rate_hz": round((self.count - 1) / span, 3) if span > 0 else 0.0,
            "mean_delay_ms": round(1000.0 * scale * self.delay_sum_s / self.count, 3)
            if self.count
            else 0.0,
            "min_delay_ms": round(1000.0 * scale * self.delay_min_s, 3) if self.count else 0.0,
            "max_delay_ms": round(1000.0 * scale * self.delay_max_s, 3) if self.count else 0.0,
        }


class LaneStats:
    """:class:`TelemetryStats` of every lane source, as arrays indexed by source index.

    Lane entries are added in bursts of at least ``_LANE_FOLD_ENTRIES`` (and whenever
    read), with NumPy: ``ufunc.at`` applies repeated indices one after another in order, so
    every number is the one :meth:`TelemetryStats.add` gives report by report."""

    def __init__(self) -> None:
        self.keys: list[str] = []
        self._count = np.zeros(0, dtype=np.int64)
        self._first = np.zeros(0)
        self._last = np.zeros(0)
        self._sum = np.zeros(0)
        self._min = np.zeros(0)
        self._max = np.zeros(0)
        self._backlog: list[float] = []

    @property
    def size(self) -> int:
        return len(self.keys)

    def append(self, key: str) -> None:
        """One more source (index ``size``), with the statistics key ``key``."""
        self.keys.append(key)
        if len(self.keys) > len(self._count):
            cap = max(64, 2 * len(self._count))

            def grown(a: npt.NDArray[Any], fill: float) -> npt.NDArray[Any]:
                out = np.full(cap, fill, dtype=a.dtype)
                out[: len(a)] = a
                return out

            self._count = grown(self._count, 0)
            self._first = grown(self._first, 0.0)
            self._last = grown(self._last, 0.0)
            self._sum = grown(self._sum, 0.0)
            self._min = grown(self._min, math.inf)
            self._max = grown(self._max, -math.inf)

    def add(self, values: list[float]) -> None:
        self._backlog += values
        if len(self._backlog) >= _LANE_FOLD_ENTRIES * LANE_STRIDE:
            self.fold()

    def fold(self) -> None:
        if not self._backlog:
            return
        a = np.array(self._backlog, dtype=np.float64).reshape(-1, LANE_STRIDE)
        self._backlog = []
        idx = a[:, 0].astype(np.intp)
        cap = a[:, _LANE_CAPTURE]
        delay = a[:, _LANE_RECEIPT] - cap
        used, first_at = np.unique(idx, return_index=True)
        new = self._count[used] == 0
        self._first[used[new]] = cap[first_at[new]]
        np.add.at(self._count, idx, 1)
        np.maximum.at(self._last, idx, cap)
        np.add.at(self._sum, idx, delay)
        np.minimum.at(self._min, idx, delay)
        np.maximum.at(self._max, idx, delay)

    def items(self) -> list[tuple[str, TelemetryStats]]:
        """(key, statistics) per source heard so far (call :meth:`fold` first)."""
        n = self.size
        rows = zip(
            self.keys,
            self._count[:n].tolist(),
            self._first[:n].tolist(),
            self._last[:n].tolist(),
            self._sum[:n].tolist(),
            self._min[:n].tolist(),
            self._max[:n].tolist(),
            strict=True,
        )
        return [
            (key, TelemetryStats(count, first, last, total, low, high))
            for key, count, first, last, total, low, high in rows
            if count
        ]


_T = TypeVar("_T")


def latest_per_sys_id(
    per_vehicle: dict[tuple[SysId, str], _T], when: Callable[[_T], float]
) -> dict[SysId, _T]:
    """Of the entries kept per (system id, vehicle), the one with the latest ``when`` for each
    system id."""
    out: dict[SysId, _T] = {}
    for (sys_id, _), item in per_vehicle.items():
        cur = out.get(sys_id)
        if cur is None or when(item) > when(cur):
            out[sys_id] = item
    return out


@dataclass(slots=True)
class SourceStats:
    """Per measurement source (kind, system id, ICAO, operation, vehicle address): its
    statistics, and whether no operation flies its system id (as of an airspace version)."""

    stats: TelemetryStats
    airspace_version: int = -1
    unknown: bool = False
