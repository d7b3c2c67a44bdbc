"""Scenarios: our TOML format (:func:`load_scenario`) and the paper's GAUSS files
(:func:`load_gauss`), both loaded into one validated, frozen :class:`Scenario`."""

from __future__ import annotations

from pathlib import Path

from gcs_utm.scenario.gauss import load_gauss
from gcs_utm.scenario.toml_format import load_scenario
from gcs_utm.scenario.types import (
    EventKind,
    Scenario,
    ScenarioError,
    ScenarioEvent,
    VehicleSetup,
)


def load_any(
    path: str | Path, yaml_path: str | Path | None = None, *, t0_s: float = 0.0
) -> Scenario:
    """Load ``path`` by its suffix: ``.json`` is GAUSS (with ``yaml_path`` or its sibling
    ``.yaml``), anything else our TOML format."""
    if Path(path).suffix.lower() == ".json":
        return load_gauss(path, yaml_path, t0_s=t0_s)
    if yaml_path is not None:
        raise ScenarioError(
            str(path), "(call)", "yaml_path", "only GAUSS .json scenarios take a YAML"
        )
    return load_scenario(path, t0_s=t0_s)


__all__ = [
    "EventKind",
    "Scenario",
    "ScenarioError",
    "ScenarioEvent",
    "VehicleSetup",
    "load_any",
    "load_gauss",
    "load_scenario",
]
