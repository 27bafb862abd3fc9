"""Scenarios and CAN transports of the HIL, CAN, FMU and vcan tests."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from gainlink.hil.plants import toml_write

from .net import multicast_group, udp_port

#: int16 ranges for the pendulum's outputs and reference (the input F takes the artifact's +-20 N).
PENDULUM_RANGES = {"x": [-5.0, 5.0], "theta": [-1.0, 1.0], "r_x": [-5.0, 5.0]}


def udp_transport(*, fd: bool = True) -> dict[str, Any]:
    """A python-can udp_multicast configuration on a port (and group) of this test's own."""
    return {"interface": "udp_multicast", "channel": multicast_group(), "port": udp_port(), "hop_limit": 0, "fd": fd}


def write_scenario(path: Path, data: dict[str, Any]) -> Path:
    """Write a scenario mapping as TOML."""
    path.write_text(toml_write.dumps(data), "utf-8")
    return path


def pendulum_scenario(
    *, gains: Path, fmu: Path, transport: dict[str, Any], duration: float = 3.0, **extra: Any
) -> dict[str, Any]:
    """Lockstep: the firmware stabilises the nonlinear pendulum FMU from theta = 0.1 rad.

    The per-command wait is generous (a shared VM can stall for a few hundred ms); it only elapses when a
    command is really lost, and fault tests that lose commands on purpose pass their own short one.
    """
    data = {
        "name": "pendulum_hil",
        "artifact": str(gains),
        "duration": duration,
        "mode": "lockstep",
        "controller": "firmware",
        "step_timeout": 2.0,
        "peer_timeout": 4.0,
        "plant": {"kind": "fmu", "path": str(fmu), "outputs": ["x", "theta"]},
        "transport": transport,
        "initial_state": {"theta": 0.1},
    }
    data.update(extra)
    return data
