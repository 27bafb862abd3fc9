"""The MPC example as the tests vary it (examples/pendulum_mpc.toml)."""

from __future__ import annotations

import tomllib

from support.paths import EXAMPLES


def mpc_pendulum(horizon: int = 20, *, box: float | None = None, soft: dict | None = None, cap: int = 10) -> dict:
    """examples/pendulum_mpc.toml, with another horizon, cap, input box or soft boxes."""
    data = tomllib.loads((EXAMPLES / "pendulum_mpc.toml").read_text())
    data["mpc"].update(horizon=horizon, max_iter=cap)
    if box is not None:
        data["limits"].update(u_min=[-box], u_max=[box])
    if soft:
        data["mpc"]["boxes"] = soft
    return data
