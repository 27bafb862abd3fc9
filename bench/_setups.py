"""What several benchmarks set up the same way (a module, not a benchmark: scripts/bench.sh skips ``_*.py``)."""

from __future__ import annotations

import os
import random
import socket
import tomllib
from pathlib import Path

from gainlink.laws import design as design_spec
from gainlink.shipping import artifact as artifact_mod
from gainlink.spec import parse_spec

ROOT = Path(__file__).resolve().parents[1]


def multicast_transport(*, fd: bool = True, salt: int = 0, reply: bool = False) -> dict:
    """A udp_multicast transport on a group and port of this process's own (two benchmarks running at once, or a
    test run beside one, do not hear each other), confined to the host (hop limit 0); with ``reply``, the commands
    come back on the next port (``reply_port``: neither end reads back its own frames)."""
    rnd = random.Random(os.getpid() + salt)
    port = rnd.randint(40000, 60000)
    out = {
        "interface": "udp_multicast",
        "channel": f"239.74.{rnd.randint(1, 254)}.{rnd.randint(1, 254)}",
        "port": port,
        "hop_limit": 0,
        "fd": fd,
    }
    if reply:
        out["reply_port"] = port + 1
    return out


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 that nothing holds now (the system's choice)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def pendulum_1khz(folder: Path) -> Path:
    """The pendulum example designed again at a 1 ms period, written to ``folder/gains.json``."""
    spec = tomllib.loads((ROOT / "examples" / "pendulum.toml").read_text())
    spec["Ts"], spec["name"] = 0.001, "pendulum_1khz"
    path = Path(folder) / "gains.json"
    artifact_mod.write(path, design_spec(parse_spec(spec)).artifact)
    return path
