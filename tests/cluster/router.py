"""A MAVLink router for the cluster tests, doing what ``mavproxy.py --out`` or mavlink-router
do in production: every datagram a vehicle sends goes to every instance, every datagram an
instance sends goes to every vehicle heard. Loopback UDP only, bounded by its ``close``."""

from __future__ import annotations

import selectors
import socket
import threading


class UdpFanout:
    """Vehicles send to ``vehicle_port``; each instance ``udpin`` port in ``outs`` gets a copy
    (its replies come back to the router's instance socket and go to every vehicle)."""

    def __init__(self, outs: list[int]) -> None:
        self._outs = [("127.0.0.1", p) for p in outs]
        self._vehicles_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._vehicles_sock.bind(("127.0.0.1", 0))
        self._instances_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._instances_sock.bind(("127.0.0.1", 0))
        self.vehicle_port = int(self._vehicles_sock.getsockname()[1])
        self._vehicles: set[tuple[str, int]] = set()
        self.forwarded = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="udp-fanout", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        sel = selectors.DefaultSelector()
        sel.register(self._vehicles_sock, selectors.EVENT_READ, "vehicle")
        sel.register(self._instances_sock, selectors.EVENT_READ, "instance")
        while not self._stop.is_set():
            for key, _ in sel.select(0.2):
                sock: socket.socket = key.fileobj  # type: ignore[assignment]
                try:
                    data, addr = sock.recvfrom(65535)
                except OSError:
                    continue
                if key.data == "vehicle":
                    self._vehicles.add(addr)
                    targets, out = self._outs, self._instances_sock
                else:
                    targets, out = sorted(self._vehicles), self._vehicles_sock
                for target in targets:
                    try:
                        out.sendto(data, target)
                        self.forwarded += 1
                    except OSError:  # an instance not listening (killed): the others go on
                        pass
        sel.close()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5.0)
        self._vehicles_sock.close()
        self._instances_sock.close()


__all__ = ["UdpFanout"]
