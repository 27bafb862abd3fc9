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
