"""The flat layouts the tracker's kernels share, defined here once.

Record (one per measurement that reaches a track; a batch is one (NCOL, N) float64 array, so
each quantity is one contiguous row): capture time; longitude and latitude, replaced by east
and north once projected (so east, north, alt are the position measurement z, contiguous); the
grid velocity (east, north, up; zero when not measured); the position variances (east, north,
up) [m^2]; the velocity variances [m^2/s^2] (the same on every axis, three times); the source
index (see :data:`SOURCE_INDEX`); 1.0 if a velocity was measured.

Entry (one per measurement before its checks, :data:`ENTRY_STRIDE` numbers): the layout of a
:class:`~gcs_utm.model.PositionLane` entry -- source (the lane's source index, or the
measurement's position in its batch), receipt and capture time, lon, lat, alt, velocity
north/east/down [m/s], eph and epv [m] (nan: unknown).

The optional C kernel (``_kalman_c.c``) writes both layouts out as C constants and exports them
as ``LAYOUT``; :mod:`.kernel` refuses a build whose ``LAYOUT`` is not :data:`C_LAYOUT`.
"""

from __future__ import annotations

from gcs_utm.model import LANE_STRIDE, MeasurementSource

# ---- record ---------------------------------------------------------------------------------
REC_T = 0
REC_LON = REC_EAST = 1
REC_LAT = REC_NORTH = 2
REC_ALT = 3
REC_VE, REC_VN, REC_VU = 4, 5, 6
REC_R = 7  # 3 rows: east, north, up position variances
REC_RV = 10  # 3 rows: velocity variances
REC_SRC = 13
REC_HAS_VEL = 14
NCOL = 15

# ---- entry (PositionLane) -------------------------------------------------------------------
ENT_SRC = 0
ENT_RCV = 1
ENT_T = 2
ENT_LON = 3
ENT_LAT = 4
ENT_ALT = 5
ENT_VN, ENT_VE, ENT_VD = 6, 7, 8
ENT_EPH = 9
ENT_EPV = 10
ENTRY_STRIDE = 11
if ENTRY_STRIDE != LANE_STRIDE:  # pragma: no cover - a change of model.PositionLane
    raise ImportError(f"model.LANE_STRIDE is {LANE_STRIDE}, the tracker reads {ENTRY_STRIDE}")

# Index of a measurement source in REC_SRC and in the per-source tables.
SOURCE_INDEX = {
    MeasurementSource.TELEMETRY: 0,
    MeasurementSource.ADSB: 1,
    MeasurementSource.MQTT: 2,
}
N_SOURCES = 3

# Version of the C functions' arguments (2: update_rows takes restart_after), so that a build
# of older source is refused at import like a stale layout.
C_ARGS_VERSION = 2

# What the C kernel must export as LAYOUT, in this order.
C_LAYOUT = (
    REC_T, REC_EAST, REC_NORTH, REC_ALT, REC_VE, REC_R, REC_RV, REC_SRC, REC_HAS_VEL, NCOL,
    ENT_SRC, ENT_RCV, ENT_T, ENT_LON, ENT_LAT, ENT_ALT, ENT_VN, ENT_VE, ENT_VD, ENT_EPH,
    ENT_EPV, ENTRY_STRIDE, N_SOURCES, C_ARGS_VERSION,
)  # fmt: skip

# Altitudes outside this band are not an aircraft: below the Dead Sea shore (-430 m) with
# margin, above any airspace a UTM serves (the stratosphere, 30 km) with margin.
MIN_ALT_AMSL_M = -1_000.0
MAX_ALT_AMSL_M = 50_000.0
