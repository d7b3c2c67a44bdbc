"""Closing the pilot station while it is connecting (``gcs-utm pilot``, Ctrl-C with the broker
unreachable): a cancel that reaches the station inside a connection attempt and comes out as
a connection error (``asyncio.timeout`` and the MQTT client can turn it into one) ends the
station; it does not become one more retry, which left the process running until killed."""

from __future__ import annotations

import asyncio

from adapters.mqtt.config import MqttConfig
from adapters.mqtt.station import PilotStation
from gcs_utm.clock import ManualClock


async def test_a_cancel_turned_into_a_connection_error_still_closes_the_station() -> None:
    station = PilotStation(
        MqttConfig(backoff_initial_s=0.01, backoff_max_s=0.01), "op", ManualClock(0.0)
    )
    attempts = 0

    async def connect_that_hides_the_cancel() -> None:
        nonlocal attempts
        attempts += 1
        try:
            await asyncio.sleep(3600.0)  # waiting for CONNACK
        except asyncio.CancelledError:
            raise OSError("connection aborted") from None

    station._serve_once = connect_that_hides_the_cancel  # type: ignore[method-assign]

    async def open_then_close() -> None:
        async with station:
            while attempts == 0:
                await asyncio.sleep(0.01)

    closing = asyncio.create_task(open_then_close())
    done, _ = await asyncio.wait([closing], timeout=5.0)
    assert done, f"the station did not close ({attempts} connection attempts)"
    closing.result()
    assert attempts == 1
