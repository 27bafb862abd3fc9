"""The declared ranges of samples and references (``[limits] y_min/y_max``, ``r_min/r_max``) and what a
fixed-point law requires of a spec: ranges for every sample and reference, each containing the operating point,
and an anti-windup mode whose integrator can be bounded."""

from __future__ import annotations

import numpy as np

from ..errors import SpecError
from .model import ImplementationSpec, LimitsSpec, OperatingPoint, PlantModel
from .pairs import integer
from .values import as_vector

NUMERIC = ("float32", "q31", "q15")


def parse_ranges(tbl: dict, plant: PlantModel, *, q: int) -> dict:
    """``y_min``/``y_max`` (p values each) and ``r_min``/``r_max`` (q values each): both or neither of a pair,
    the lower below the upper; returns the keyword arguments of :class:`LimitsSpec` (None when absent)."""
    out = {}
    for lo_key, hi_key, size, what in (("y_min", "y_max", plant.p, "output"), ("r_min", "r_max", q, "reference")):
        if (lo_key in tbl) != (hi_key in tbl):
            given, missing = (lo_key, hi_key) if lo_key in tbl else (hi_key, lo_key)
            raise SpecError(f"limits.{given} is given without limits.{missing}")
        if lo_key not in tbl:
            out[lo_key] = out[hi_key] = None
            continue
        if size == 0:
            raise SpecError(f"limits.{lo_key}/{hi_key} range the references, but there is no [integral] table")
        lo = as_vector(tbl[lo_key], f"limits.{lo_key}", size)
        hi = as_vector(tbl[hi_key], f"limits.{hi_key}", size)
        bad = np.flatnonzero(lo >= hi)
        if bad.size:
            raise SpecError(f"limits.{lo_key} must be below limits.{hi_key} for every {what} (not for entry {bad[0]})")
        out[lo_key], out[hi_key] = lo, hi
    return out


def check_ranges(
    limits: LimitsSpec,
    op: OperatingPoint | None,
    Ci: np.ndarray,
    plant: PlantModel,
    implementation: ImplementationSpec,
) -> None:
    """Refuse a range that excludes the operating point, and a fixed-point spec without ranges or with an
    integrator that cannot be bounded (``anti_windup = "none"``)."""
    y_op = np.zeros(plant.p) if op is None else op.y_op
    _contains("y", limits.y_min, limits.y_max, y_op, plant.outputs)
    references = [f"r_{plant.outputs[int(np.argmax(row))]}" for row in Ci]
    _contains("r", limits.r_min, limits.r_max, Ci @ y_op, references)
    if not integer(implementation.numeric):
        return
    numeric = f'numeric = "{implementation.numeric}"'
    if limits.y_min is None:
        raise SpecError(
            f"{numeric} needs the samples' ranges: limits.y_min and limits.y_max (one value per output), "
            "which bound every variable of the fixed-point law"
        )
    if Ci.shape[0] and limits.r_min is None:
        raise SpecError(
            f"{numeric} needs the references' ranges: limits.r_min and limits.r_max (one value per tracked output)"
        )
    if Ci.shape[0] and limits.anti_windup == "none":
        raise SpecError(
            f'{numeric} cannot bound the integrator with anti_windup = "none" (it winds up without limit while '
            'the command saturates): use "clamp" or "backcalc"'
        )


def _contains(kind: str, lo, hi, op: np.ndarray, names) -> None:
    if lo is None:
        return
    outside = np.flatnonzero((op < lo) | (op > hi))
    if outside.size:
        i = outside[0]
        where = "operating point y_op" if kind == "y" else "reference at the operating point (Ci y_op)"
        raise SpecError(
            f"limits.{kind}_min/{kind}_max for {names[i]} is [{lo[i]:g}, {hi[i]:g}], which excludes the {where}, "
            f"{op[i]:g}"
        )


def parse_numeric(tbl: dict) -> dict:
    """``numeric`` and ``fixed_point_max_error`` of ``[implementation]``, as keyword arguments."""
    out = {}
    numeric = tbl.get("numeric", "float32")
    if numeric not in NUMERIC:
        raise SpecError(f"implementation.numeric must be one of {', '.join(NUMERIC)}, not {numeric!r}")
    out["numeric"] = numeric
    if "fixed_point_max_error" in tbl:
        value = tbl["fixed_point_max_error"]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < 1:
            raise SpecError(
                "implementation.fixed_point_max_error is a fraction of each input's limit span, in (0, 1); "
                f"got {value!r}"
            )
        out["fixed_point_max_error"] = float(value)
    return out
