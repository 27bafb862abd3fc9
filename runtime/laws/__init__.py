"""gainlink.laws: every kind of control law behind one interface (docs/design.md, "Adding a law").

A law is a pair, structure x numeric format; :func:`law_of` is the one place that decides which law an artifact
runs, from the artifact's own content (a ``schedule`` block: the scheduled structure; ``checks.fixed_point``: an
integer format). Everything else asks the returned :class:`Law`: for a :class:`Controller` to step
(``reference``, ``model``, ``native``), for its refusals (:meth:`Law.refuse`), its safe command and trim.

Pairs today: ``lq/float32``, ``lq/q31``, ``lq/q15``, ``scheduled/float32``, ``mpc/float32``. A scheduled law on
integers is not a pair: a time-varying law has no worst-case peak gain to certify its formats with.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ..errors import LawError
from ..shipping.law_c import law_pair
from .base import CELLS, ENGINES, Capabilities, Controller, Law, OneStepVerdict, Step
from .fixed import FixedLaw
from .lq import LqLaw
from .mpc import MpcLaw
from .scheduled import ScheduledLaw

if TYPE_CHECKING:
    from ..spec import PlantSpec
    from ..synthesis.pipeline import DesignResult

__all__ = [
    "CELLS",
    "ENGINES",
    "Capabilities",
    "Controller",
    "Law",
    "OneStepVerdict",
    "Step",
    "design",
    "law_for",
    "law_for_spec",
    "law_of",
    "pairs",
]

#: Each structure's law class (its numeric formats are the class's).
STRUCTURES: dict[str, tuple[type[Law], ...]] = {"lq": (LqLaw, FixedLaw), "scheduled": (ScheduledLaw,),
                                                "mpc": (MpcLaw,)}  # fmt: skip

#: Why a structure has no form in a numeric format that another structure has.
NOT_PAIRS = {
    ("scheduled", "q31"): "a scheduled law on integers is time-varying, and the worst-case peak gain that certifies "
    "a fixed-point law's formats does not apply to it",
}
NOT_PAIRS[("scheduled", "q15")] = NOT_PAIRS[("scheduled", "q31")]


def pairs() -> list[str]:
    """Every law pair, ``structure/numeric``."""
    return [f"{s}/{n}" for s, classes in STRUCTURES.items() for cls in classes for n in cls.numerics]


def law_for(structure: str, numeric: str = "float32") -> Law:
    """The law of ``structure`` in ``numeric``; :class:`LawError` (one line) for anything that is not a pair."""
    if structure not in STRUCTURES:
        raise LawError(f"unknown law structure {structure!r} (structures: {', '.join(STRUCTURES)})")
    for cls in STRUCTURES[structure]:
        if numeric in cls.numerics:
            return cls(numeric)
    reason = NOT_PAIRS.get((structure, numeric))
    if reason is not None:
        raise LawError(f"no {structure} law in {numeric}: {reason}")
    formats = [n for cls in STRUCTURES[structure] for n in cls.numerics]
    raise LawError(f"no {structure} law in {numeric} (formats: {', '.join(formats)})")


def law_of(artifact: Any) -> Law:
    """The law ``artifact`` runs. Which it is, is read in one place, :func:`gainlink.shipping.law_c.law_pair`, below
    this layer because the C export names the law too (module docstring)."""
    return law_for(*law_pair(artifact))


def law_for_spec(spec: PlantSpec) -> Law:
    """The law a spec asks for: a ``[schedule]`` the scheduled structure, ``[controller] method = "mpc"`` the MPC
    structure, ``[implementation] numeric`` its format; the one place that reads which for a spec, as :func:`law_of`
    for an artifact."""
    structure = "scheduled" if spec.schedule is not None else "mpc" if spec.mpc is not None else "lq"
    return law_for(structure, spec.implementation.numeric)


def design(spec: PlantSpec) -> DesignResult:
    """Design the law ``spec`` asks for (:func:`law_for_spec`): the sealed artifact and the numbers behind its
    checks (what ``gl.design_report`` returns)."""
    return law_for_spec(spec).design(spec)
