"""The float32 lq law's design step: the observer-based pipeline with the closed-loop fidelity of its float32
arithmetic as the implementation check (:func:`float32_check`, given to
:func:`gainlink.synthesis.pipeline.synthesize_lq`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...shipping.artifact import from_dict, seal
from ...synthesis.implementation import realised
from .fidelity import Float32Fidelity, float32_fidelity

if TYPE_CHECKING:
    from ...spec import PlantSpec


def float32_check(data: dict, spec: PlantSpec, warnings: list[str]) -> dict[str, Float32Fidelity | None]:
    """The float32 law's closed-loop fidelity (:func:`~gainlink.laws.lq.fidelity.float32_fidelity`) recorded in
    ``checks.float32``, with a warning naming the remedy when it is above its threshold (``float32`` of the design
    result; None when the spec switched the check off)."""
    if not spec.implementation.float32_check:
        return {"float32": None}
    kind = spec.implementation.realization
    fidelity = float32_fidelity(from_dict(seal(data)))
    data["checks"]["float32"] = fidelity.to_dict()
    if not fidelity.ok:
        better = None
        if kind == "as_designed":
            better = float32_fidelity(from_dict(seal(realised(data, "balanced")))).max_rel_u
        warnings.append(fidelity.warning(kind, balanced=better))
    return {"float32": fidelity}
