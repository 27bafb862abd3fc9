"""The closed-loop scenario the Cortex-M images' UART tests share (the pendulum FMU over MAVLink or slcan), and the
check that an image's run equals the host app's bit for bit."""

from __future__ import annotations

import numpy as np
from gainlink.hil.loop.scenario import parse_scenario

RANGES = {"x": [-5.0, 5.0], "theta": [-1.0, 1.0], "r_x": [-5.0, 5.0]}


def scenario(
    artifact_path,
    transport: dict,
    *,
    controller: str,
    board: str | None = None,
    duration: float = 1.5,
    faults: list | None = None,
):
    data = {
        "name": "pendulum_uart",
        "artifact": str(artifact_path),
        "duration": duration,
        "mode": "lockstep",
        "controller": controller,
        "step_timeout": 2.0,
        "peer_timeout": 5.0,
        "seed": 7,
        "twin": True,
        "plant": {"kind": "fmu", "fmu": "cart_pendulum", "outputs": ["x", "theta"]},
        "transport": transport,
        "initial_state": {"theta": 0.1},
        "reference": {"r_x": {"kind": "step", "at": 0.3, "value": 0.4}},
        "noise": {"theta": 0.001},
    }
    if board is not None:
        data["board"] = board
    if faults is not None:
        data["faults"] = faults
    return parse_scenario(data, path=artifact_path.parent / "scenario.toml")


def assert_same_closed_loop(image, host) -> None:
    """Both runs complete, nothing lost, and the image's commands and samples equal the host's bit for bit."""
    assert image.complete and host.complete, (image.reason, host.reason)
    assert image.metrics["lost"] == 0 and image.trace.got.all()
    assert image.trace.u.shape == host.trace.u.shape
    np.testing.assert_array_equal(image.trace.u, host.trace.u)  # float32 commands, bit for bit
    np.testing.assert_array_equal(image.trace.y, host.trace.y)
