from __future__ import annotations

import csv
from pathlib import Path

import pytest

DATA = Path(__file__).resolve().parents[2] / "../shared/data/adsb"
CSV_PATH = DATA / "pymodes_sample_data_adsb.csv"
BEAST_PATH = DATA / "traffic_sample_dump1090_beast.bin"


@pytest.fixture(scope="session")
def csv_rows() -> list[tuple[float, str]]:
    if not CSV_PATH.exists():
        pytest.skip(f"recording not found: {CSV_PATH} (../shared/data is not checked out)")
    with CSV_PATH.open() as f:
        return [(float(r[0]), r[1]) for r in csv.reader(f)]


@pytest.fixture(scope="session")
def beast_bytes() -> bytes:
    if not BEAST_PATH.exists():
        pytest.skip(f"recording not found: {BEAST_PATH} (../shared/data is not checked out)")
    return BEAST_PATH.read_bytes()
