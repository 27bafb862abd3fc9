"""Helpers and fixtures shared by the HIL, CAN, FMU and vcan tests (imported by them; holds no tests)."""

from __future__ import annotations

import os
import random
from pathlib import Path

import pytest
from gainlink.hil.plants import toml_write
from gainlink.shipping.artifact import load

_rng = random.Random(os.getpid() ^ int.from_bytes(os.urandom(4), "little"))


def udp_transport(*, fd: bool = True) -> dict:
    """A python-can udp_multicast configuration on a private group and port (tests may run in parallel)."""
    return {
        "interface": "udp_multicast",
        "channel": f"239.74.{_rng.randint(1, 254)}.{_rng.randint(1, 254)}",
        "port": _rng.randint(40000, 60000),
        "hop_limit": 0,
        "fd": fd,
    }


def write_scenario(path: Path, data: dict) -> Path:
    """Write a scenario mapping as TOML."""
    path.write_text(toml_write.dumps(data), "utf-8")
    return path


@pytest.fixture(scope="session")
def pendulum_gains(example_artifacts) -> Path:
    """The pendulum example's artifact (designed once per session by conftest)."""
    return example_artifacts["pendulum"]


@pytest.fixture(scope="session")
def can_firmware(pendulum_gains) -> Path:
    """The firmware's gainlink_can host executable built for the pendulum artifact."""
    from gainlink.hil.links.can_firmware import firmware_can_executable

    return firmware_can_executable(load(pendulum_gains))


@pytest.fixture(scope="session")
def cart_fmu() -> Path:
    """The project's nonlinear cart-pendulum FMU, built from its C sources with fmpy."""
    from gainlink.hil.plants.build import build_fmu

    return build_fmu("cart_pendulum")


def pendulum_scenario(*, gains: Path, fmu: Path, transport: dict, duration: float = 3.0, **extra) -> dict:
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
