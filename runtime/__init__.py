"""gainlink: state-space controller design to a verified, running firmware loop.

``import gainlink as gl`` gives the curated API in :data:`__all__`: designs from a spec file, a dict
or a python-control system (:func:`design`), artifacts from one's own gains (:func:`from_gains`),
the artifact (:class:`Artifact`: ``load``, ``save``, ``controller()``, ``closed_loop()``), replay and
simulation of the law, the HIL bridge as :mod:`gainlink.hil` (``gl.hil.run``) and campaigns on Dask as
:mod:`gainlink.hil.campaign` (``gl.campaign.run``; imported on first use, so ``import gainlink`` loads
neither it nor Dask). The command line ``gainlink`` is a shell over the same functions.
"""

import types as _types

from . import hil
from .api import analyze, design, design_report, from_gains, load, replay, simulate
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
from .proof.fidelity import float32_fidelity
from .proof.onestep import one_step_check
from .proof.reference import ReferenceLoop, Trace
from .proof.simulation import Simulation
from .proof.twin import twin_comparison
from .shipping.artifact import Artifact
from .synthesis.compensator import compensator_stability
from .version import __version__ as __version__

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
    "analyze",
    "campaign",
    "compensator_stability",
    "design",
    "design_report",
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
