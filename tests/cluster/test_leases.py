"""Region leases on a real PostgreSQL server: one holder at a time, expiry, release, the
shared map, and failover of a region after its owner is killed with SIGKILL."""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from gcs_utm.cluster import lease
from gcs_utm.cluster.config import ClusterConfig
from gcs_utm.cluster.member import ClusterMember
from gcs_utm.cluster.regions import RegionError, RegionMap
from gcs_utm.store import open_store

REPO = Path(__file__).resolve().parents[2]
GRID = RegionMap(west_m=-1000.0, south_m=0.0, cell_m=1000.0, columns=2, rows=1, halo_m=100.0)


def test_one_holder_at_a_time_expiry_and_release(pg_url: str) -> None:
    with open_store(pg_url) as a, open_store(pg_url) as b:
        lease.publish_map(a, GRID)
        got = lease.acquire(a, "c0r0", "A#1", 1, lease_s=0.5)
        assert got is not None and got.generation == 1
        assert lease.acquire(b, "c0r0", "B#2", 2, lease_s=0.5) is None
        renewed = lease.acquire(a, "c0r0", "A#1", 1, lease_s=0.5)
        assert renewed is not None and renewed.generation == 1
        assert renewed.expires_unix_s > got.expires_unix_s
        assert renewed.acquired_unix_s == got.acquired_unix_s
        assert lease.owners(b) == {"c0r0": "A#1"}
        time.sleep(0.6)  # A stopped renewing: expired on the database clock
        assert lease.owners(b) == {}
        taken = lease.acquire(b, "c0r0", "B#2", 2, lease_s=5.0)
        assert taken is not None and taken.generation == 2 and taken.holder == "B#2"
        assert lease.acquire(a, "c0r0", "A#1", 1, lease_s=0.5) is None  # A is out
        assert not lease.release(a, "c0r0", "A#1")
        assert lease.release(b, "c0r0", "B#2")
        again = lease.acquire(a, "c0r0", "A#1", 1, lease_s=0.5)  # free at once after release
        assert again is not None and again.generation == 3


def test_every_instance_must_use_the_same_region_map(pg_url: str) -> None:
    with open_store(pg_url) as s:
        lease.publish_map(s, GRID)
        lease.publish_map(s, GRID)  # the same map again is fine
        other = RegionMap(
            west_m=-1000.0, south_m=0.0, cell_m=900.0, columns=2, rows=1, halo_m=100.0
        )
        with pytest.raises(RegionError, match="region map differs"):
            lease.publish_map(s, other)


def test_racing_instances_never_both_win(pg_url: str) -> None:
    """Eight connections racing for one free region, many rounds: exactly one wins each."""
    import threading

    stores = [open_store(pg_url) for _ in range(8)]
    try:
        for round_ in range(20):
            region = f"c{round_}r0"
            wins: list[str] = []
            barrier = threading.Barrier(len(stores))

            def race(
                i: int,
                region: str = region,
                wins: list[str] = wins,
                barrier: threading.Barrier = barrier,
            ) -> None:
                barrier.wait()
                if lease.acquire(stores[i], region, f"I{i}#{i}", i, 5.0) is not None:
                    wins.append(f"I{i}")

            threads = [threading.Thread(target=race, args=(i,)) for i in range(len(stores))]
            for t in threads:
                t.start()
            for t in threads:
                t.join(10)
            assert len(wins) == 1, wins
    finally:
        for s in stores:
            s.close()


_OWNER = textwrap.dedent(
    """
    import asyncio, sys
    from gcs_utm.cluster.config import ClusterConfig
    from gcs_utm.cluster.member import ClusterMember

    async def main():
        cfg = ClusterConfig(instance="A", region="c0r0", standby=False, west_m=-1000.0,
            south_m=0.0, cell_m=1000.0, columns=2, rows=1, halo_m=100.0,
            lease_s=float(sys.argv[2]), renew_s=float(sys.argv[3]))
        async def gained(region, lease):
            print("gained", region, flush=True)
        async def lost(region, lease):
            print("lost", region, flush=True)
        m = ClusterMember(sys.argv[1], cfg, instance="A", epoch=1, on_gained=gained,
            on_lost=lost)
        await m.start()
        await m.run()

    asyncio.run(main())
    """
)


async def test_standby_takes_a_region_over_after_kill_9(pg_url: str) -> None:
    lease_s, renew_s = 2.0, 0.5
    child = subprocess.Popen(
        [sys.executable, "-c", _OWNER, pg_url, str(lease_s), str(renew_s)],
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    assert child.stdout is not None
    gained: dict[str, float] = {}
    lost: list[str] = []

    async def on_gained(region: str, _lease: object) -> None:
        gained[region] = time.monotonic()

    async def on_lost(region: str, _lease: object) -> None:
        lost.append(region)

    cfg = ClusterConfig(
        instance="B",
        region="c1r0",
        standby=True,
        west_m=-1000.0,
        south_m=0.0,
        cell_m=1000.0,
        columns=2,
        rows=1,
        halo_m=100.0,
        lease_s=lease_s,
        renew_s=renew_s,
    )
    member = ClusterMember(pg_url, cfg, instance="B", epoch=2, on_gained=on_gained, on_lost=on_lost)
    try:
        line = await asyncio.wait_for(asyncio.to_thread(child.stdout.readline), 30.0)
        assert line.split() == ["gained", "c0r0"]
        await member.start()
        task = asyncio.create_task(member.run())
        await asyncio.sleep(3 * lease_s)  # B holds its own region, never A's while A lives
        assert set(member.owned) == {"c1r0"}
        with open_store(pg_url) as s:
            assert lease.owners(s) == {"c0r0": "A#1", "c1r0": "B#2"}
        killed = time.monotonic()
        child.send_signal(signal.SIGKILL)
        child.wait(10)
        while "c0r0" not in gained and time.monotonic() - killed < 10.0:
            await asyncio.sleep(0.05)
        failover_s = gained.get("c0r0", float("inf")) - killed
        assert failover_s <= lease_s + renew_s + 1.0, failover_s
        assert member.owned["c0r0"].generation == 2 and lost == []
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        with open_store(pg_url) as s:
            assert lease.owners(s) == {}  # released on the way out
    finally:
        if child.poll() is None:
            child.kill()
            child.wait(10)
        child.stdout.close()
        await member.close()
