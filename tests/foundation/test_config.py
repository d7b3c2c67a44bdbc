"""Config loader: TOML -> frozen settings dataclasses, errors naming file/key, rendered defaults
load back to the defaults."""

from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass
from enum import Enum
from pathlib import Path

import pytest

from gcs_utm.config import ConfigError, build, load_toml, render_toml, setting


class Mode(Enum):
    FAST = "fast"
    SAFE = "safe"


@dataclass(frozen=True, slots=True, kw_only=True)
class Inner:
    """Inner table."""

    gain: float = setting(0.5, "filter gain", min=0.0, max=1.0)
    names: tuple[str, ...] = setting(("a", "b"), "names to watch")


@dataclass(frozen=True, slots=True, kw_only=True)
class Outer:
    """Test settings."""

    enabled: bool = setting(True, "switch")
    period_s: float = setting(1.0, "cycle period", min=0.01, unit="s")
    count: int = setting(3, "how many", min=1, max=10)
    name: str = setting("x", "a name")
    mode: Mode = setting(Mode.SAFE, "mode")
    limit_m: float | None = setting(None, "optional limit", min=0.0, unit="m")
    weights: tuple[float, float] = setting((1.0, 2.0), "alpha, beta")
    ports: list[int] = setting([1, 2], "ports", min=0, max=65535)
    inner: Inner = setting(Inner(), "nested")

    def __post_init__(self) -> None:
        if self.weights[0] > self.weights[1]:
            raise ValueError("weights: alpha must not exceed beta")


def _err(mapping: dict[str, object]) -> ConfigError:
    with pytest.raises(ConfigError) as info:
        build(Outer, mapping, source="site.toml", section="test")
    return info.value


def test_build_converts_every_supported_type() -> None:
    cfg = build(
        Outer,
        {
            "enabled": False,
            "period_s": 2,  # an int where a float is declared is accepted
            "count": 4,
            "name": "y",
            "mode": "fast",
            "limit_m": 3.5,
            "weights": [0, 1.5],
            "ports": [80],
            "inner": {"gain": 0.25, "names": ["q"]},
        },
        source="site.toml",
        section="test",
    )
    assert cfg == Outer(
        enabled=False,
        period_s=2.0,
        count=4,
        name="y",
        mode=Mode.FAST,
        limit_m=3.5,
        weights=(0.0, 1.5),
        ports=[80],
        inner=Inner(gain=0.25, names=("q",)),
    )
    assert isinstance(cfg.period_s, float)
    assert dataclasses.is_dataclass(cfg)
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.count = 5  # type: ignore[misc]


def test_absent_keys_take_defaults() -> None:
    assert build(Outer, {}, source="s", section="test") == Outer()


def test_unknown_key_names_file_dotted_key_and_valid_keys() -> None:
    err = _err({"inner": {"gian": 0.1}})
    assert err.source == "site.toml"
    assert err.key == "test.inner.gian"
    assert "gain" in err.expected and "names" in err.expected
    assert str(err).startswith("site.toml: test.inner.gian: unknown key")


@pytest.mark.parametrize(
    ("mapping", "key", "fragment"),
    [
        ({"enabled": 1}, "test.enabled", "expected a boolean"),
        ({"count": 2.0}, "test.count", "expected an integer"),
        ({"count": True}, "test.count", "expected an integer"),
        ({"count": 11}, "test.count", "<= 10"),
        ({"period_s": "1"}, "test.period_s", "expected a number"),
        ({"period_s": 0.0}, "test.period_s", ">= 0.01"),
        ({"period_s": float("nan")}, "test.period_s", "finite"),
        ({"mode": "turbo"}, "test.mode", "'fast', 'safe'"),
        ({"limit_m": -1.0}, "test.limit_m", ">= 0.0"),
        ({"weights": [1.0]}, "test.weights", "2 items"),
        ({"ports": [80, 70000]}, "test.ports[1]", "<= 65535"),
        ({"inner": 3}, "test.inner", "expected a table"),
        ({"inner": {"gain": 2.0}}, "test.inner.gain", "<= 1.0"),
        ({"inner": {"names": ["a", 1]}}, "test.inner.names[1]", "expected a string"),
    ],
)
def test_bad_values_name_the_key_and_expectation(
    mapping: dict[str, object], key: str, fragment: str
) -> None:
    err = _err(mapping)
    assert err.key == key
    assert fragment in err.expected


def test_cross_field_check_of_the_dataclass_is_reported_with_the_file() -> None:
    err = _err({"weights": [3.0, 1.0]})
    assert err.source == "site.toml" and "alpha must not exceed beta" in err.expected


def test_load_toml_reports_the_line_of_a_syntax_error(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text("[test]\ncount = 3\nname = = 'x'\n")
    with pytest.raises(ConfigError) as info:
        load_toml(path)
    assert info.value.source == str(path)
    assert info.value.key == "line 3"


def test_load_toml_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="does not exist"):
        load_toml(tmp_path / "nope.toml")


def test_rendered_defaults_comment_every_key_and_load_back_to_defaults(tmp_path: Path) -> None:
    text = render_toml({"test": Outer})
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if "=" in line and not line.startswith(("#", "[")):
            assert lines[i - 1].startswith("# "), f"no comment above {line!r}"
    assert "# cycle period (s, 0.01..)" in text
    assert "[test.inner]" in text
    assert "# limit_m = (unset" in text
    parsed = tomllib.loads(text)
    assert build(Outer, parsed["test"], source="default", section="test") == Outer()
    path = tmp_path / "d.toml"
    path.write_text(text)
    assert build(Outer, load_toml(path)["test"], source=str(path), section="test") == Outer()
