"""``[mpc]``: the constrained law's horizon, solver settings and soft boxes (docs/design.md, "MPC (the fourth law)").

A spec asks for the MPC law with ``[controller] method = "mpc"`` (weights as for ``lqr``) and holds an ``[mpc]``
table::

    [mpc]
    horizon = 20                  # N: moves u0..u(N-1), states x1..xN, terminal cost on xN
    max_iter = 10                 # the ADMM iteration cap (a step's cost is bounded by it)
    rho = 3.0                     # optional: the input slacks' penalty (default 3 mean(diag R))
    rho_state = 3000.0            # optional: the state boxes' penalty (default 1000 rho)
    tol = 1e-3                    # stopping tolerance, relative to each constrained signal's scale
    boxes = { x_dot = [-1.5, 1.5] }   # soft boxes, absolute, on states or outputs by name
    box_weight = 1e6              # optional: the boxes' quadratic penalty (default 1e4 max(diag Q))

A name that is both a state and an output (the pendulum's ``x``) boxes the state. Not with a ``[schedule]``, a
fixed-point ``numeric`` or another realisation than ``as_designed`` (the boxes are in the design's coordinates).

The spec's parser reads the table through ``gainlink.spec.parse.BLOCKS["mpc"]`` (:func:`parse_mpc`) and checks
``[implementation]`` through ``parse.CHECKS["mpc"]`` (:func:`check_implementation`), both registered by this family.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...errors import SpecError, did_you_mean
from ...spec.model import ImplementationSpec, MpcBox, MpcSpec, OperatingPoint, PlantModel
from ...spec.pairs import integer
from ...spec.values import no_unknown, positive_number

MPC_KEYS = {"horizon", "max_iter", "rho", "rho_state", "tol", "boxes", "box_weight"}
#: Largest horizon and cap a spec may ask for (the C's workspace is static: a typo of 2000 would not fit anywhere).
MAX_HORIZON = 200
MAX_ITER = 10000


def _count(tbl: dict, key: str, default: int | None, largest: int) -> int:
    """An integer ``>= 1`` and ``<= largest`` (``default`` when absent; required when None)."""
    value = tbl.get(key, default)
    if value is None:
        raise SpecError(f"mpc.{key} is required (an integer >= 1)")
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= largest:
        raise SpecError(f"mpc.{key} must be an integer from 1 to {largest}, got {value!r}")
    return int(value)


def _optional_positive(tbl: dict, key: str) -> float | None:
    return None if key not in tbl else positive_number(tbl[key], f"mpc.{key}")


def parse_mpc(tbl: dict | None, *, method: str, plant: PlantModel, op: OperatingPoint | None) -> MpcSpec | None:
    """The ``[mpc]`` table of a spec whose controller method is ``method`` (module docstring); None without one."""
    if method != "mpc":
        if tbl is not None:
            raise SpecError(f'an [mpc] table needs [controller] method = "mpc" (the method is {method!r})')
        return None
    if tbl is None:
        raise SpecError('[controller] method = "mpc" needs an [mpc] table with its horizon')
    no_unknown(tbl, MPC_KEYS, "mpc")
    tol = positive_number(tbl.get("tol", 1e-3), "mpc.tol")
    if tol >= 1.0:
        raise SpecError(f"mpc.tol is relative to each constrained signal's scale and must be below 1, got {tol:g}")
    boxes = tbl.get("boxes", {})
    if not isinstance(boxes, dict):
        raise SpecError("mpc.boxes must be a table { name = [min, max], ... } of states or outputs")
    return MpcSpec(
        horizon=_count(tbl, "horizon", None, MAX_HORIZON),
        max_iter=_count(tbl, "max_iter", 10, MAX_ITER),
        rho=_optional_positive(tbl, "rho"),
        rho_state=_optional_positive(tbl, "rho_state"),
        tol=tol,
        boxes=tuple(_box(name, bounds, plant, op) for name, bounds in boxes.items()),
        box_weight=_optional_positive(tbl, "box_weight"),
    )


def _box(name: str, bounds: Any, plant: PlantModel, op: OperatingPoint | None) -> MpcBox:
    """One soft box, checked: a state or output name, ``[min, max]`` with ``min < max`` (``-inf``/``inf`` allowed
    for one side), the operating point inside it."""
    if name in plant.states:
        kind, index = "state", plant.states.index(name)
        at = 0.0 if op is None or op.x_op is None else float(op.x_op[index])
    elif name in plant.outputs:
        kind, index = "output", plant.outputs.index(name)
        at = 0.0 if op is None else float(op.y_op[index])
    else:
        known = (*plant.states, *plant.outputs)
        raise SpecError(f"mpc.boxes names {name!r}, which is not a state or output{did_you_mean(name, known)}")
    if not isinstance(bounds, list) or len(bounds) != 2 or any(isinstance(b, bool) or not isinstance(b, (int, float))
                                                               for b in bounds):  # fmt: skip
        raise SpecError(f"mpc.boxes.{name} must be [min, max], got {bounds!r}")
    lo, hi = float(bounds[0]), float(bounds[1])
    if math.isnan(lo) or math.isnan(hi) or not lo < hi or (math.isinf(lo) and math.isinf(hi)):
        raise SpecError(f"mpc.boxes.{name} must have min < max and at least one finite bound, got [{lo:g}, {hi:g}]")
    if not lo <= at <= hi:
        raise SpecError(
            f"mpc.boxes.{name} [{lo:g}, {hi:g}] excludes the operating point ({name} = {at:g} there): the law could "
            "not rest at its trim inside the box"
        )
    return MpcBox(name=name, kind=kind, index=index, lo=lo, hi=hi)


def check_mpc_spec(*, numeric: str, realization: str) -> None:
    """What the MPC law cannot be combined with in this version, refused in one line each (a ``[schedule]``: at the
    top of :func:`gainlink.spec.parse.parse_spec`, before the points are read)."""
    if integer(numeric):
        raise SpecError(
            f"implementation.numeric {numeric!r} is not available for the MPC law in this version (float32 only)"
        )
    if realization != "as_designed":
        raise SpecError(
            f"implementation.realization {realization!r} cannot carry an MPC law: its prediction model and boxes "
            "are in the design's coordinates (use as_designed)"
        )


def weights_default(Q: np.ndarray, R: np.ndarray, mpc: MpcSpec) -> tuple[float, float, float]:
    """``rho``, ``rho_state`` and ``box_weight`` with the default rules applied where the spec gave none."""
    rho = mpc.rho if mpc.rho is not None else 3.0 * float(np.mean(np.diag(R)))
    rho_state = mpc.rho_state if mpc.rho_state is not None else 1000.0 * rho
    box_weight = mpc.box_weight if mpc.box_weight is not None else 1e4 * float(np.max(np.diag(Q)))
    return rho, rho_state, box_weight


def check_implementation(implementation: ImplementationSpec) -> None:
    """:func:`check_mpc_spec` of a spec's ``[implementation]``."""
    check_mpc_spec(numeric=implementation.numeric, realization=implementation.realization)
