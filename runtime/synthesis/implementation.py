"""The spec's ``[implementation]`` choices applied to a designed artifact: the realisation of the estimate and the
compensator's stability (:func:`realise`, every observer-based law), then the law's own check of its arithmetic,
recorded in ``checks`` with its warnings, is the law's own: the float32 closed-loop fidelity
(:func:`gainlink.laws.lq.design.float32_check`), a fixed-point law's certificate
(:func:`gainlink.laws.fixed.design.fixed_point_check`)."""

from __future__ import annotations

from ..shipping.artifact import Artifact, from_dict, seal
from ..spec import ImplementationSpec
from .compensator import CompensatorStability, compensator_stability
from .realization import apply, transformation


def realise(data: dict, implementation: ImplementationSpec, warnings: list[str]) -> tuple[dict, CompensatorStability]:
    """The estimate in the spec's realisation, and the compensator's stability recorded in ``checks.compensator``
    (with its warning). Returns ``(data, compensator stability)``; ``data`` is not sealed."""
    kind = implementation.realization
    if kind != "as_designed":
        data = realised(data, kind)
    data = dict(data, checks=dict(data["checks"]))
    compensator = compensator_stability(from_dict(seal(data)))
    data["checks"]["compensator"] = compensator.to_dict()
    if not compensator.stable:
        warnings.append(compensator.warning())
    return data, compensator


def realised(data: dict, kind: str) -> dict:
    """``data`` with the estimate in the realisation ``kind`` (from the design's coordinates)."""
    a: Artifact = from_dict(seal(data))
    T = transformation(kind, Ad=a.Ad, Bd=a.Bd, Cd=a.Cd, Dd=a.Dd, K=a.K, L=a.L, M=a.M, form=a.observer_form)
    return apply(data, kind=kind, T=T)
