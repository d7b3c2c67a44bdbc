"""MAVLink mission upload on loopback: a 20-item mission to one ``sitl`` vehicle.

One timed run = ``MavlinkHub.upload_items`` end to end: MISSION_COUNT / REQUEST_INT /
ITEM_INT / ACK, the readback download compared item by item, and MISSION_SET_CURRENT until
MISSION_CURRENT confirms (mission mode is not switched). Targets: median < 150 ms without loss;
every upload complete (verified) within 3 s with 20 % packet loss each way (sitl PACKET_LOSS
fault, value 0.2). sitl and the hub share this process and its event loop (one core, like the
ground service with one local vehicle); sitl re-requests on its own wall-clock timer (PX4:
250 ms, ArduPilot: 1 s, ``--autopilot``), so the loss figures include the vehicle's timing, not
only ours. The lossy record gives the distribution (p50/p90/p95/max over ``--loss-runs``),
``within_budget`` = verified uploads that finished inside ``--budget-s``, and ``failed``.
"""

from __future__ import annotations

import argparse
import asyncio
import math
import time

from gcs_utm.bench.timing import summary

NAME = "upload"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--items", type=int, default=20, help="mission items per upload")
    p.add_argument("--runs", type=int, default=20, help="timed uploads without loss")
    p.add_argument("--loss-runs", type=int, default=10, help="timed uploads with packet loss")
    p.add_argument("--loss", type=float, default=0.2, help="packet loss probability each way")
    p.add_argument("--budget-s", type=float, default=3.0, help="completion target under loss")
    p.add_argument(
        "--autopilot", choices=("px4", "ardupilot"), default="px4", help="sitl vehicle flavour"
    )
    p.add_argument("--seed", type=int, default=1, help="sitl random seed (packet loss draws)")


class _NullSink:
    def on_measurement(self, m: object) -> None: ...
    def on_status(self, s: object) -> None: ...
    def on_hazard(self, h: object) -> None: ...
    def on_vehicle(self, v: object) -> None: ...
    def on_link_health(self, h: object) -> None: ...


async def _bench(
    args: argparse.Namespace,
) -> tuple[list[float], list[float], list[bool], dict[str, int]]:
    import sitl
    from adapters.mavlink import MavlinkConfig, MavlinkHub
    from adapters.mavlink.mission import MAV_CMD_NAV_WAYPOINT, MissionItem
    from gcs_utm.clock import ScaledClock
    from gcs_utm.model import SysId

    sim = sitl.SimTime(speed=1.0)
    clock = ScaledClock(1.0, start_utc_s=sim.start_utc_s, start_mono_s=sim.start_mono_s)
    home = (47.397742, 8.545594, 488.0)
    first = 1 if args.autopilot == "ardupilot" else 0  # ArduPilot's seq 0 is home
    items = [
        MissionItem(
            seq=i,
            command=MAV_CMD_NAV_WAYPOINT,
            current=int(i == first),
            param4=math.nan,
            x=round((home[0] + 0.0002 * (i + 1)) * 1e7),
            y=round(home[1] * 1e7),
            z=home[2] + 20.0,
        )
        for i in range(args.items)
    ]
    cfg = MavlinkConfig(links=("udpin:127.0.0.1:0",))
    clean: list[float] = []
    lossy: list[float] = []
    ok: list[bool] = []
    async with MavlinkHub(cfg, clock, _NullSink()) as hub:
        port = hub.local_port(hub.link_names()[0])
        spec = sitl.VehicleSpec(
            instance=0, gcs_port=port, bind_port=0, autopilot=args.autopilot, seed=args.seed
        )
        async with sitl.Fleet([spec], sim) as fleet:
            for _ in range(250):
                if hub.vehicles():
                    break
                await asyncio.sleep(0.02)
            else:
                raise RuntimeError("sitl vehicle not discovered")
            vehicle = fleet.vehicles[0]
            for i in range(args.runs + 1):  # first one is warm-up
                t0 = time.perf_counter()
                res = await hub.upload_items(SysId(1), items, set_mission_mode=False)
                dt = (time.perf_counter() - t0) * 1000.0
                if not res.verified:
                    raise RuntimeError(f"upload without loss failed: {res.error}")
                if i:
                    clean.append(dt)
            vehicle.inject_fault(sitl.FaultKind.PACKET_LOSS, duration_s=None, value=args.loss)
            for _ in range(args.loss_runs):
                t0 = time.perf_counter()
                res = await hub.upload_items(
                    SysId(1),
                    items,
                    set_mission_mode=False,
                    deadline_t_s=clock.now_s() + 4.0 * args.budget_s,
                )
                dt = (time.perf_counter() - t0) * 1000.0
                lossy.append(dt)
                ok.append(res.verified)
                await asyncio.sleep(0.3)  # let sitl's transfer state settle between runs
            counters = {
                "hub_mission_retries": hub.counters.mission_retries,
                "vehicle_rerequests": vehicle.counters["mission_rerequests"],
            }
    return clean, lossy, ok, counters


def _pct(xs: list[float], q: float) -> float:
    s = sorted(xs)
    return round(s[min(len(s) - 1, max(0, math.ceil(q * len(s)) - 1))], 1)


def run(args: argparse.Namespace) -> list[dict[str, object]]:
    clean, lossy, ok, counters = asyncio.run(_bench(args))
    vehicle = f"sitl {args.autopilot}"
    rec1 = summary(f"upload_{args.items}_items", args.items, clean, vehicle=vehicle, loss=0.0)
    rec1["target_median_ms"] = 150.0
    records = [rec1]
    if lossy:
        budget_ms = args.budget_s * 1000.0
        within = sum(1 for v, dt in zip(ok, lossy, strict=True) if v and dt <= budget_ms)
        records.append(
            summary(
                f"upload_{args.items}_items_loss{round(args.loss * 100)}",
                args.items,
                lossy,
                vehicle=vehicle,
                loss=args.loss,
                budget_s=args.budget_s,
                within_budget=within,
                within_budget_text=f"{within} of {len(lossy)} within {args.budget_s:g} s",
                failed=len(ok) - sum(ok),
                p50_ms=_pct(lossy, 0.5),
                p90_ms=_pct(lossy, 0.9),
                p95_ms=_pct(lossy, 0.95),
                **counters,
            )
        )
    return records
