"""gainlink: state-space controller design to a verified, running firmware loop.

``import gainlink as gl`` gives the curated API in :data:`__all__`: designs from a spec file, a dict
or a python-control system (:func:`design`), artifacts from one's own gains (:func:`from_gains`),
the artifact (:class:`Artifact`: ``load``, ``save``, ``controller()``, ``closed_loop()``), replay and
simulation of the law, the HIL bridge as :mod:`gainlink.hil` (``gl.hil.run``) and campaigns on Dask as
:mod:`gainlink.hil.campaign` (``gl.campaign.run``; imported on first use, so ``import gainlink`` loads
neither it nor Dask). The command line ``gainlink`` is a shell over the same functions.
"""

__version__ = "0.1.0"

import types as _types

# The submodules design, replay and simulate are loaded first; the functions of the same names
# then take their place as attributes of the package (``gl.design(...)``). Code inside gainlink
# imports from the submodules (``from gainlink.design import design``), which is unaffected.
from . import design as _design_module  # noqa: F401
from . import hil
from . import replay as _replay_module  # noqa: F401
from . import simulate as _simulate_module  # noqa: F401
from .api import design, from_gains, load, replay, simulate
from .artifact import Artifact
from .compensator import compensator_stability
from .errors import (
    ArtifactError,
    DataError,
    DesignError,
    GainlinkError,
    IntegrityError,
    PlantError,
    ScenarioError,
    SpecError,
)
from .fidelity import float32_fidelity
from .onestep import one_step_check
from .reference import ReferenceLoop, Trace
from .simulate import Simulation
from .twin import twin_comparison

__all__ = [
    "Artifact",
    "ArtifactError",
    "DataError",
    "DesignError",
    "GainlinkError",
    "IntegrityError",
    "PlantError",
    "ReferenceLoop",
    "ScenarioError",
    "Simulation",
    "SpecError",
    "Trace",
    "campaign",
    "compensator_stability",
    "design",
    "float32_fidelity",
    "from_gains",
    "hil",
    "load",
    "one_step_check",
    "replay",
    "simulate",
    "twin_comparison",
]


def __getattr__(name: str) -> _types.ModuleType:
    # gl.campaign is gainlink.hil.campaign, imported when first asked for (PEP 562).
    if name == "campaign":
        import importlib

        module = importlib.import_module("gainlink.hil.campaign")
        globals()[name] = module
        return module
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
