"""Altitude offsets from the plan that persist (see :meth:`.tracker.Tracker.predict`).

A UAS that follows its plan is predicted on the plan plus its current offset decaying with
``plan_offset_decay_s``: the autopilot steers a cross-track error back. An altitude offset
is often not steered back at all: the vehicle's altitude reference differs from the UTM's
(barometer against GNSS, a home altitude off by a metre), or it holds its altitude a little
off. Decayed, such an offset disappeared from the prediction and a pass a few centimetres
inside the vertical minimum was predicted only seconds before it happened.

An offset is *persistent* when the filtered altitude has stayed on the same side of the plan
for at least ``window_s`` of track time: a single noisy sample never makes one, and an
offset that changes sign starts over. Its size is the smallest seen over the last one to two
windows (two blocks of ``window_s``, the older dropped as a new one starts), so it is never
larger than what the track showed all along, and follows a shrinking offset at once. The
prediction keeps that part and decays only the rest. Pure; one row per track row.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]


class AltitudeOffsets:
    """Per track row: the sign of the current same-sign run of altitude offsets, when it
    started, the smallest offset size in the current and the previous block, the start of
    the current block and the time of the last sample (all track state times, s)."""

    def __init__(self, window_s: float) -> None:
        self.window_s = window_s
        self._sign = np.zeros(0)
        self._run_t0 = np.zeros(0)
        self._blk_t0 = np.zeros(0)
        self._cur_m = np.zeros(0)
        self._prev_m = np.zeros(0)
        self._last_t = np.zeros(0)

    _NAMES = ("_sign", "_run_t0", "_blk_t0", "_cur_m", "_prev_m", "_last_t")

    def grow(self, cap: int, n: int) -> None:
        """Room for ``cap`` rows, keeping the first ``n``."""
        for name in self._NAMES:
            old = getattr(self, name)
            new = np.zeros(cap)
            new[:n] = old[:n]
            setattr(self, name, new)
        self.reset(np.arange(n, cap, dtype=np.intp))

    def reset(self, rows: IntArray) -> None:
        """Forget rows ``rows`` (a new track: no run yet)."""
        self._sign[rows] = 0.0
        self._last_t[rows] = -np.inf

    def compact(self, keep: IntArray) -> None:
        """Rows ``keep`` become rows 0..len(keep)-1 (as the tracker's arrays)."""
        for name in self._NAMES:
            arr = getattr(self, name)
            arr[: len(keep)] = arr[keep]

    def observe(self, rows: IntArray, t_s: FloatArray, offset_m: FloatArray) -> None:
        """Samples ``offset_m`` (altitude minus the plan's, m) of rows ``rows`` at their
        state times ``t_s``; a row whose state time has not moved since its last sample
        (no new measurement) is not counted again."""
        new = t_s > self._last_t[rows]
        rows, t, off = rows[new], t_s[new], offset_m[new]
        size = np.abs(off)
        sign = np.sign(off)
        restart = sign != self._sign[rows]
        roll = ~restart & (t - self._blk_t0[rows] >= self.window_s)
        keep = ~restart & ~roll
        cur = self._cur_m[rows]
        self._prev_m[rows] = np.where(restart, np.inf, np.where(roll, cur, self._prev_m[rows]))
        self._cur_m[rows] = np.where(keep, np.minimum(cur, size), size)
        self._blk_t0[rows] = np.where(keep, self._blk_t0[rows], t)
        self._run_t0[rows] = np.where(restart, t, self._run_t0[rows])
        self._sign[rows] = sign
        self._last_t[rows] = t

    def persistent(self, rows: IntArray) -> FloatArray:
        """The persistent altitude offset of rows ``rows`` (m, 0 where there is none)."""
        held = self._last_t[rows] - self._run_t0[rows] >= self.window_s
        size = np.minimum(self._cur_m[rows], self._prev_m[rows])
        out: FloatArray = np.where(held & (self._sign[rows] != 0.0), self._sign[rows] * size, 0.0)
        return out


def keep_persistent(
    alt: FloatArray,
    rows: IntArray,
    bias_m: FloatArray,
    ahead0_s: FloatArray,
    steps_s: FloatArray,
    *,
    decay_s: float,
) -> None:
    """Put the persistent altitude offsets ``bias_m`` of rows ``rows`` back into their
    plan-following prediction ``alt`` (N, K), in place. That prediction is the plan plus the
    whole offset decaying as exp(-max(a0 + k step, 0) / T) (:func:`.prediction.follow`);
    with the persistent part kept, it is the plan plus the bias plus the rest decaying, i.e.
    ``alt + bias * (1 - decay)``."""
    some = bias_m != 0.0
    rows, bias = rows[some], bias_m[some]
    if len(rows) == 0:
        return
    decay = np.exp(-np.maximum(np.add.outer(ahead0_s[rows], steps_s), 0.0) / decay_s)
    alt[rows] += bias[:, None] * (1.0 - decay)
