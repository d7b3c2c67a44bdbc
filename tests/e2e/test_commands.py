"""The README's commands are wired as the issue asks: ``demo`` runs use case 1 then use case
2 from the scenarios shipped inside the package (a fresh install has nothing else), ``serve``
listens where PX4 SITL sends by default and keeps its store in the working folder, and
``bench`` with no name collects every benchmark."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from gcs_utm.bench import discover
from gcs_utm.cli import build_parser, main
from gcs_utm.cli import run as run_cli
from gcs_utm.scenario import load_any
from gcs_utm.settings import Settings

ROOT = Path(__file__).resolve().parents[2]


def test_demo_runs_use_case_1_then_2_from_the_package(monkeypatch: pytest.MonkeyPatch) -> None:
    ran: list[tuple[Path, argparse.Namespace]] = []

    def fake_run_one(path: Path, args: argparse.Namespace, **_kw: object) -> int:
        ran.append((path, args))
        return 0

    monkeypatch.setattr(run_cli, "_run_one", fake_run_one)
    assert main(["demo", "--headless", "--auto-accept", "--speed", "10"]) == 0
    assert [p.name for p, _ in ran] == ["use_case_1.toml", "use_case_2.toml"]
    for path, args in ran:
        # shipped in the package (gcs_utm/data/scenarios), identical to config/scenarios
        assert "gcs_utm" in path.parts and "data" in path.parts
        assert path.read_bytes() == (ROOT / "config" / "scenarios" / path.name).read_bytes()
        assert load_any(path).operations
        assert (args.speed, args.auto_accept, args.external, args.config) == (
            10.0,
            True,
            False,
            None,
        )


def test_demo_stops_at_the_first_failing_use_case(monkeypatch: pytest.MonkeyPatch) -> None:
    ran: list[str] = []

    def failing(path: Path, args: argparse.Namespace, **_kw: object) -> int:
        ran.append(path.name)
        return 2

    monkeypatch.setattr(run_cli, "_run_one", failing)
    assert main(["demo", "--headless"]) == 2
    assert ran == ["use_case_1.toml"]


def test_serve_defaults() -> None:
    assert Settings().mavlink.links == ("udpin:127.0.0.1:14550",)
    args = build_parser().parse_args(["serve"])
    assert args.db == Path("gcs_utm.sqlite") and args.config is None
    assert not args.headless and not args.auto_accept


def test_bench_collects_every_benchmark() -> None:
    assert set(discover()) == {
        "tracking",
        "monitoring",
        "deconfliction",
        "ingest",
        "upload",
        "fuzz",
        "strategic",
        "resolution",
        "cluster",
        "service_cycle",
        "soak",
        "eval",
    }
    # each one is also reachable by name
    for name in discover():
        assert build_parser().parse_args(["bench", name, "--json"]).bench_name == name
