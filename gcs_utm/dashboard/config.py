"""Settings of the operator's dashboard (section ``[dashboard]``)."""

from __future__ import annotations

from dataclasses import dataclass

from gcs_utm.config import setting


@dataclass(frozen=True, slots=True, kw_only=True)
class DashboardConfig:
    refresh_s: float = setting(0.5, "screen refresh period", min=0.05, max=10.0, unit="s")
    operator: str = setting("dashboard", "operator name recorded with answers given here")
    headless_status_s: float = setting(
        5.0, "period of the one-line status log in --headless mode", min=0.5, unit="s"
    )
    auto_answer_delay_s: float = setting(
        2.0,
        "think time of --auto-accept / --auto-reject before answering (clock seconds)",
        min=0.0,
        unit="s",
    )
