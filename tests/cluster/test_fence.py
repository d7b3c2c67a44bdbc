"""Lease fencing: a member that stalled past its lease expiry while a standby took its region
over cannot write its region's rows when it resumes (the operation, its plans, its
recommendations): the store refuses them against the lease generation, the refusal is
audited and the member stops (fail-stop), before its own next lease round would notice."""

from __future__ import annotations

import asyncio
import time
from dataclasses import replace
from pathlib import Path

import pytest

from gcs_utm.cluster import lease
from gcs_utm.cluster.fence import LeaseFence, Refusal
from gcs_utm.model import OperationId, RecommendationId
from gcs_utm.scenario import load_scenario
from gcs_utm.store import FencedError, is_postgres, open_store
from gcs_utm.store.versions import allocate
from tests.cluster.harness import config, file_airspace, member
from tests.store.conftest import raw_execute
from tests.store.test_store import UC1, _rec

LEASE_S = 1.0


@pytest.mark.timeout(60)
async def test_a_stalled_member_cannot_write_its_lost_regions_rows(pg_url: str) -> None:
    file_airspace(pg_url)
    a = await member(pg_url, config("A", "c0r0", standby=False, lease_s=LEASE_S))
    b = await member(pg_url, config("B", "c1r0", standby=True, lease_s=LEASE_S))
    try:
        assert await a.step() == ["gained c0r0"] and await b.step() == ["gained c1r0"]
        uas1 = a.airspace.ops[OperationId("UAS1")]
        rec = replace(_rec(), deadline_t_s=time.time() + 600.0)
        a.writer.save_recommendation(rec).result(10.0)  # A holds c0r0: written
        # A stalls (no lease round) past its expiry; B, a standby, takes c0r0 over
        assert await b.step_until("gained c0r0") == ["gained c0r0"]
        with open_store(pg_url) as s:
            now = lease.leases(s)["c0r0"]
        assert (now.holder, now.generation) == (b.node.member.holder, 2)
        # A resumes: its member still believes it holds c0r0, its writes are refused
        assert "c0r0" in a.node.member.owned
        later = replace(rec, version=2)
        with pytest.raises(FencedError, match=r"generation 1.*generation 2 held by B#"):
            a.writer.save_recommendation(later).result(10.0)
        with pytest.raises(FencedError):
            a.writer.save_plan(replace(uas1.plan, version=7)).result(10.0)
        with pytest.raises(FencedError):
            a.writer.save_operation(uas1).result(10.0)
        # the owner's adoption path (a version allocated on the member's connection) too
        await a.node.decisions.adopt(later, "adopted by a stale member")
        assert a.usm.proposed == []
        # and a decision A would file for B's UAS2 (as a decider watching it)
        uas2 = replace(rec, id=RecommendationId("T9/UAS2"), operation_id=OperationId("UAS2"))
        await a.node.decisions.file(uas2)
        await asyncio.sleep(0.05)  # the refusals reach the loop
        assert a.failed == ["region c0r0 taken over: this instance stops (fenced)"]
        a.flush()
        with open_store(pg_url) as s:
            fenced = [e for e in s.load_audit() if e.action == "write_fenced"]
            plans = [p.version for p in s.load_plans("UAS1")]
        assert [e.subject for e in fenced] == ["UAS1"] * 4 + ["UAS2"]
        assert fenced[0].actor == a.node.member.holder
        assert fenced[0].detail == {
            "region": "c0r0",
            "generation": 1,
            "current_generation": 2,
            "current_holder": b.node.member.holder,
        }
        rows = raw_execute(pg_url, "SELECT version, epoch FROM recommendations ORDER BY 1")
        # A's v1, then B's v2 (B resumed A's pending prompt): nothing of A after the takeover
        assert rows == [(1, a.node.member.epoch), (2, b.node.member.epoch)]
        assert 7 not in plans
        # the new owner writes under its own generation
        b.writer.save_recommendation(replace(rec, id=RecommendationId(rec.id + "b"))).result(10.0)
        # and A's own next round sees the loss as before (fail-stop)
        assert await a.step() == ["lost c0r0"]
    finally:
        await a.close()
        await b.close()


def test_the_fence_checks_the_generation_on_both_backends(db: str | Path) -> None:
    """The same check on SQLite and PostgreSQL, store-level: a write carries the generation
    its life gained the region with; a newer generation refuses it."""
    refused: list[Refusal] = []
    region_of = {"UAS1": "c0r0"}.get
    with open_store(db) as s:
        s.begin_life()
        for op in load_scenario(UC1).operations:
            s.save_operation(op)
        first = lease.acquire(s, "c0r0", "A#1", 1, 0.05)
        assert first is not None and first.generation == 1
        fence = LeaseFence("A#1", region_of, refused.append, share_lock=is_postgres(db))
        fence.gained("c0r0", 1)
        s.fence = fence
        rec = _rec()
        s.save_recommendation(rec)
        assert allocate(s, replace(rec, version=1), s.epoch, fence) == 2
        time.sleep(0.1)  # A's lease expires; B takes the region
        assert lease.acquire(s, "c0r0", "B#2", 2, 30.0) is not None
        with pytest.raises(FencedError, match="region c0r0"):
            s.save_recommendation(replace(rec, version=3))
        with pytest.raises(FencedError):
            allocate(s, replace(rec, version=3), s.epoch, fence)
        assert [r.generation for r in refused] == [1, 1]
        assert {(r.current_generation, r.current_holder) for r in refused} == {(2, "B#2")}
        s.fence = None
        assert [r.version for r in s.load_recommendations(latest_only=False)] == [1, 2]
        # a filing for an operation of a region this life never held (a decider's) is
        # checked against every lease it gained: refused too, as A is stale
        s.fence = fence
        other = replace(rec, id=RecommendationId(rec.id + "x"), operation_id=OperationId("UAS2"))
        with pytest.raises(FencedError, match="region c0r0"):
            s.save_recommendation(other)
        # a life holding a live lease files it
        b_fence = LeaseFence("B#2", region_of, refused.append, share_lock=is_postgres(db))
        b_fence.gained("c0r0", 2)
        s.fence = b_fence
        s.save_recommendation(other)
        assert len(refused) == 3


def test_versions_are_allocated_once_each_under_a_race(pg_url: str) -> None:
    """Eight connections allocating versions of one id at once: every number once, none
    skipped (the insert that loses a number reads again and takes the next)."""
    import concurrent.futures

    rec = _rec()
    with open_store(pg_url) as s:
        s.begin_life()
        s.save_operation(load_scenario(UC1).operations[0])

    def worker(_i: int) -> list[int]:
        with open_store(pg_url) as s:
            epoch = s.begin_life()
            return [allocate(s, replace(rec, version=1), epoch) for _ in range(10)]

    with concurrent.futures.ThreadPoolExecutor(8) as pool:
        got = [v for part in pool.map(worker, range(8)) for v in part]
    assert sorted(got) == list(range(1, 81))
