"""The fixed-point law's design step: the observer-based pipeline with the certificate of its integer arithmetic as
the implementation check (:func:`fixed_point_check`, given to :func:`gainlink.synthesis.pipeline.synthesize_lq`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...shipping.artifact import from_dict, seal
from .certificate import FixedPointCertificate, certificate_dict, certify
from .fidelity import fixed_point_fidelity

if TYPE_CHECKING:
    from ...spec import PlantSpec


def fixed_point_check(data: dict, spec: PlantSpec, warnings: list[str]) -> dict[str, FixedPointCertificate]:
    """Certify the fixed-point law for the spec's declared ranges, record it in ``checks.fixed_point`` with the
    measured closed-loop deviation (``fixed_point`` of the design result)."""
    impl, lim = spec.implementation, spec.limits
    ranges = {"y_min": lim.y_min, "y_max": lim.y_max, "r_min": lim.r_min, "r_max": lim.r_max}
    cert = certify(from_dict(seal(data)), ranges, numeric=impl.numeric, max_error=impl.fixed_point_max_error)
    data["checks"]["fixed_point"] = certificate_dict(cert)
    measured = fixed_point_fidelity(from_dict(seal(data)))
    data["checks"]["fixed_point"]["measured"] = measured.to_dict()
    return {"fixed_point": cert}
