"""Making a design: a typed spec in, a checked, sealed gain artifact out.

:func:`synthesize` runs the pipeline (discretise, augment with integrators, controller gain, observer gain,
anti-windup, the loop's checks, the implementation choices); :mod:`.analysis` answers structural questions
about a plant; :mod:`.compensator`, :mod:`.deadtime` and :mod:`.realization` are the checks and coordinate
choices the pipeline records.
"""

from .pipeline import DesignResult, synthesize

__all__ = ["DesignResult", "synthesize"]
