"""UDP/TCP ports and multicast groups private to one test, for a suite that runs in parallel.

Several suites share a host: the pytest-xdist workers of one run, and the runs of other checkouts. What keeps
their buses apart is the *port*, not the multicast group: python-can's ``udp_multicast`` and the firmware's
``gainlink_can`` both bind their socket to ``INADDR_ANY:port`` with ``SO_REUSEPORT``, and on Linux such a socket
receives the datagrams of every group that any socket of the host joined on that port (``IP_MULTICAST_ALL`` is on
by default). Two buses on different groups but the same port hear each other; on different ports they do not.

So every test takes its own ports from :func:`udp_port` / :func:`tcp_port`:

- below the kernel's ephemeral range (32768-60999), so no socket the kernel numbers itself (a client's source
  port, a ``bind(("", 0))``) can take one between the test choosing it and binding it; clear of the campaign's
  bus-slot ports (14600.., 43200..) and python-can's default 43113;
- from a block of its own per xdist worker, so two workers of one run never pick the same port;
- never twice in one process, starting at a random place in the block;
- only when a probe ``bind`` without ``SO_REUSEADDR``/``SO_REUSEPORT`` succeeds, so a port that a concurrent
  suite of another checkout holds right now is skipped.
"""

from __future__ import annotations

import os
import random
import socket

FIRST_PORT = 20000
BLOCK = 600  # ports per xdist worker: 20 workers fit below 32000
WORKER_BLOCKS = 20

_given: set[int] = set()
_rng = random.Random(os.getpid() ^ int.from_bytes(os.urandom(4), "little"))


def worker_index() -> int:
    """This process's pytest-xdist worker number (``gw3`` -> 3), 0 outside xdist."""
    name = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    return int(name[2:]) % WORKER_BLOCKS if name.startswith("gw") and name[2:].isdigit() else 0


def _free(port: int, kind: int) -> bool:
    with socket.socket(socket.AF_INET, kind) as s:
        try:
            s.bind(("0.0.0.0", port))
        except OSError:
            return False
    return True


def _port(kind: int) -> int:
    first = FIRST_PORT + BLOCK * worker_index()
    start = _rng.randrange(BLOCK)
    for i in range(BLOCK):
        port = first + (start + i) % BLOCK
        if port not in _given and _free(port, kind):
            _given.add(port)
            return port
    raise RuntimeError(f"no free port left in {first}..{first + BLOCK - 1} (worker {worker_index()})")


def udp_port() -> int:
    """A UDP port no other test uses: for a MAVLink link or a udp_multicast bus."""
    return _port(socket.SOCK_DGRAM)


def tcp_port() -> int:
    """A TCP port no other test uses: for a QEMU UART served as a socket."""
    return _port(socket.SOCK_STREAM)


def multicast_group() -> str:
    """A random IPv4 group in 239.74.0.0/16 (the port isolates the bus; a distinct group keeps captures legible)."""
    return f"239.74.{_rng.randint(1, 254)}.{_rng.randint(1, 254)}"
