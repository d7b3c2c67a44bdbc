from __future__ import annotations

import csv
from pathlib import Path

import pytest

DATA = Path(__file__).resolve().parents[1] / "data" / "adsb"  # provenance: tests/data/SOURCES.md
CSV_PATH = DATA / "synthetic_adsb.csv"  # written by tests/adsb/encode.py
BEAST_PATH = DATA / "traffic_sample_dump1090_beast.bin"


@pytest.fixture(scope="session")
def csv_rows() -> list[tuple[float, str]]:
    with CSV_PATH.open() as f:
        return [(float(r[0]), r[1]) for r in csv.reader(f)]


@pytest.fixture(scope="session")
def beast_bytes() -> bytes:
    return BEAST_PATH.read_bytes()
