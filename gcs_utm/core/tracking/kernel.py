"""The tracker's two per-measurement kernels, each one function with a NumPy reference and an
optional C implementation (``_kalman_c.c``, built by ``pip install`` where a C compiler is
present) that computes the same thing bit for bit (the tests compare them):

- :func:`entry_records` (reference :func:`check_entries`): the checks of each entry (finite,
  in range, capture time not after receipt + ``max_future_s``, measured speed) and its record
  (:mod:`.layout`);
- :func:`update_rows`: the common round, in which every measurement simply updates its own
  track (no gate, duplicate or out-of-order rejection, no new track). Its NumPy reference is
  the tracker's general round (``Tracker._round`` with :func:`.kalman.step`); the C kernel
  takes the common case for any number of rows and declines anything else.

The C kernel exports its copy of the layouts; a build that disagrees with :mod:`.layout` (a
stale build) is refused at import with an error that says how to rebuild.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from gcs_utm.core.tracking.layout import (
    C_LAYOUT,
    ENT_ALT,
    ENT_EPH,
    ENT_EPV,
    ENT_RCV,
    ENT_SRC,
    ENT_T,
    ENT_VD,
    ENT_VE,
    ENT_VN,
    ENTRY_STRIDE,
    MAX_ALT_AMSL_M,
    MIN_ALT_AMSL_M,
    NCOL,
    REC_ALT,
    REC_HAS_VEL,
    REC_R,
    REC_RV,
    REC_SRC,
    REC_T,
    REC_VE,
    REC_VN,
    REC_VU,
)

try:  # the optional C kernel: the same results
    from gcs_utm.core.tracking import _kalman_c as _c
except ImportError:  # pragma: no cover - built by every install with a C compiler
    _c = None  # type: ignore[assignment]

if _c is not None and tuple(getattr(_c, "LAYOUT", ())) != C_LAYOUT:  # pragma: no cover
    raise ImportError(
        "gcs_utm.core.tracking._kalman_c was built from another version of the layouts or "
        "arguments in gcs_utm/core/tracking/layout.py: rebuild it (pip install -e .)"
    )

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]
BoolArray = npt.NDArray[np.bool_]


def name() -> str:
    """Which implementation runs: "c" (the extension is built) or "numpy"."""
    return "c" if _c is not None else "numpy"


def entry_records(  # noqa: PLR0917 (the checks' parameters, as the C function takes them)
    values: Sequence[float],
    defaults: tuple[tuple[float, float, float], ...],
    kinds: IntArray | None,
    has_vel: BoolArray | None,
    min_sigma_m: float,
    max_future_s: float,
    max_speed_mps: float,
    north_dir: tuple[float, float],
) -> tuple[IntArray, FloatArray, int, int]:
    """Checks and records of entries (a flat sequence of :data:`ENTRY_STRIDE` numbers per
    entry); ``defaults``: (eph, epv, velocity sigma) per source index; the other arguments as
    :func:`check_entries` takes them. In C when it is built, else :func:`check_entries`."""
    if _c is not None:
        k = len(values) // ENTRY_STRIDE
        a = np.empty((NCOL, k))
        idx = np.empty(k, dtype=np.intp)
        m, invalid, gate = _c.entry_records(
            values, a, idx, defaults, min_sigma_m, max_future_s, max_speed_mps**2, north_dir,
            MIN_ALT_AMSL_M, MAX_ALT_AMSL_M, kinds, has_vel,
        )  # fmt: skip
        if m < k:
            return idx[:m], a[:, :m].copy(), invalid, gate
        return idx, a, invalid, gate
    v = np.array(values, dtype=np.float64).reshape(-1, ENTRY_STRIDE).T.copy()
    table = np.array(defaults, dtype=np.float64)
    return check_entries(
        v, table, kinds, has_vel, min_sigma_m, max_future_s, max_speed_mps, north_dir
    )


def check_entries(  # noqa: PLR0917
    v: FloatArray,
    defaults: FloatArray,
    kind: IntArray | None,
    has_vel: BoolArray | None,
    min_sigma_m: float,
    max_future_s: float,
    max_speed_mps: float,
    north_dir: tuple[float, float],
) -> tuple[IntArray, FloatArray, int, int]:
    """The NumPy reference of the checks and records: entries ``v`` (ENTRY_STRIDE, K), one
    contiguous row per field; ``defaults`` (sources, 3) = (eph, epv, velocity sigma) per
    source index; ``kind`` (K,) each entry's source index (None: all 0); ``has_vel`` (K,)
    whether a velocity was measured (None: all; a missing one is given as zeros). Returns
    (the passing entries' ``ENT_SRC`` values, records (NCOL, M), invalid, gate)."""
    if v.shape[1] == 0:
        return np.zeros(0, dtype=np.intp), np.empty((NCOL, 0)), 0, 0
    vn, ve, vd = v[ENT_VN : ENT_VD + 1]
    sig = v[ENT_EPH : ENT_EPV + 1]  # eph, epv; nan: unknown
    # each entry's defaults: scalars when every entry is of source 0, else rows
    dflt: Any = defaults[0].tolist() if kind is None else defaults[kind].T
    with np.errstate(all="ignore"):  # nan and inf fail the checks
        speed2 = vn * vn + ve * ve + vd * vd
        sig_lo = np.fmin.reduce(sig, axis=1).tolist()  # (fmin skips nan)
        if _all_pass(v, sig, sig_lo, speed2, max_future_s, max_speed_mps):
            invalid = gate = 0
            sel: IntArray | slice = slice(None)
        else:
            sel, invalid, gate = _passing(v, sig, speed2, dflt, max_future_s, max_speed_mps)
    idx = v[ENT_SRC, sel].astype(np.intp)
    a = _records(v, sel, sig_lo, dflt, kind, has_vel, min_sigma_m, north_dir)
    return idx, a, invalid, gate


def _all_pass(  # noqa: PLR0917
    v: FloatArray,
    sig: FloatArray,
    sig_lo: list[float],
    speed2: FloatArray,
    max_future_s: float,
    max_speed_mps: float,
) -> bool:
    """The common case: a few reductions tell that every entry passes (a nan anywhere makes
    its reduction nan, and the comparison false)."""
    rcv, t = v[ENT_RCV], v[ENT_T]
    lo = v[ENT_RCV : ENT_ALT + 1].min(axis=1).tolist()  # rcv, t, lon, lat, alt
    hi = v[ENT_RCV : ENT_ALT + 1].max(axis=1).tolist()
    sig_hi = np.fmax.reduce(sig, axis=1).tolist()  # (fmax skips nan)
    return (
        -math.inf < lo[1]
        and hi[1] < math.inf
        and lo[2] >= -180.0
        and hi[2] <= 180.0
        and lo[3] >= -90.0
        and hi[3] <= 90.0
        and lo[4] >= MIN_ALT_AMSL_M
        and hi[4] <= MAX_ALT_AMSL_M
        and not float(np.fmax.reduce(t - rcv)) > max_future_s  # (nan rcv: passes)
        and not (sig_lo[0] < 0.0 or sig_lo[1] < 0.0)
        and not (sig_hi[0] == math.inf or sig_hi[1] == math.inf)
        and float(speed2.max()) <= max_speed_mps**2
    )


def _passing(  # noqa: PLR0917
    v: FloatArray,
    sig: FloatArray,
    speed2: FloatArray,
    dflt: Any,
    max_future_s: float,
    max_speed_mps: float,
) -> tuple[IntArray, int, int]:
    """Entry by entry: (the passing entries, invalid, gate)."""
    rcv, t, lon, lat, alt, vn, ve, vd = v[ENT_RCV : ENT_VD + 1]
    eph_d, epv_d, _ = dflt
    ok = (
        np.isfinite(t)
        & (lat >= -90.0)
        & (lat <= 90.0)
        & (lon >= -180.0)
        & (lon <= 180.0)
        & (alt >= MIN_ALT_AMSL_M)
        & (alt <= MAX_ALT_AMSL_M)
        & ~((t - rcv > max_future_s) & np.isfinite(rcv))
    )
    eph = np.where(np.isnan(sig[0]), eph_d, sig[0])  # unknown: the default
    epv = np.where(np.isnan(sig[1]), epv_d, sig[1])
    ok_sigma = np.isfinite(eph) & np.isfinite(epv) & (eph >= 0.0) & (epv >= 0.0)
    invalid = int(np.count_nonzero(~ok)) + int(np.count_nonzero(ok & ~ok_sigma))
    ok &= ok_sigma
    fast = ~(speed2 <= max_speed_mps**2)
    finite_v = np.isfinite(vn) & np.isfinite(ve) & np.isfinite(vd)
    gate = int(np.count_nonzero(ok & fast & finite_v))
    invalid += int(np.count_nonzero(ok & fast & ~finite_v))
    ok &= ~fast
    return np.flatnonzero(ok), invalid, gate


def _records(  # noqa: PLR0917
    v: FloatArray,
    sel: IntArray | slice,
    sig_lo: list[float],
    dflt: Any,
    kind: IntArray | None,
    has_vel: BoolArray | None,
    min_sigma_m: float,
    north_dir: tuple[float, float],
) -> FloatArray:
    """The records (NCOL, M) of the passing entries ``sel``."""
    eph_d, epv_d, vsig = dflt
    sig = v[ENT_EPH : ENT_EPV + 1]
    n = v[ENT_SRC, sel].shape[0]
    a = np.empty((NCOL, n))
    a[REC_T : REC_ALT + 1] = v[ENT_T : ENT_ALT + 1, sel]  # t, lon, lat, alt: the record's order
    # NED (true north/east) -> grid east/north: north along north_dir, east 90 deg right of it
    nd_e, nd_n = north_dir
    vn = v[ENT_VN, sel]
    ve = v[ENT_VE, sel]
    a[REC_VE] = vn * nd_e + ve * nd_n
    a[REC_VN] = vn * nd_n - ve * nd_e
    np.negative(v[ENT_VD, sel], out=a[REC_VU])
    for k, default, first in ((0, eph_d, REC_R), (1, epv_d, REC_R + 2)):
        d = default if kind is None else default[sel]
        if math.isnan(sig_lo[k]):  # unknown throughout: the default's variance
            e = np.maximum(d, min_sigma_m)
        else:
            e = np.where(np.isnan(sig[k, sel]), d, sig[k, sel])
            np.maximum(e, min_sigma_m, out=e)
        a[first] = e * e
    a[REC_R + 1] = a[REC_R]  # east and north: eph
    vs = vsig if kind is None else vsig[sel]
    a[REC_RV : REC_RV + 3] = vs * vs
    if kind is None:
        a[REC_SRC] = 0.0
    else:
        a[REC_SRC] = kind[sel]
    if has_vel is None:
        a[REC_HAS_VEL] = 1.0
    else:
        hv = has_vel[sel]
        a[REC_HAS_VEL] = hv
        a[REC_VE : REC_VU + 1, ~hv] = 0.0  # not measured: zero, as the record says
    return a


def update_rows(  # noqa: PLR0917 (the tracker's arrays, as the C function takes them)
    rw: IntArray,
    a: FloatArray,
    state: tuple[FloatArray, FloatArray, FloatArray, FloatArray],
    counts: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], BoolArray],
    q: tuple[float, float, float],
    max_jump_m: float,
    gate_margin_m: float,
    max_speed_mps: float,
    restart_after_s: float,
) -> bool:
    """The common round of rows ``rw`` (existing tracks, each once) with records ``a`` (NCOL,
    M, projected) in C, in place on ``state`` = (x, p, t, src_t) and ``counts`` = (updates,
    gate_fails, stale). False (nothing changed) when the C kernel is absent or one
    measurement would not simply update its track (among them one more than
    ``restart_after_s`` after its track's state: it restarts the track): the NumPy round
    decides then."""
    if _c is None:
        return False
    x, p, t, src_t = state
    updates, gate_fails, stale = counts
    return _c.update_rows(
        rw, a, x, p, t, src_t, updates, gate_fails, stale, q, max_jump_m, gate_margin_m,
        max_speed_mps, restart_after_s,
    )  # fmt: skip
