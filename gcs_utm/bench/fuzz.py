"""Fuzzed and spoofed MAVLink through the hub's receive path: nothing escapes, everything bad
is counted by cause, memory stays bounded.

Two records:

- ``fuzz``: ``--frames`` datagrams (seeded, ``--seed``) into :meth:`MavlinkHub.receiver` --
  the callback the UDP and TCP transports call with each datagram or stream chunk -- of a
  UDP link and a TCP link: valid frames of five vehicles and one that signs (MAVLink 1 and
  2, the messages the hub handles and the mission/command protocol), and mutations of them:
  random payloads behind a valid CRC, flipped bits, cut frames, random bytes, unknown message
  ids, spoofed identities (any sysid/compid from any port, sysid 0), ``time_boot_ms`` going
  back, unsigned / wrongly signed / replayed frames of the signing vehicle, several frames in
  one datagram, streams split at random. Reported: datagrams sent, frames decoded, dropped
  per cause (the hub's counters), handler errors (a bug if not 0), datagrams that moved no
  counter (``uncounted``, a bug if not 0), senders and vehicles held, RSS before / peak / after.
- ``fuzz_spoof_idle``: ``--identities`` spoofed (port, sysid, compid) identities, each a
  HEARTBEAT and a GLOBAL_POSITION_INT, then ``--idle-s`` seconds of idle (real time, the hub's
  periodic sweep running as in ``serve``): RSS before, after the flood and after the idle,
  with ``within_40mb`` (issue 21: 12,000 identities + 100 s idle within 40 MB of the start).

RSS is the process's resident set (``/proc/self/status``; 0 where there is none). The hub has
a counting sink here (no tracking or store): this measures the hub's own per-sender state.
"""

from __future__ import annotations

import argparse
import asyncio
import gc
import random
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from adapters.mavlink import MavlinkHub
    from gcs_utm.clock import ManualClock

_Receiver = Callable[[bytes, "tuple[str, int] | None"], None]

NAME = "fuzz"

KEY_HEX = "c3" * 32  # the signing vehicle's key (sysid 9), known to the hub
_WRONG_HEX = "3c" * 32
_SIGNED_SYSID = 9
T0_S = 1_700_000_000.0  # the fuzz's clock (UTC) and signing time: runs repeat exactly
_DROP_CAUSES = (
    "bad_crc",
    "garbage",
    "unknown_msg",
    "truncated",
    "bad_signature",
    "unsigned",
    "replayed",
    "sysid_zero",
    "sysid_claims",
    "not_for_us",
)
_REJECTS = ("bad_crc", "garbage", "unknown_msg", "truncated", "bad_signature")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--frames", type=int, default=300_000, help="fuzzed datagrams")
    p.add_argument("--seed", type=int, default=1, help="random seed of the mutations")
    p.add_argument("--identities", type=int, default=12_000, help="spoofed identities")
    p.add_argument("--idle-s", type=float, default=100.0, help="idle time after the spoof flood")


def rss_mb() -> float:
    """Resident set size of this process in MB (0.0 without /proc)."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return 0.0


class CountingSink:
    """Counts what the hub hands on (a TelemetrySink)."""

    def __init__(self) -> None:
        self.counts = {"measurements": 0, "statuses": 0, "hazards": 0, "vehicles": 0}

    def on_measurement(self, m: object) -> None:
        self.counts["measurements"] += 1

    def on_status(self, s: object) -> None:
        self.counts["statuses"] += 1

    def on_hazard(self, h: object) -> None:
        self.counts["hazards"] += 1

    def on_vehicle(self, v: object) -> None:
        self.counts["vehicles"] += 1

    def on_link_health(self, h: object) -> None:
        pass


@dataclass(slots=True)
class FuzzResult:
    datagrams: int = 0
    stream_chunks: int = 0
    frames_decoded: int = 0
    dropped: dict[str, int] = field(default_factory=dict)
    handler_errors: int = 0
    uncounted: int = 0
    senders_held: int = 0
    vehicles_held: int = 0
    senders_evicted: int = 0
    vehicles_evicted: int = 0
    sink: dict[str, int] = field(default_factory=dict)
    elapsed_s: float = 0.0
    rss_start_mb: float = 0.0
    rss_peak_mb: float = 0.0
    rss_end_mb: float = 0.0


class Mutator:
    """Seeded datagrams for the fuzz (module docstring)."""

    def __init__(self, seed: int) -> None:
        from pymavlink.dialects.v10 import common as mav1
        from pymavlink.dialects.v20 import common as mav2

        self._mav2 = mav2
        self.rng = random.Random(seed)
        self.vehicles = [(f"10.0.0.{i}", 14550) for i in range(1, 6)]
        self._enc2 = [mav2.MAVLink(None, srcSystem=i, srcComponent=1) for i in range(1, 6)]
        self._enc1 = [mav1.MAVLink(None, srcSystem=i, srcComponent=1) for i in range(1, 6)]
        self._signer = self._signing(KEY_HEX)
        self._forger = self._signing(_WRONG_HEX)
        self._recorded: list[bytes] = []  # signed frames, sent again as replays
        self._boot_ms = [0] * 5
        self._crc_extra = {mid: cls.crc_extra for mid, cls in mav2.mavlink_map.items()}
        from fastcrc import crc16

        self._crc = crc16.mcrf4xx

    def hello(self) -> list[tuple[bytes, tuple[str, int]]]:
        """A first HEARTBEAT of every vehicle (so they, not a spoofer, bind their sysid)."""
        out = []
        for v, enc in enumerate(self._enc2):
            out.append(
                (bytes(enc.heartbeat_encode(2, 12, 129, 0, 4, 3).pack(enc)), self.vehicles[v])
            )
        hb = self._signer.heartbeat_encode(2, 3, 129, 0, 4, 3)
        out.append((bytes(hb.pack(self._signer)), ("10.0.0.9", 14550)))
        return out

    def _signing(self, key_hex: str) -> Any:
        from adapters.mavlink.wire import signing_timestamp

        enc = self._mav2.MAVLink(None, srcSystem=_SIGNED_SYSID, srcComponent=1)
        enc.signing.secret_key = bytes.fromhex(key_hex)
        enc.signing.sign_outgoing = True
        enc.signing.timestamp = signing_timestamp(T0_S)  # the hub's clock starts there too
        return enc

    # --- valid messages ---------------------------------------------------------------------
    def _message(self, enc: Any, v: int) -> Any:
        r = self.rng
        self._boot_ms[v % 5] += r.randint(1, 200)
        boot = self._boot_ms[v % 5]
        k = r.randrange(15)
        builders: list[Callable[[], Any]] = [
            lambda: enc.heartbeat_encode(2, r.choice((3, 12, 8)), 129, r.getrandbits(32), 4, 3),
            lambda: enc.global_position_int_encode(
                boot, 473977418 + r.randint(-9999, 9999), 85455939, 500000, 20000, 1, 2, 3, 0
            ),
            lambda: enc.gps_raw_int_encode(
                boot * 1000, r.randint(0, 6), 0, 0, 0, r.randint(0, 65535), 120, 0, 0, 9
            ),
            lambda: enc.sys_status_encode(
                0, 0, 0, 0, 15000, -1, r.randint(-1, 100), 0, 0, 0, 0, 0, 0
            ),
            lambda: enc.system_time_encode(r.getrandbits(63), boot),
            lambda: enc.battery_status_encode(
                0, 0, 0, 2500, [4000] * 10, -1, -1, -1, r.randint(-1, 100)
            ),
            lambda: enc.mission_current_encode(r.randint(0, 65535)),
            lambda: enc.extended_sys_state_encode(0, r.randint(0, 4)),
            lambda: enc.statustext_encode(r.randint(0, 7), r.choice((b"GPS jamming", b"ok", b""))),
            lambda: enc.mission_ack_encode(255, 190, r.randint(0, 15), 0),
            lambda: enc.command_ack_encode(r.randint(0, 600), r.randint(0, 9)),
            lambda: enc.mission_count_encode(255, 190, r.randint(0, 65535), 0),
            lambda: enc.mission_item_int_encode(
                r.choice((255, 0, 7)), 190, r.randint(0, 9), 6, 16, 0, 1,
                0.0, 0.0, 0.0, float("nan"), 473977418, 85455939, 30.0, 0,
            ),
            lambda: enc.attitude_encode(boot, 0.1, 0.2, 0.3, 0.0, 0.0, 0.0),
            lambda: enc.vfr_hud_encode(5.0, 5.0, 90, 50, 500.0, 0.5),
        ]  # fmt: skip
        return builders[k]()

    def valid(self, v: int | None = None) -> tuple[bytes, tuple[str, int]]:
        """A valid frame of one of the five vehicles (MAVLink 2, sometimes 1)."""
        v = self.rng.randrange(5) if v is None else v
        if self.rng.random() < 0.1:
            enc = self._enc1[v]
            try:
                m = self._message(enc, v)
            except TypeError:  # a MAVLink 2 extension field in the v1 dialect's encoder
                enc = self._enc2[v]
                m = self._message(enc, v)
        else:
            enc = self._enc2[v]
            m = self._message(enc, v)
        return bytes(m.pack(enc)), self.vehicles[v]

    # --- mutations --------------------------------------------------------------------------
    def _fix_crc(self, frame: bytearray) -> bytearray:
        """Recompute the CRC of a MAVLink 2 frame (unsigned) after its bytes were changed."""
        if len(frame) < 12 or frame[0] != 0xFD:
            return frame
        n = 10 + frame[1]
        if len(frame) < n + 2:
            return frame
        mid = frame[7] | (frame[8] << 8) | (frame[9] << 16)
        extra = self._crc_extra.get(mid, 0)
        crc = self._crc(bytes([extra]), self._crc(bytes(frame[1:n])))
        frame[n], frame[n + 1] = crc & 0xFF, crc >> 8
        return frame

    def datagram(self) -> tuple[bytes, tuple[str, int], str]:
        """One fuzzed datagram, its source address and the mutation's name: the first
        mutation of :data:`_MUTATIONS` whose share the draw falls in (and that applies to the
        frame's MAVLink version), else several valid frames in one datagram."""
        x = self.rng.random()
        data, addr = self.valid()
        b = bytearray(data)
        for limit, v2_only, mutation in _MUTATIONS:
            if x < limit and (b[0] == 0xFD or not v2_only):
                return mutation(self, b, addr)
        parts = [self.valid()[0] for _ in range(self.rng.randint(2, 4))]
        return b"".join(parts), addr, "several"

    def _valid(self, b: bytearray, addr: tuple[str, int]) -> tuple[bytes, tuple[str, int], str]:
        return bytes(b), addr, "valid"

    def _payload(self, b: bytearray, addr: tuple[str, int]) -> tuple[bytes, tuple[str, int], str]:
        """Random payload behind a valid CRC."""
        for i in range(10, 10 + b[1]):
            b[i] = self.rng.getrandbits(8)
        return bytes(self._fix_crc(b)), addr, "payload"

    def _bitflip(self, b: bytearray, addr: tuple[str, int]) -> tuple[bytes, tuple[str, int], str]:
        r = self.rng
        for _ in range(r.randint(1, 4)):
            b[r.randrange(len(b))] ^= 1 << r.randrange(8)
        return bytes(b), addr, "bitflip"

    def _truncated(self, b: bytearray, addr: tuple[str, int]) -> tuple[bytes, tuple[str, int], str]:
        return bytes(b[: self.rng.randrange(1, len(b))]), addr, "truncated"

    def _random(self, b: bytearray, addr: tuple[str, int]) -> tuple[bytes, tuple[str, int], str]:
        return self.rng.randbytes(self.rng.randint(1, 300)), addr, "random"

    def _unknown(self, b: bytearray, addr: tuple[str, int]) -> tuple[bytes, tuple[str, int], str]:
        """A message id nobody knows, with a CRC."""
        b[7], b[8], b[9] = 0x39, 0x30, self.rng.getrandbits(8) | 0x80
        return bytes(self._fix_crc(b)), addr, "unknown"

    def _spoof(self, b: bytearray, addr: tuple[str, int]) -> tuple[bytes, tuple[str, int], str]:
        """A spoofed identity from anywhere."""
        r = self.rng
        b[5], b[6] = r.choice((0, 1, 2, r.getrandbits(8))), r.getrandbits(8)
        where = (f"10.9.{r.getrandbits(8)}.{r.getrandbits(8)}", r.randint(1024, 65535))
        return bytes(self._fix_crc(b)), where, "spoof"

    def _backwards(self, b: bytearray, addr: tuple[str, int]) -> tuple[bytes, tuple[str, int], str]:
        """A position whose time_boot_ms goes back."""
        r = self.rng
        v = r.randrange(5)
        enc = self._enc2[v]
        m = enc.global_position_int_encode(
            r.randint(0, 1000), 473977418, 85455939, 500000, 20000, 0, 0, 0, 0
        )
        return bytes(m.pack(enc)), self.vehicles[v], "backwards"

    def _signed(self, b: bytearray, addr: tuple[str, int]) -> tuple[bytes, tuple[str, int], str]:
        """A frame of the signing vehicle (sysid 9, its own address): signed, forged,
        replayed or unsigned."""
        r = self.rng
        where = ("10.0.0.9", 14550)
        y = r.random()
        if y < 0.5:
            frame = bytes(self._message(self._signer, 9).pack(self._signer))
            if len(self._recorded) < 64:
                self._recorded.append(frame)
            return frame, where, "signed"
        if y < 0.7:
            return bytes(self._message(self._forger, 9).pack(self._forger)), where, "forged"
        if y < 0.85 and self._recorded:
            return r.choice(self._recorded), where, "replayed"
        plain = self._mav2.MAVLink(None, srcSystem=_SIGNED_SYSID, srcComponent=1)
        return bytes(self._message(plain, 9).pack(plain)), where, "unsigned"

    def stream(self, total: int) -> Iterator[bytes]:
        """``total`` chunks of a byte stream (TCP): frames and mutations cut at random."""
        buf = bytearray()
        for _ in range(total):
            while len(buf) < 600:
                buf += self.datagram()[0]
            cut = self.rng.randint(1, 300)
            yield bytes(buf[:cut])
            del buf[:cut]


_Mutation = Callable[[Mutator, bytearray, tuple[str, int]], tuple[bytes, tuple[str, int], str]]
_MUTATIONS: tuple[tuple[float, bool, _Mutation], ...] = (
    # (upper end of the draw's share, MAVLink 2 frames only, mutation), tried in order
    (0.15, False, Mutator._valid),
    (0.35, True, Mutator._payload),
    (0.50, False, Mutator._bitflip),
    (0.58, False, Mutator._truncated),
    (0.62, False, Mutator._random),
    (0.66, True, Mutator._unknown),
    (0.80, True, Mutator._spoof),
    (0.85, False, Mutator._backwards),
    (0.93, False, Mutator._signed),
)


def _counted(c: Any) -> int:
    return int(sum(getattr(c, k) for k in _REJECTS)) + int(c.frames)


async def fuzz(
    frames: int,
    seed: int,
    *,
    max_senders: int = 1024,
    max_vehicles: int = 1024,
    on_progress: Callable[[int], None] | None = None,
) -> FuzzResult:
    """Run the ``fuzz`` record (module docstring) and return it."""
    from adapters.mavlink import MavlinkConfig, MavlinkHub
    from gcs_utm.clock import ManualClock

    clock = ManualClock(T0_S)
    sink = CountingSink()
    cfg = MavlinkConfig(
        links=("udpin:127.0.0.1:0",),
        signing_keys={str(_SIGNED_SYSID): KEY_HEX},
        max_senders=max_senders,
        max_vehicles=max_vehicles,
        health_period_s=3600.0,  # the sweep runs below, on the fuzz's own clock
        reconnect_min_s=60.0,
        reconnect_max_s=60.0,
    )
    out = FuzzResult(rss_start_mb=rss_mb())
    hub = MavlinkHub(cfg, clock, sink)
    await hub.start()
    try:
        udp = hub.receiver(hub.link_names()[0])
        # a TCP link whose peer is not there: chunks are fed to it as a stream would be
        tcp = hub.receiver(await hub.add_link("tcp:127.0.0.1:9"))
        t0 = time.perf_counter()
        _feed(
            hub,
            clock,
            Mutator(seed),
            receivers=(udp, tcp),
            frames=frames,
            out=out,
            on_progress=on_progress,
        )
        out.elapsed_s = time.perf_counter() - t0
        hub.flush_positions()
        c = hub.counters
        snap = c.snapshot()
        out.frames_decoded = c.frames
        out.dropped = {k: snap[k] for k in _DROP_CAUSES}
        out.handler_errors = c.handler_errors
        out.senders_held, out.vehicles_held = _held(hub)
        out.senders_evicted = c.senders_evicted
        out.vehicles_evicted = c.vehicles_evicted
        out.sink = dict(sink.counts)
    finally:
        await hub.close()
    gc.collect()
    out.rss_end_mb = rss_mb()
    out.rss_peak_mb = max(out.rss_peak_mb, out.rss_end_mb)
    return out


def _feed(
    hub: MavlinkHub,
    clock: ManualClock,
    mut: Mutator,
    *,
    receivers: tuple[_Receiver, _Receiver],
    frames: int,
    out: FuzzResult,
    on_progress: Callable[[int], None] | None,
) -> None:
    """``frames`` chunks into the hub's UDP and TCP receivers (every tenth a stream chunk),
    counting datagrams that moved no counter; the idle sweep and RSS every 20,000."""
    udp, tcp = receivers
    for data, addr in mut.hello():
        udp(data, addr)
    chunks = mut.stream(frames // 10)
    c = hub.counters
    for i in range(frames):
        clock.advance(0.0005)
        before = _counted(c)
        if i % 10 == 9:
            tcp(next(chunks), ("127.0.0.1", 9))
            out.stream_chunks += 1
        else:
            data, addr, _kind = mut.datagram()
            udp(data, addr)
            out.datagrams += 1
            if _counted(c) == before:
                out.uncounted += 1
        if i % 20_000 == 19_999:
            hub.evict_idle()
            out.rss_peak_mb = max(out.rss_peak_mb, rss_mb())
            if on_progress is not None:
                on_progress(i + 1)


def _held(hub: MavlinkHub) -> tuple[int, int]:
    """(source addresses with parser state, vehicle states) the hub holds."""
    return sum(lk.senders for lk in hub.links()), len(hub.health())


async def spoof_idle(identities: int, idle_s: float) -> dict[str, Any]:
    """The ``fuzz_spoof_idle`` record (module docstring), with the default settings."""
    from pymavlink.dialects.v20 import common as mav2

    from adapters.mavlink import MavlinkConfig, MavlinkHub
    from gcs_utm.clock import RealClock

    gc.collect()
    rss0 = rss_mb()
    cfg = MavlinkConfig(links=("udpin:127.0.0.1:0",))
    sink = CountingSink()
    async with MavlinkHub(cfg, RealClock(), sink) as hub:
        receive = hub.receiver(hub.link_names()[0])
        t0 = time.perf_counter()
        for i in range(identities):
            enc = mav2.MAVLink(None, srcSystem=1 + i % 255, srcComponent=1 + (i // 255) % 255)
            addr = (f"10.{i >> 16 & 255}.{i >> 8 & 255}.{i & 255}", 20000 + i % 40000)
            receive(bytes(enc.heartbeat_encode(2, 12, 129, 0, 4, 3).pack(enc)), addr)
            gpi = enc.global_position_int_encode(
                1000, 473977418, 85455939, 500000, 20000, 0, 0, 0, 0
            )
            receive(bytes(gpi.pack(enc)), addr)
            if i % 500 == 499:
                await asyncio.sleep(0)  # the loop runs meanwhile, as it would in serve
        flood_s = time.perf_counter() - t0
        gc.collect()
        rss_flood = rss_mb()
        held = _held(hub)
        await asyncio.sleep(idle_s)
        gc.collect()
        rss_idle = rss_mb()
        c = hub.counters
        left = _held(hub)
        snap = c.snapshot()
    return {
        "benchmark": "fuzz_spoof_idle",
        "identities": identities,
        "idle_s": idle_s,
        "flood_s": round(flood_s, 3),
        "rss_start_mb": round(rss0, 1),
        "rss_after_flood_mb": round(rss_flood, 1),
        "rss_after_idle_mb": round(rss_idle, 1),
        "rss_growth_after_idle_mb": round(rss_idle - rss0, 1),
        "within_40mb": rss_idle - rss0 <= 40.0,
        "senders_held_after_flood": held[0],
        "vehicles_held_after_flood": held[1],
        "senders_held_after_idle": left[0],
        "vehicles_held_after_idle": left[1],
        "counters": {
            k: snap[k]
            for k in (
                "frames",
                "sysid_claims",
                "address_changes",
                "senders_evicted",
                "vehicles_evicted",
            )
        },
        "sink": sink.counts,
        "settings": {
            "max_senders": cfg.max_senders,
            "max_vehicles": cfg.max_vehicles,
            "sender_idle_s": cfg.sender_idle_s,
        },
    }


def run(args: argparse.Namespace) -> list[dict[str, Any]]:
    def progress(n: int) -> None:
        if n % 100_000 == 0:
            print(f"fuzz: {n:,} datagrams", flush=True, file=__import__("sys").stderr)

    # the spoof flood first: its RSS figures are not blurred by the fuzz's allocations
    idle = asyncio.run(spoof_idle(args.identities, args.idle_s))
    res = asyncio.run(fuzz(args.frames, args.seed, on_progress=progress))
    rec: dict[str, Any] = {"benchmark": "fuzz", "seed": args.seed, **asdict(res)}
    rec["sent"] = res.datagrams + res.stream_chunks
    rec["per_s"] = round(rec["sent"] / res.elapsed_s) if res.elapsed_s > 0 else 0
    for k in ("elapsed_s", "rss_start_mb", "rss_peak_mb", "rss_end_mb"):
        rec[k] = round(rec[k], 3)
    return [rec, idle]
