"""Scheduled specs for the tests: the example tank (sigma = its measured level) and variants with an external
sigma, a current-form observer, and a family with a crossing that no common Lyapunov function covers."""

from __future__ import annotations

import copy
from pathlib import Path

from gainlink.fileio import read_toml

ROOT = Path(__file__).resolve().parents[1]
TANK = ROOT / "examples" / "tank_scheduled.toml"


def tank_dict() -> dict:
    """The example spec as a dict (a fresh copy each call)."""
    data, _ = read_toml(TANK, what="spec", error=ValueError)
    return copy.deepcopy(data)


def tank_hil_scenario(path, *, name: str, transport: dict, rate: float = 0.2, start: float = 1.0, **extra) -> dict:
    """A lockstep HIL scenario of the scheduled tank (artifact at ``path``) on ``transport``: from rest at 0.04 m,
    the level's reference climbs to 1 m at ``rate`` m/s from ``start`` (6 s; ``extra`` keys replace or add)."""
    data: dict = {
        "name": name,
        "artifact": str(path),
        "duration": 6.0,
        "controller": "firmware",
        "step_timeout": 2.0,
        "peer_timeout": 4.0,
        "plant": {"kind": "tank", "step": 0.005},
        "transport": transport,
        "initial_state": {"q": 0.08, "h": 0.04},
        "reference": {"r_h": {"kind": "sweep", "low": 0.04, "high": 1.0, "rate": rate, "start": start}},
    }
    return data | extra


def external_tank(*, form: str = "predictor", rate_max: float | None = None, filter_tau: float = 0.0) -> dict:
    """The tank scheduled on an external signal ``load`` (a frozen sigma is then a constant input)."""
    data = tank_dict()
    data["schedule"]["sigma"] = "load"
    data["schedule"]["external"] = ["load"]
    data["schedule"]["filter_tau"] = filter_tau
    if rate_max is not None:
        data["schedule"]["rate_max"] = rate_max
    data["observer"]["form"] = form
    return data


def spring(k_end: float = 400.0) -> dict:
    """A mass on a spring whose stiffness is scheduled from 1 to ``k_end`` (an external sigma from 0 to 1): the
    frozen loops are stable everywhere, no Lyapunov certificate is found, and sigma moving fast destabilises it."""
    return {
        "name": "spring",
        "Ts": 0.02,
        "plant": {"kind": "continuous", "states": ["x", "v"], "inputs": ["F"], "outputs": ["x"]},
        "schedule": {
            "sigma": "k",
            "external": ["k"],
            "points": [0.0, 1.0],
            "plant": [{"A": [[0.0, 1.0], [-k, -0.1]], "B": [[0.0], [1.0]], "C": [[1.0, 0.0]]} for k in (1.0, k_end)],
        },
        "controller": {"method": "lqr", "Q_diag": [100.0, 1.0], "R_diag": [0.01]},
        "integral": {"outputs": ["x"], "Q_diag": [1000.0]},
        "observer": {"method": "kalman", "W_diag": [1e-4, 1e-2], "V_diag": [1e-6]},
        "limits": {"u_min": [-1e3], "u_max": [1e3]},
    }
