from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

LAYOUT: tuple[int, ...]

def update_rows(
    rw: npt.NDArray[np.intp],
    a: npt.NDArray[np.float64],
    x: npt.NDArray[np.float64],
    p: npt.NDArray[np.float64],
    t: npt.NDArray[np.float64],
    src_t: npt.NDArray[np.float64],
    updates: npt.NDArray[np.int64],
    gate_fails: npt.NDArray[np.int64],
    stale: npt.NDArray[Any],
    q: tuple[float, float, float],
    max_jump: float,
    margin: float,
    max_speed: float,
    restart_after: float,
    /,
) -> bool: ...
def entry_records(
    values: Sequence[float],
    a: npt.NDArray[np.float64],
    idx: npt.NDArray[np.intp],
    defaults: tuple[tuple[float, float, float], ...],
    min_sigma: float,
    max_future: float,
    max_speed2: float,
    north_dir: tuple[float, float],
    min_alt: float,
    max_alt: float,
    kinds: npt.NDArray[np.intp] | None = None,
    has_vel: npt.NDArray[np.bool_] | None = None,
    /,
) -> tuple[int, int, int]: ...
