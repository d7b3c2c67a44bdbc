"""Scenarios: our TOML format (:func:`load_scenario`) and the paper's GAUSS files
(:func:`load_gauss`), both loaded into one validated, frozen :class:`Scenario`."""

from __future__ import annotations

from pathlib import Path

from gcs_utm.scenario.gauss import gauss_json_of, load_gauss
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
    ``.yaml``); ``.yaml``/``.yml`` is a GAUSS scenario YAML, the entry point of the scenario
    it describes (its ``operations_json``); anything else our TOML format. A folder or a
    missing file is one :class:`ScenarioError` saying so."""
    p = Path(path)
    if p.is_dir():
        raise ScenarioError(str(p), "(file)", "(file)", "is a directory, not a scenario file")
    if not p.exists():
        raise ScenarioError(str(p), "(file)", "(file)", "the file does not exist")
    suffix = p.suffix.lower()
    if suffix in (".yaml", ".yml"):
        if yaml_path is not None:
            raise ScenarioError(
                str(p), "(call)", "yaml_path", "a GAUSS YAML is itself the scenario's YAML"
            )
        return load_gauss(gauss_json_of(p), p, t0_s=t0_s)
    if suffix == ".json":
        return load_gauss(p, yaml_path, t0_s=t0_s)
    if yaml_path is not None:
        raise ScenarioError(
            str(path), "(call)", "yaml_path", "only GAUSS .json scenarios take a YAML"
        )
    return load_scenario(p, t0_s=t0_s)


__all__ = [
    "EventKind",
    "Scenario",
    "ScenarioError",
    "ScenarioEvent",
    "VehicleSetup",
    "gauss_json_of",
    "load_any",
    "load_gauss",
    "load_scenario",
]
