"""One definition of loss of separation: Monitoring's detector, the shared predicate and the
run report agree, with the effective minima (operational volumes included)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs_utm.app.report import separation
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.geometry import segment_separation
from gcs_utm.core.monitoring.loss import minima_arrays, separation_ratio
from tests.monitoring.helpers import operation

CYL = MonitoringConfig()
SPH = MonitoringConfig(separation_mode="sphere")


def is_loss(
    config: MonitoringConfig, dh_m: float, dv_m: float, ov_a_m: float = 0.0, ov_b_m: float = 0.0
) -> bool:
    """The definition of gcs_utm.core.monitoring.loss, written out: strict inequalities on
    the effective minima."""
    h_min, v_min = config.effective_minima(ov_a_m, ov_b_m)
    if config.spherical:
        return bool(np.hypot(dh_m, dv_m) < h_min)
    return bool(dh_m < h_min and abs(dv_m) < v_min)


def test_report_uses_the_effective_minima_not_the_bare_ones() -> None:
    # The flown pair of issue 19: 48.8 m / 35.0 m apart with operational volumes of 17.875 m
    # each (effective minima 50 / 35.75 m) is a loss, as Monitoring alerts it.
    a = operation("A", [(0, 0, 100, 0), (10, 0, 100, 1)], fg=5.0, ov=17.875)
    b = operation("B", [(0, 60, 100, 0), (10, 60, 100, 1)], fg=5.0, ov=17.875)
    assert CYL.effective_minima(17.875, 17.875) == (50.0, 35.75)
    ops = {a.id: a, b.id: b}

    def samples(dv_m: float) -> Any:  # (t_s, lat, lon, alt_amsl_m, east_m, north_m)
        return {
            "A": [(0.0, 0.0, 0.0, 100.0, 0.0, 0.0)],
            "B": [(0.0, 0.0, 0.0, 100.0 + dv_m, 0.0, 48.8)],
        }

    assert separation(samples(35.0), ops, CYL)[0].loss_of_separation
    assert not separation(samples(35.8), ops, CYL)[0].loss_of_separation
    assert is_loss(CYL, 48.8, 35.0, 17.875, 17.875)
    assert not is_loss(CYL, 48.8, 35.0)  # bare minima: 35 m > 15 m


@pytest.mark.parametrize("config", [CYL, SPH], ids=["cylinder", "sphere"])
@settings(max_examples=200, deadline=None)
@given(
    dh=st.floats(0.0, 150.0),
    dv=st.floats(-80.0, 80.0),
    ov_a=st.floats(1.0, 40.0),
    ov_b=st.floats(1.0, 40.0),
)
def test_predicate_ratio_and_monitoring_kernel_agree(
    config: MonitoringConfig, dh: float, dv: float, ov_a: float, ov_b: float
) -> None:
    h, v = config.effective_minima(ov_a, ov_b)
    mh, mv = minima_arrays(config, np.array([ov_a]), np.array([ov_b]))
    assert (float(mh[0]), float(mv[0])) == (h, v)
    loss = is_loss(config, dh, dv, ov_a, ov_b)
    assert loss == bool(separation_ratio(dh, dv, h, v, spherical=config.spherical) < 1.0)
    # Monitoring's segment kernel on a pair standing still at that offset.
    a = np.array([[dh, 0.0, dv]])
    b = np.zeros((1, 3))
    kernel = segment_separation(a, a, b, b, min_h_m=h, min_v_m=v, spherical=config.spherical)
    assert bool(kernel.loss[0]) == loss
