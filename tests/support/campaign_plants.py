"""Plants for the campaign tests: one that fails as a bug in a user's plant does (with an exception of its own),
one that takes its time; and a SIL run of the pendulum law on the project's cart-pendulum FMU (:func:`fmu_run`).

Imported by name (``kind = "python", class = "support.campaign_plants:BuggyPendulum"``) in the Dask worker
processes of the tests, which have this folder on their ``PYTHONPATH``.
"""

from __future__ import annotations

import time
from pathlib import Path

from gainlink.errors import PlantError
from gainlink.hil.plants.models import CartPendulum


class BuggyPendulum(CartPendulum):
    """The built-in cart-pendulum; with ``bug = true`` its constructor raises a RuntimeError (not a GainlinkError,
    so the run raises on the worker, as a bug would); with ``broken_while = PATH`` it refuses to start (a
    PlantError: the run's error) as long as that file exists."""

    def __init__(self, *, bug: bool = False, broken_while: str = "", **options) -> None:
        super().__init__(**options)
        if bug:
            raise RuntimeError("BuggyPendulum: the bug this test asked for")
        if broken_while and Path(broken_while).exists():
            raise PlantError(f"BuggyPendulum: broken while {broken_while} exists")


class SlowPendulum(CartPendulum):
    """The built-in cart-pendulum, asleep ``pause`` seconds in every step (wall time, no CPU): a campaign of it
    lasts long enough to be interrupted or killed halfway even when a loaded machine stalls the test for a while
    (the plain pendulum's runs take a few tenths of a second each)."""

    def __init__(self, *, pause: float = 0.0, **options) -> None:
        super().__init__(**options)
        self.pause = pause

    def advance(self, *, u, dt: float) -> None:
        time.sleep(self.pause)
        super().advance(u=u, dt=dt)


def fmu_run(cart_fmu: Path, pend: Path, m: float, *, interface: str, duration: float, **plant):
    """A SIL run of the pendulum law (``pend``, its gains.json) on the cart-pendulum FMU through ``interface``
    (``cs`` or ``me``), pole mass ``m`` and the plant table's other keys ``plant``, with its twin."""
    from gainlink.hil.loop.bridge import run_scenario
    from gainlink.hil.loop.scenario import parse_scenario

    data = {
        "artifact": str(pend),
        "transport": {},
        "duration": duration,
        "seed": 3,
        "initial_state": {"theta": 0.1},
        "noise": {"theta": 1e-4},
        "plant": {"kind": "fmu", "path": str(cart_fmu), "interface": interface, "parameters": {"m": m}, **plant},
    }
    return run_scenario(parse_scenario(data))
