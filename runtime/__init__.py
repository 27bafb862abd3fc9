"""gainlink: state-space controller design to a verified, running firmware loop.

``import gainlink as gl`` gives the curated API in :data:`__all__`: designs from a spec file, a dict
or a python-control system (:func:`design`), artifacts from one's own gains (:func:`from_gains`),
the artifact (:class:`Artifact`: ``load``, ``save``, ``controller()``, ``closed_loop()``), replay and
simulation of the law, the HIL bridge as :mod:`gainlink.hil` (``gl.hil.run``) and campaigns on Dask as
:mod:`gainlink.hil.campaign` (``gl.campaign.run``). The command line ``gainlink`` is a shell over the same functions.

Each name is imported when first asked for (PEP 562), so that ``import gainlink.hil.loop.bridge`` (or the
command line's ``gainlink hil run``) does not load the design side, SciPy and python-control it never uses, and
``import gainlink`` loads neither the campaigns nor Dask.
"""

import importlib as _importlib
from typing import TYPE_CHECKING, Any

from .version import __version__ as __version__

if TYPE_CHECKING:  # the same names for type checkers, as explicit re-exports
    from . import hil as hil
    from .api import analyze as analyze
    from .api import design as design
    from .api import design_report as design_report
    from .api import from_gains as from_gains
    from .api import load as load
    from .api import replay as replay
    from .api import simulate as simulate
    from .errors import ArtifactError as ArtifactError
    from .errors import DataError as DataError
    from .errors import DesignError as DesignError
    from .errors import GainlinkError as GainlinkError
    from .errors import IntegrityError as IntegrityError
    from .errors import PlantError as PlantError
    from .errors import ScenarioError as ScenarioError
    from .errors import SpecError as SpecError
    from .hil import campaign as campaign
    from .laws.lq.fidelity import float32_fidelity as float32_fidelity
    from .proof.onestep import one_step_check as one_step_check
    from .proof.reference import ReferenceLoop as ReferenceLoop
    from .proof.reference import Trace as Trace
    from .proof.simulation import Simulation as Simulation
    from .proof.twin import twin_comparison as twin_comparison
    from .shipping.artifact import Artifact as Artifact
    from .synthesis.compensator import compensator_stability as compensator_stability

#: Where each public name lives: name -> (module relative to this package, attribute or None for the module).
_WHERE = {
    "Artifact": (".shipping.artifact", "Artifact"),
    "ArtifactError": (".errors", "ArtifactError"),
    "DataError": (".errors", "DataError"),
    "DesignError": (".errors", "DesignError"),
    "GainlinkError": (".errors", "GainlinkError"),
    "IntegrityError": (".errors", "IntegrityError"),
    "PlantError": (".errors", "PlantError"),
    "ReferenceLoop": (".proof.reference", "ReferenceLoop"),
    "ScenarioError": (".errors", "ScenarioError"),
    "Simulation": (".proof.simulation", "Simulation"),
    "SpecError": (".errors", "SpecError"),
    "Trace": (".proof.reference", "Trace"),
    "analyze": (".api", "analyze"),
    "campaign": (".hil.campaign", None),
    "compensator_stability": (".synthesis.compensator", "compensator_stability"),
    "design": (".api", "design"),
    "design_report": (".api", "design_report"),
    "float32_fidelity": (".laws.lq.fidelity", "float32_fidelity"),
    "from_gains": (".api", "from_gains"),
    "hil": (".hil", None),
    "load": (".api", "load"),
    "one_step_check": (".proof.onestep", "one_step_check"),
    "replay": (".api", "replay"),
    "simulate": (".api", "simulate"),
    "twin_comparison": (".proof.twin", "twin_comparison"),
}

__all__ = sorted(_WHERE)


def __getattr__(name: str) -> Any:
    where = _WHERE.get(name)
    if where is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    module = _importlib.import_module(where[0], __name__)
    value = module if where[1] is None else getattr(module, where[1])
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


# Every law family registers its parts in the tables of the layers below the laws (gainlink.registry) when
# gainlink.laws is imported; importing it here fills them before any gainlink module is used, whichever is imported
# first (``import gainlink.shipping.artifact`` runs this file first). It costs numpy and the artifact's modules, which
# every command that reads a spec or an artifact loads anyway; SciPy and python-control stay lazy.
from . import laws as _laws  # noqa: E402, F401
