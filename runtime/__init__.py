"""gainlink: state-space controller design to a verified, running firmware loop.

``import gainlink as gl`` gives the curated API in :data:`__all__`: designs from a spec file, a dict
or a python-control system (:func:`design`), artifacts from one's own gains (:func:`from_gains`),
the artifact (:class:`Artifact`: ``load``, ``save``, ``controller()``, ``closed_loop()``), replay and
simulation of the law, the HIL bridge as :mod:`gainlink.hil` (``gl.hil.run``) and campaigns on Dask as
:mod:`gainlink.hil.campaign` (``gl.campaign.run``; imported on first use, so ``import gainlink`` loads
neither it nor Dask). The command line ``gainlink`` is a shell over the same functions.
"""

__version__ = "0.1.0"

# The submodules design, replay and simulate are loaded first; the functions of the same names
# then take their place as attributes of the package (``gl.design(...)``). Code inside gainlink
# imports from the submodules (``from gainlink.design import design``), which is unaffected.
from . import design as _design_module, replay as _replay_module, simulate as _simulate_module  # noqa: E402,F401
from .api import design, from_gains, load, replay, simulate  # noqa: E402
from .artifact import Artifact  # noqa: E402
from .errors import (ArtifactError, DataError, DesignError, GainlinkError, IntegrityError,  # noqa: E402
                     PlantError, ScenarioError, SpecError)
from .reference import ReferenceLoop, Trace  # noqa: E402
from .simulate import Simulation  # noqa: E402
from .compensator import compensator_stability  # noqa: E402
from .fidelity import float32_fidelity  # noqa: E402
from .onestep import one_step_check  # noqa: E402
from .twin import twin_comparison  # noqa: E402
from . import hil  # noqa: E402

__all__ = [
    "design", "from_gains", "load", "replay", "simulate",
    "Artifact", "ReferenceLoop", "Trace", "Simulation",
    "GainlinkError", "SpecError", "DesignError", "ArtifactError", "IntegrityError", "DataError",
    "PlantError", "ScenarioError",
    "one_step_check", "compensator_stability", "float32_fidelity", "twin_comparison",
    "hil", "campaign",
]


def __getattr__(name: str):
    # gl.campaign is gainlink.hil.campaign, imported when first asked for (PEP 562).
    if name == "campaign":
        import importlib

        module = importlib.import_module("gainlink.hil.campaign")
        globals()[name] = module
        return module
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
