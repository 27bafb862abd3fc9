"""Making a design: a typed spec in, a checked, sealed gain artifact out.

:func:`synthesize_lq` runs the observer-based law's pipeline (discretise, augment with integrators, controller gain,
observer gain, anti-windup, the loop's checks, the implementation choices; a law asks for it with its own check of
its arithmetic, :func:`gainlink.laws.design` designs any spec); :mod:`.analysis` answers structural questions
about a plant; :mod:`.compensator`, :mod:`.deadtime` and :mod:`.realization` are the checks and coordinate
choices the pipeline records.
"""

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .pipeline import DesignResult as DesignResult
    from .pipeline import synthesize_lq as synthesize_lq

__all__ = ["DesignResult", "synthesize_lq"]


def __getattr__(name: str) -> Any:
    # The pipeline (SciPy, python-control, the LMI solvers) is imported on first use (PEP 562), not by every
    # import of a submodule: the HIL bridge uses .compensator and must not pay for it.
    if name in __all__:
        from . import pipeline

        return getattr(pipeline, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
