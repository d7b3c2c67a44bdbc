"""Track exchange between regions over MQTT (any MQTT 5 broker).

Each instance publishes the tracks of the operations it owns, once per publication period,
on the topic of the region each track is in: ``<prefix>/cluster/regions/<region>/traffic``,
in the existing traffic encoding (:func:`adapters.mqtt.encode.encode_traffic`, schema
``traffic.json``). It subscribes to the topics of its own regions and of their neighbours,
and keeps the tracks of other instances' operations inside the halo of one of its regions:
those are fed to its tracker as measurements of the (foreign) operation, so its Monitoring
sees a conflict across a border (:mod:`gcs_utm.cluster.policy` says who then decides).

Queue policy: the outbox is bounded and latest-wins (a traffic message superseded one period
later is worth nothing): when full, the oldest message is dropped and counted. A bad inbound
payload is counted and logged once per topic, never raised. The client reconnects with
backoff (``[mqtt] backoff_initial_s`` .. ``backoff_max_s``); TLS is not supported here yet.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable, Iterable
from dataclasses import dataclass

from adapters.mqtt.config import MqttConfig
from adapters.mqtt.encode import encode_traffic
from adapters.mqtt.wire import MqttMessageError, parse_json, validate
from gcs_utm.cluster.regions import RegionMap
from gcs_utm.model import OperationId, Track

_log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True, kw_only=True)
class RemoteTrack:
    """One track of another instance's operation, as received."""

    region_id: str
    operation_id: OperationId
    t_s: float
    lat_deg: float
    lon_deg: float
    alt_amsl_m: float
    vel_enu_mps: tuple[float, float, float]
    position_sigma_m: float | None


def region_topic(prefix: str, region_id: str) -> str:
    return f"{prefix}/cluster/regions/{region_id}/traffic"


def decode_traffic(topic: str, payload: bytes, region_id: str) -> list[RemoteTrack]:
    """The operations' tracks of one traffic message (tracks without an operation, i.e.
    intruders, are each instance's own surveillance and are skipped); raises
    :class:`MqttMessageError` for a payload that is not a valid traffic message."""
    obj = parse_json(topic, payload)
    validate("traffic", obj, topic)
    assert isinstance(obj, dict)
    out = []
    for tr in obj["tracks"]:
        op = tr.get("operation_id")
        if not op:
            continue
        vel = tr["vel_enu_mps"]
        sigma = tr.get("position_sigma_m")
        out.append(
            RemoteTrack(
                region_id=region_id,
                operation_id=OperationId(str(op)),
                t_s=float(tr["t_s"]),
                lat_deg=float(tr["lat_deg"]),
                lon_deg=float(tr["lon_deg"]),
                alt_amsl_m=float(tr["alt_amsl_m"]),
                vel_enu_mps=(float(vel[0]), float(vel[1]), float(vel[2])),
                position_sigma_m=None if sigma is None else float(sigma),
            )
        )
    return out


class RegionExchange:
    """The MQTT client of one instance's region exchange."""

    def __init__(
        self,
        config: MqttConfig,
        region_map: RegionMap,
        *,
        client_id: str,
        on_tracks: Callable[[list[RemoteTrack]], Awaitable[None]],
        outbox_size: int = 64,
    ) -> None:
        self.config = config
        self.map = region_map
        self.prefix = config.topic_prefix
        self._client_id = client_id
        self._on_tracks = on_tracks
        self._outbox: asyncio.Queue[tuple[str, bytes]] = asyncio.Queue(maxsize=outbox_size)
        self._watched: set[str] = set()
        self._subscribed: set[str] = set()
        self.published = 0
        self.received = 0
        self.dropped = 0
        self.bad = 0
        self.connected = asyncio.Event()

    # ---- outbound -----------------------------------------------------------------------
    def publish(self, tracks: Iterable[Track], t_s: float) -> None:
        """Queue the tracks of this instance's operations, one message per region."""
        by_region: dict[str, list[Track]] = {}
        for tr in tracks:
            by_region.setdefault(self.map.region_of(tr.east_m, tr.north_m), []).append(tr)
        for region_id, part in sorted(by_region.items()):
            item = (region_topic(self.prefix, region_id), encode_traffic(part, t_s))
            if self._outbox.full():
                self._outbox.get_nowait()  # latest wins: the oldest is stale anyway
                self.dropped += 1
            self._outbox.put_nowait(item)

    # ---- inbound ------------------------------------------------------------------------
    def watch(self, regions: Iterable[str]) -> None:
        """Receive the traffic of these regions and of their neighbours."""
        wanted: set[str] = set()
        for r in regions:
            wanted.add(r)
            wanted.update(self.map.neighbours(r))
        self._watched = wanted

    def _region_of_topic(self, topic: str) -> str | None:
        head = f"{self.prefix}/cluster/regions/"
        if not topic.startswith(head) or not topic.endswith("/traffic"):
            return None
        return topic[len(head) : -len("/traffic")]

    async def _receive(self, client: object) -> None:
        import aiomqtt

        assert isinstance(client, aiomqtt.Client)
        async for msg in client.messages:
            topic = str(msg.topic)
            region_id = self._region_of_topic(topic)
            if region_id is None or region_id not in self._watched:
                continue
            payload = msg.payload if isinstance(msg.payload, bytes | bytearray) else b""
            try:
                tracks = decode_traffic(topic, bytes(payload), region_id)
            except MqttMessageError as exc:
                self.bad += 1
                if self.bad == 1 or self.bad % 1000 == 0:
                    _log.warning(
                        "cluster exchange: bad traffic message (%d so far): %s", self.bad, exc
                    )
                continue
            self.received += 1
            if tracks:
                await self._on_tracks(tracks)

    async def _send(self, client: object) -> None:
        import aiomqtt

        assert isinstance(client, aiomqtt.Client)
        while True:
            topic, payload = await self._outbox.get()
            await client.publish(topic, payload, qos=0)
            self.published += 1

    async def _follow_watch(self, client: object) -> None:
        """Subscribe to newly watched regions as regions are gained."""
        import aiomqtt

        assert isinstance(client, aiomqtt.Client)
        while True:
            for region_id in sorted(self._watched - self._subscribed):
                await client.subscribe(region_topic(self.prefix, region_id), qos=0)
                self._subscribed.add(region_id)
            await asyncio.sleep(0.2)

    async def run(self) -> None:
        """Connect, subscribe, exchange; reconnect with backoff until cancelled."""
        import aiomqtt

        delay_s = self.config.backoff_initial_s
        while True:
            try:
                async with aiomqtt.Client(
                    self.config.host,
                    self.config.port,
                    identifier=self._client_id,
                    username=self.config.username or None,
                    password=self.config.password or None,
                    keepalive=self.config.keepalive_s,
                ) as client:
                    self._subscribed = set()
                    self.connected.set()
                    delay_s = self.config.backoff_initial_s
                    async with asyncio.TaskGroup() as tg:
                        tg.create_task(self._follow_watch(client))
                        tg.create_task(self._receive(client))
                        tg.create_task(self._send(client))
            except* aiomqtt.MqttError as group:
                self.connected.clear()
                _log.warning(
                    "cluster exchange: broker %s:%d: %s; retrying in %.1f s",
                    self.config.host,
                    self.config.port,
                    group.exceptions[0],
                    delay_s,
                )
            await asyncio.sleep(delay_s)
            delay_s = min(self.config.backoff_max_s, delay_s * 2)


__all__ = ["RegionExchange", "RemoteTrack", "decode_traffic", "region_topic"]
