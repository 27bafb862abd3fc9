"""A lossy UDP relay for link fault injection: drops, duplicates and reorders datagrams both ways.

Clients send to the relay's port; the relay forwards to ``upstream`` from its own socket and sends
what comes back to the last client address. Each datagram independently is dropped with
probability ``drop``, else sent twice with probability ``duplicate``, and held back with
probability ``reorder`` until the next datagram in the same direction has gone out (so it arrives
after it). A seeded random generator makes a run reproducible.
"""

from __future__ import annotations

import random
import selectors
import socket
import threading
from dataclasses import dataclass


@dataclass
class RelayStats:
    """Datagrams seen, dropped, duplicated and reordered (both directions)."""

    seen: int = 0
    dropped: int = 0
    duplicated: int = 0
    reordered: int = 0


class LossyUdpRelay:
    """A UDP relay thread (a context manager).

    Parameters
    ----------
    upstream : tuple of (str, int)
        Where to forward client datagrams (e.g. the firmware's ``udpin`` address).
    drop, duplicate, reorder : float
        Probabilities per datagram.
    seed : int
        Seed of the random generator.
    host : str
        Address the relay listens on (its port is chosen by the system: see :attr:`port`).
    """

    def __init__(
        self,
        *,
        upstream: tuple[str, int],
        drop: float = 0.2,
        duplicate: float = 0.1,
        reorder: float = 0.1,
        seed: int = 1,
        host: str = "127.0.0.1",
    ):
        self.upstream = upstream
        self.drop, self.duplicate, self.reorder = drop, duplicate, reorder
        self.rng = random.Random(seed)
        self.stats = RelayStats()
        self.front = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.front.bind((host, 0))
        self.back = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.back.bind((host, 0))
        self.port = self.front.getsockname()[1]
        self.client: tuple[str, int] | None = None
        self._held: dict[str, bytes | None] = {"up": None, "down": None}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="lossy-udp-relay", daemon=True)

    @property
    def url(self) -> str:
        """pymavlink URL a client uses to talk through the relay."""
        return f"udpout:127.0.0.1:{self.port}"

    def _forward(self, direction: str, data: bytes) -> None:
        sock, dest = (self.back, self.upstream) if direction == "up" else (self.front, self.client)
        if dest is None:
            return
        self.stats.seen += 1
        r = self.rng.random()
        if r < self.drop:
            self.stats.dropped += 1
            return
        copies = 2 if self.rng.random() < self.duplicate else 1
        self.stats.duplicated += copies - 1
        held = self._held[direction]
        if held is None and self.rng.random() < self.reorder:
            self._held[direction] = data
            self.stats.reordered += 1
            return
        for _ in range(copies):
            sock.sendto(data, dest)
        if held is not None:
            sock.sendto(held, dest)
            self._held[direction] = None

    def _run(self) -> None:
        sel = selectors.DefaultSelector()
        sel.register(self.front, selectors.EVENT_READ, "up")
        sel.register(self.back, selectors.EVENT_READ, "down")
        try:
            while not self._stop.is_set():
                events = sel.select(timeout=0.05)
                if not events:
                    for direction, held in self._held.items():  # release what waited for a successor too long
                        if held is not None:
                            self._held[direction] = None
                            self._forward_raw(direction, held)
                for key, _ in events:
                    try:
                        data, addr = key.fileobj.recvfrom(65536)
                    except OSError:
                        continue
                    if key.data == "up":
                        self.client = addr
                    self._forward(key.data, data)
        finally:
            sel.close()

    def _forward_raw(self, direction: str, data: bytes) -> None:
        sock, dest = (self.back, self.upstream) if direction == "up" else (self.front, self.client)
        if dest is not None:
            sock.sendto(data, dest)

    def start(self) -> LossyUdpRelay:
        """Start the relay thread."""
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop the thread and close the sockets."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2)
        self.front.close()
        self.back.close()

    def __enter__(self) -> LossyUdpRelay:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()
