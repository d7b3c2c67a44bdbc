"""Filed 4D plans in a space-time index: the strategic check at the scale of a whole airspace.

Each plan, (K, 4) east_m, north_m, alt_amsl_m, t_s in the local frame and piecewise linear in
time, is cut at fixed time windows (multiples of ``window_s`` since the epoch, the same for
every plan). Per window, the box of the plan's positions in it (its waypoints there and its
positions at the window's ends; straight legs, so every position of the window is in it) is
grown by the plan's half minimum per axis: ``max(min / 2, own operational volume)``, plus a
millimetre for rounding. Two plans can lose separation at an instant only when both are
airborne then, i.e. in the same window, and their grown boxes overlap there, because the
pair's minimum (``MonitoringConfig.effective_minima``: the configured minimum, never below the
sum of the two volumes) is at most the sum of the two growths. So the index never drops a
pair the exact check would report; it only spares the exact check the pairs that cannot
conflict.

- All pairs of N plans (:func:`candidate_pairs`): per window, the boxes go through
  Monitoring's 4D grid (``separation._same_cell_pairs``: packed cell keys, one integer sort,
  same-cell neighbours), then the grown boxes are compared.
- One plan against N filed plans (:class:`PlanIndex`): the filed boxes are kept sorted by
  window; a query compares the new plan's box in each of its windows with the filed boxes of
  that window only (a slice), so its cost is that of the plans airborne at the same time, and
  nothing else is re-checked. Plans can be added and withdrawn one at a time.

The exact check of each candidate pair is the strategic kernel
(``pair_check.check_pairs``); the reference it is tested against is the all-pairs loop in
``tests/monitoring/strategic_oracle.py``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.geometry import FloatArray
from gcs_utm.core.monitoring.separation import _same_cell_pairs

IntArray = npt.NDArray[np.int64]

# Added to every growth: the boxes come from a different rounding of the same positions than
# the exact kernel's samples (np.interp); a millimetre covers that many times over.
_ROUNDING_M = 1e-3


def window_s_of(config: MonitoringConfig, step_s: float) -> float:
    """Time window of the strategic index: Monitoring's grid cell duration, at least the
    check's sampling step (a window shorter than a step only adds entries)."""
    return max(config.grid_dt_s, step_s, 1e-3)


def growth_m(config: MonitoringConfig, volume_m: FloatArray) -> FloatArray:
    """(N, 3) growth per axis of each plan's window boxes: half the configured minimum or its
    own operational volume, whichever is larger (see the module doc), plus rounding."""
    vol = np.asarray(volume_m, np.float64)
    if config.spherical:
        h = v = config.safety_distance_m / 2.0
    else:
        h = config.separation_horizontal_m / 2.0
        v = config.separation_vertical_m / 2.0
    gh = np.maximum(h, vol) + _ROUNDING_M
    gv = np.maximum(v, vol) + _ROUNDING_M
    return np.column_stack([gh, gh, gv])


@dataclass(frozen=True, slots=True)
class WindowBoxes:
    """Per (plan, window) entry, sorted by plan then window: ``plan`` (E,) row of the plan in
    the list given, ``window`` (E,) window number (floor(t_s / window_s)), ``lo``/``hi`` (E, 3)
    the grown box."""

    plan: IntArray
    window: IntArray
    lo: FloatArray
    hi: FloatArray


def window_boxes(plans: Sequence[FloatArray], grow_m: FloatArray, window_s: float) -> WindowBoxes:
    """The grown box of every plan in every window it is airborne in (vectorised over all
    legs of all plans). ``grow_m`` (N, 3) as :func:`growth_m`."""
    if not plans:
        z = np.empty(0, np.int64)
        return WindowBoxes(z, z, np.empty((0, 3)), np.empty((0, 3)))
    # Legs: consecutive waypoints; a single waypoint is a leg from it to itself.
    legs0: list[FloatArray] = []
    legs1: list[FloatArray] = []
    for p in plans:
        q = p if len(p) >= 2 else np.vstack([p, p])
        legs0.append(q[:-1])
        legs1.append(q[1:])
    counts = np.array([len(x) for x in legs0], np.int64)
    a = np.concatenate(legs0)
    b = np.concatenate(legs1)
    owner = np.repeat(np.arange(len(plans), dtype=np.int64), counts)
    ta, tb = a[:, 3], b[:, 3]
    w0 = np.floor(ta / window_s).astype(np.int64)
    w1 = np.floor(tb / window_s).astype(np.int64)
    # Pieces: each leg cut at the window ends it spans (a leg of windows w0..w1 has w1-w0+1).
    n_pieces = w1 - w0 + 1
    leg = np.repeat(np.arange(len(a), dtype=np.int64), n_pieces)
    first = np.cumsum(n_pieces) - n_pieces
    win = w0[leg] + (np.arange(len(leg), dtype=np.int64) - first[leg])
    t_lo = np.maximum(ta[leg], win * window_s)
    t_hi = np.minimum(tb[leg], (win + 1) * window_s)
    dt = (tb - ta)[leg]
    moving = dt > 0
    span = np.where(moving, dt, 1.0)
    f0 = np.where(moving, (t_lo - ta[leg]) / span, 0.0)[:, None]
    f1 = np.where(moving, (t_hi - ta[leg]) / span, 0.0)[:, None]
    d = (b - a)[leg, :3]
    p0 = a[leg, :3] + f0 * d
    p1 = a[leg, :3] + f1 * d
    lo = np.minimum(p0, p1)
    hi = np.maximum(p0, p1)
    # A jump (two waypoints at one time, different positions): the exact check samples the
    # plan with np.interp, which spreads the jump over the sample interval before it, so
    # its positions there are not the plan's. Such a plan gets its whole box (every sample
    # of it lies there) in each of its windows.
    jump = (dt == 0) & np.any(d != 0, axis=1)
    if jump.any():
        jumpy = np.zeros(len(plans), bool)
        jumpy[owner[leg[jump]]] = True
        for i in np.flatnonzero(jumpy).tolist():
            sel = owner[leg] == i
            lo[sel] = plans[i][:, :3].min(axis=0)
            hi[sel] = plans[i][:, :3].max(axis=0)
    # One entry per (plan, window): pieces are in plan, then time order.
    pl = owner[leg]
    new = np.ones(len(leg), bool)
    new[1:] = (pl[1:] != pl[:-1]) | (win[1:] != win[:-1])
    starts = np.flatnonzero(new)
    plan_e = pl[starts]
    grow = np.asarray(grow_m, np.float64)[plan_e]
    return WindowBoxes(
        plan=plan_e,
        window=win[starts],
        lo=np.minimum.reduceat(lo, starts, axis=0) - grow,
        hi=np.maximum.reduceat(hi, starts, axis=0) + grow,
    )


def _overlap(
    lo_a: FloatArray, hi_a: FloatArray, lo_b: FloatArray, hi_b: FloatArray
) -> npt.NDArray[np.bool_]:
    out: npt.NDArray[np.bool_] = np.all((lo_a <= hi_b) & (lo_b <= hi_a), axis=-1)
    return out


def candidate_pairs(boxes: WindowBoxes, n: int, cell_m: FloatArray) -> IntArray:
    """Sorted codes ``a * n + b`` (a < b, plan rows) of the pairs whose grown boxes overlap in
    at least one common window, through Monitoring's grid, one window at a time."""
    order = np.argsort(boxes.window, kind="stable")
    win = boxes.window[order]
    plan = boxes.plan[order]
    lo_s = boxes.lo[order]
    hi_s = boxes.hi[order]
    edges = np.flatnonzero(np.diff(win)) + 1
    bounds = np.concatenate([[0], edges, [len(win)]])
    found: list[IntArray] = []
    for s, e in zip(bounds[:-1].tolist(), bounds[1:].tolist(), strict=True):
        if e - s < 2:
            continue
        lo = lo_s[s:e]
        hi = hi_s[s:e]
        bits = max(1, int(e - s - 1).bit_length())
        ia, ib = _same_cell_pairs(
            np.ascontiguousarray(lo.T), np.ascontiguousarray(hi.T), cell_m, bits
        )
        if len(ia) == 0:
            continue
        keep = _overlap(lo[ia], hi[ia], lo[ib], hi[ib])
        pa = plan[s:e][ia[keep]]
        pb = plan[s:e][ib[keep]]
        found.append(np.minimum(pa, pb) * n + np.maximum(pa, pb))
    if not found:
        return np.empty(0, np.int64)
    return np.unique(np.concatenate(found))


def grid_cell_m(config: MonitoringConfig, boxes: WindowBoxes) -> FloatArray:
    """Cell size: Monitoring's configured cell, enlarged to the median box (most boxes then
    touch at most two cells per axis, as in Monitoring's grid)."""
    cell = np.array([config.grid_dx_m, config.grid_dy_m, config.grid_dz_m])
    if len(boxes.lo) == 0:
        return cell
    out: FloatArray = np.maximum(cell, np.median(boxes.hi - boxes.lo, axis=0))
    return out


class PlanIndex:
    """Filed plans by time window, for checking ONE plan against all of them.

    ``add`` files a plan under a key (any hashable id, e.g. the operation id) with its own
    growth; ``remove`` withdraws it; ``candidates`` returns the keys, in filing order, whose
    boxes overlap the query's in a common window. Additions go to a small pending part that a
    query scans directly and that is merged into the sorted part once it grows past an eighth
    of it, so filing stays cheap and a query never re-sorts the whole airspace."""

    def __init__(self, window_s: float) -> None:
        if not window_s > 0:
            raise ValueError(f"window_s must be positive, got {window_s}")
        self.window_s = window_s
        self._keys: list[object] = []  # filing order; row = position here
        self._alive: list[bool] = []
        self._row: dict[object, int] = {}
        self._sorted = _Entries.empty()
        self._pending: list[_Entries] = []
        self._pending_n = 0

    def __len__(self) -> int:
        return len(self._row)

    def __contains__(self, key: object) -> bool:
        return key in self._row

    def add(self, key: object, plan: FloatArray, grow_m: FloatArray) -> None:
        """File ``plan`` (K, 4) under ``key`` (replacing what was filed under it)."""
        if key in self._row:
            self.remove(key)
        row = len(self._keys)
        self._keys.append(key)
        self._alive.append(True)
        self._row[key] = row
        wb = window_boxes([plan], np.asarray(grow_m, np.float64).reshape(1, 3), self.window_s)
        entries = _Entries(np.full(len(wb.window), row, np.int64), wb.window, wb.lo, wb.hi)
        self._pending.append(entries)
        self._pending_n += len(entries.window)
        if self._pending_n * 8 > len(self._sorted.window) + 64:
            self._merge()

    def add_many(
        self, keys: Sequence[object], plans: Sequence[FloatArray], grow_m: FloatArray
    ) -> None:
        """File many plans at once (one vectorised pass)."""
        for key in keys:
            if key in self._row:
                self.remove(key)
        base = len(self._keys)
        for k, key in enumerate(keys):
            self._keys.append(key)
            self._alive.append(True)
            self._row[key] = base + k
        wb = window_boxes(plans, grow_m, self.window_s)
        self._pending.append(_Entries(wb.plan + base, wb.window, wb.lo, wb.hi))
        self._pending_n += len(wb.window)
        self._merge()

    def remove(self, key: object) -> bool:
        """Withdraw the plan filed under ``key``; False if there is none."""
        row = self._row.pop(key, None)
        if row is None:
            return False
        self._alive[row] = False
        return True

    def keys(self) -> list[object]:
        return [k for k, alive in zip(self._keys, self._alive, strict=True) if alive]

    def candidates(self, plan: FloatArray, grow_m: FloatArray) -> list[object]:
        """Keys (filing order) of the filed plans whose grown boxes overlap ``plan``'s, grown
        by ``grow_m`` (3,), in a common window."""
        q = window_boxes([plan], np.asarray(grow_m, np.float64).reshape(1, 3), self.window_s)
        rows: list[IntArray] = [self._sorted.overlapping(q)]
        rows.extend(p.overlapping_unsorted(q) for p in self._pending)
        hit = np.unique(np.concatenate(rows))
        alive = self._alive
        keys = self._keys
        return [keys[r] for r in hit.tolist() if alive[r]]

    def _merge(self) -> None:
        parts = [self._sorted, *self._pending]
        rows = np.concatenate([p.row for p in parts])
        keep = np.asarray(self._alive, bool)[rows] if len(rows) else np.empty(0, bool)
        merged = _Entries(
            rows[keep],
            np.concatenate([p.window for p in parts])[keep],
            np.concatenate([p.lo for p in parts])[keep],
            np.concatenate([p.hi for p in parts])[keep],
        )
        self._sorted = merged.sorted_by_window()
        self._pending = []
        self._pending_n = 0


@dataclass(frozen=True, slots=True)
class _Entries:
    row: IntArray
    window: IntArray
    lo: FloatArray
    hi: FloatArray

    @staticmethod
    def empty() -> _Entries:
        z = np.empty(0, np.int64)
        return _Entries(z, z, np.empty((0, 3)), np.empty((0, 3)))

    def sorted_by_window(self) -> _Entries:
        order = np.argsort(self.window, kind="stable")
        return _Entries(self.row[order], self.window[order], self.lo[order], self.hi[order])

    def overlapping(self, q: WindowBoxes) -> IntArray:
        """Rows of the entries (sorted by window) overlapping a query box of their window."""
        if len(self.window) == 0 or len(q.window) == 0:
            return np.empty(0, np.int64)
        start = np.searchsorted(self.window, q.window, side="left")
        end = np.searchsorted(self.window, q.window, side="right")
        size = end - start
        total = int(size.sum())
        if total == 0:
            return np.empty(0, np.int64)
        which = np.repeat(np.arange(len(size), dtype=np.int64), size)
        idx = np.arange(total, dtype=np.int64) - np.repeat(np.cumsum(size) - size, size)
        idx += start[which]
        keep = _overlap(self.lo[idx], self.hi[idx], q.lo[which], q.hi[which])
        out: IntArray = self.row[idx[keep]]
        return out

    def overlapping_unsorted(self, q: WindowBoxes) -> IntArray:
        """As :meth:`overlapping` for a small unsorted part (every entry against the query's
        box of the same window)."""
        if len(self.window) == 0 or len(q.window) == 0:
            return np.empty(0, np.int64)
        pos = np.searchsorted(q.window, self.window)
        pos = np.minimum(pos, len(q.window) - 1)
        same = q.window[pos] == self.window
        keep = same & _overlap(self.lo, self.hi, q.lo[pos], q.hi[pos])
        out: IntArray = self.row[keep]
        return out
