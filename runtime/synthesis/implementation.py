"""The spec's ``[implementation]`` choices applied to a designed artifact: the realisation of the estimate, then
the compensator's stability and the float32 closed-loop fidelity (or, for a fixed-point law, its certificate and
measured fidelity) recorded in ``checks`` with their warnings."""

from __future__ import annotations

from ..proof.fidelity import Float32Fidelity, float32_fidelity
from ..proof.fixed_fidelity import fixed_point_fidelity
from ..shipping.artifact import Artifact, from_dict, seal
from ..spec import ImplementationSpec
from .compensator import CompensatorStability, compensator_stability
from .fixed_point import FixedPointCertificate, certificate_dict, certify
from .realization import apply, transformation


def implement(
    data: dict, implementation: ImplementationSpec, warnings: list[str], *, ranges: dict | None = None
) -> tuple[dict, CompensatorStability, Float32Fidelity | None, FixedPointCertificate | None]:
    """Apply the implementation choices to a designed artifact dict and record their checks.

    Returns ``(data, compensator stability, float32 fidelity or None when the check is off or the law is fixed
    point, fixed-point certificate or None)``; ``data`` is not sealed. ``ranges`` (y_min, y_max, r_min, r_max)
    are the declared ranges a fixed-point law is certified for.
    """
    kind = implementation.realization
    if kind != "as_designed":
        data = _realised(data, kind)
    data = dict(data, checks=dict(data["checks"]))
    a = from_dict(seal(data))
    compensator = compensator_stability(a)
    data["checks"]["compensator"] = compensator.to_dict()
    if not compensator.stable:
        warnings.append(compensator.warning())
    if implementation.fixed_point:
        return (data, compensator, None, _fixed_point(data, a, implementation, ranges or {}))
    fidelity = None
    if implementation.float32_check:
        fidelity = float32_fidelity(a)
        data["checks"]["float32"] = fidelity.to_dict()
        if not fidelity.ok:
            better = None
            if kind == "as_designed":
                better = float32_fidelity(from_dict(seal(_realised(data, "balanced")))).max_rel_u
            warnings.append(fidelity.warning(kind, balanced=better))
    return data, compensator, fidelity, None


def _fixed_point(data: dict, a: Artifact, implementation: ImplementationSpec, ranges: dict) -> FixedPointCertificate:
    """Certify the fixed-point law, record it in ``checks.fixed_point`` with the measured closed-loop deviation."""
    cert = certify(a, ranges, numeric=implementation.numeric, max_error=implementation.fixed_point_max_error)
    data["checks"]["fixed_point"] = certificate_dict(cert)
    measured = fixed_point_fidelity(from_dict(seal(data)))
    data["checks"]["fixed_point"]["measured"] = measured.to_dict()
    return cert


def _realised(data: dict, kind: str) -> dict:
    """``data`` with the estimate in the realisation ``kind`` (from the design's coordinates)."""
    a: Artifact = from_dict(seal(data))
    T = transformation(kind, Ad=a.Ad, Bd=a.Bd, Cd=a.Cd, Dd=a.Dd, K=a.K, L=a.L, M=a.M, form=a.observer_form)
    return apply(data, kind=kind, T=T)
