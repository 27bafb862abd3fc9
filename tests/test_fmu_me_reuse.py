"""A Model Exchange FMU plant's instance serves a campaign worker's next runs (as a Co-Simulation one does): one
instance per FMU and variables in use, reset between runs, and a run on a reused instance gives the fresh
instance's trace bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from support.campaign_plants import fmu_run


@pytest.fixture(autouse=True)
def no_kept_instances():
    """Each test starts with no FMU instance kept in this process (an earlier test's would be counted)."""
    from gainlink.hil.plants import fmu

    fmu._free_idle()
    yield
    fmu._free_idle()


ARGS = {"inputs": None, "outputs": None, "states": None, "parameters": {"m": 0.1}}


def _me_run(cart_fmu, pend, m: float, *, rtol: float = 1e-8):
    """A 0.5 s SIL run of the pendulum law on the cart-pendulum FMU through Model Exchange (fmpy's CVode), pole mass
    ``m``."""
    return fmu_run(cart_fmu, pend, m, interface="me", duration=0.5, rtol=rtol)


def test_a_model_exchange_instance_serves_the_next_runs_as_a_fresh_one_would(cart_fmu, pend):
    """Runs with other parameters and another tolerance between: the same instance object is kept (one unzipped
    copy), and the run on it repeats the fresh instance's trace bit for bit."""
    from gainlink.hil.plants import fmu

    fresh = _me_run(cart_fmu, pend, 0.12)
    assert fresh.info["plant"]["interface"] == "me"
    assert not fmu.idle_instances()  # outside: each plant freed at its run's end
    with fmu.reused_instances():
        _me_run(cart_fmu, pend, 0.08, rtol=1e-6)
        (kept,) = fmu.idle_instances().values()
        instance = kept[0].me
        again = _me_run(cart_fmu, pend, 0.12)
        for m in (0.1, 0.09):
            _me_run(cart_fmu, pend, m)
        (now,) = fmu.idle_instances().values()
    assert [p.me for p in now] == [instance] and kept[0].solver is None  # CVode's memory freed at each close
    for name in ("t", "y", "u", "r"):
        assert np.array_equal(getattr(again.trace, name), getattr(fresh.trace, name)), name
    assert again.metrics["outputs_final"] == fresh.metrics["outputs_final"]


def test_a_model_exchange_plant_whose_call_failed_is_freed_not_kept(cart_fmu):
    """A plant whose step failed (an infinite force: its outputs leave the finite numbers) is freed at close, never
    served again; the kept ones are freed at exit."""
    from gainlink.errors import PlantError
    from gainlink.hil.plants import fmu
    from gainlink.hil.plants.fmu_me import FmuModelExchangePlant

    with fmu.reused_instances():
        plant = fmu.opened(FmuModelExchangePlant, ARGS | {"path": cart_fmu}, {})
        with pytest.raises(PlantError):
            plant.advance(u=np.array([np.inf]), dt=0.01)
        plant.close()
        assert not any(fmu.idle_instances().values()) and plant.me is None
        good = fmu.opened(FmuModelExchangePlant, ARGS | {"path": cart_fmu}, {})
        good.close()
        (kept,) = fmu.idle_instances().values()
        assert kept == [good] and good.me is not None
    fmu._free_idle()  # as at exit
    assert good.me is None


def test_a_kept_instance_that_cannot_serve_the_next_run_is_freed_with_one_line(cart_fmu):
    """The next run's refused setting (a negative rtol) or parameter (a name the FMU has not), met when a kept instance
    is taken for it: one PlantError line naming it, and the instance freed, neither kept nor left loaded."""
    from gainlink.errors import PlantError
    from gainlink.hil.plants import fmu
    from gainlink.hil.plants.fmu_me import FmuModelExchangePlant

    args = ARGS | {"path": cart_fmu}
    refusals = ((args, {"rtol": -1.0}, "rtol"), (args | {"parameters": {"nope": 1.0}}, {}, "nope"))
    for bad_args, settings, says in refusals:
        with fmu.reused_instances():
            fmu.opened(FmuModelExchangePlant, args, {}).close()
            (kept,) = fmu.idle_instances().values()
            with pytest.raises(PlantError, match=says) as refused:
                fmu.opened(FmuModelExchangePlant, bad_args, settings)
            assert "\n" not in str(refused.value)
            assert not any(fmu.idle_instances().values()) and kept[0].me is None
