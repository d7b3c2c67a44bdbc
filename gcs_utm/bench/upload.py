"""MAVLink mission upload on loopback: a 20-item mission to one ``sitl`` PX4-like vehicle.

One timed run = ``MavlinkHub.upload_items`` end to end: MISSION_COUNT / REQUEST_INT /
ITEM_INT / ACK, the readback download compared item by item, and MISSION_SET_CURRENT until
MISSION_CURRENT confirms (mission mode is not switched). Targets: median < 150 ms without loss;
every upload complete (verified) within 3 s with 20 % packet loss each way (sitl PACKET_LOSS
fault, value 0.2). sitl and the hub share this process and its event loop (one core, like the
ground service with one local vehicle); sitl re-requests on its own 250 ms wall-clock timer,
as PX4 does, so the loss figures include PX4-like vehicle timing, not only ours.
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


class _NullSink:
    def on_measurement(self, m: object) -> None: ...
    def on_status(self, s: object) -> None: ...
    def on_hazard(self, h: object) -> None: ...
    def on_vehicle(self, v: object) -> None: ...
    def on_link_health(self, h: object) -> None: ...


async def _bench(args: argparse.Namespace) -> tuple[list[float], list[float], list[bool]]:
    import sitl
    from adapters.mavlink import MavlinkConfig, MavlinkHub
    from adapters.mavlink.mission import MAV_CMD_NAV_WAYPOINT, MissionItem
    from gcs_utm.clock import ScaledClock
    from gcs_utm.model import SysId

    sim = sitl.SimTime(speed=1.0)
    clock = ScaledClock(1.0, start_utc_s=sim.start_utc_s, start_mono_s=sim.start_mono_s)
    home = (47.397742, 8.545594, 488.0)
    items = [
        MissionItem(
            seq=i,
            command=MAV_CMD_NAV_WAYPOINT,
            current=int(i == 0),
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
        port = hub.local_port(next(iter(hub._links)))
        spec = sitl.VehicleSpec(instance=0, gcs_port=port, bind_port=0)
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
                ok.append(res.verified and dt <= args.budget_s * 1000.0)
                await asyncio.sleep(0.3)  # let sitl's transfer state settle between runs
    return clean, lossy, ok


def run(args: argparse.Namespace) -> list[dict[str, object]]:
    clean, lossy, ok = asyncio.run(_bench(args))
    rec1 = summary(f"upload_{args.items}_items", args.items, clean, vehicle="sitl px4", loss=0.0)
    rec1["target_median_ms"] = 150.0
    rec2 = summary(
        f"upload_{args.items}_items_loss{round(args.loss * 100)}",
        args.items,
        lossy,
        vehicle="sitl px4",
        loss=args.loss,
        verified_within_budget=sum(ok),
        budget_s=args.budget_s,
    )
    return [rec1, rec2]
