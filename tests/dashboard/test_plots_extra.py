"""matplotlib is the optional extra ``[plots]``: without it ``gcs-utm plot`` fails with one
error that says how to install it, and a run's exports still write GeoJSON and KML."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from gcs_utm.cli import main
from gcs_utm.dashboard.plot import export_all
from gcs_utm.dashboard.plotting import PlotsUnavailableError, require_plots
from tests.dashboard.test_plot import _report


@pytest.fixture
def no_matplotlib(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make ``import matplotlib`` fail as it does where the extra is not installed."""
    for name in [m for m in sys.modules if m == "matplotlib" or m.startswith("matplotlib.")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "matplotlib", None)


def test_require_plots_names_the_extra(no_matplotlib: None) -> None:
    with pytest.raises(PlotsUnavailableError, match=r"pip install 'gcs-utm\[plots\]'"):
        require_plots()


def test_cli_plot_without_matplotlib_says_how_to_install_it(
    no_matplotlib: None, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "rep.json"
    path.write_text(json.dumps(_report()))
    assert main(["plot", str(path)]) == 2
    err = capsys.readouterr().err
    assert "matplotlib" in err and "pip install 'gcs-utm[plots]'" in err
    assert not list(tmp_path.glob("*.png"))


def test_exports_without_matplotlib_write_geojson_and_kml_only(
    no_matplotlib: None, tmp_path: Path
) -> None:
    summary = export_all(_report(), tmp_path / "out", stem="t")
    assert sorted(p.name for p in summary.files) == ["t.geojson", "t.kml"]
    assert not list((tmp_path / "out").glob("*.png"))
    assert json.loads((tmp_path / "out" / "t.geojson").read_text())["features"]


def test_with_matplotlib_require_plots_passes() -> None:
    require_plots()
