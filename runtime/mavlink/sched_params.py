"""MAVLink parameters of a scheduled gain set: every float of the tables the scheduled law runs
(``firmware/apps/mavlink/gl_mav_schedparams.c``), in index order:

=====================================================  ==============================================================
id                                                     meaning
=====================================================  ==============================================================
``GL_DIM_N GL_DIM_M GL_DIM_P GL_DIM_Q GL_NPTS``        compiled structure: dimensions, points, external signals
``GL_DIM_E`` (INT32, read-only)
``GL_HASH`` (INT32)                                    CRC-32 of the tables' bytes (``gl_sched_tables_t``, float32);
                                                       setting it commits every staged value at once (checked by the
                                                       loop's own ``gl_sched_init``), or nothing
``GL_S_k``                                             the points
``GL_<B>_k_i_j``, B one of KX KY KZ F G LY             point k's coefficients (each block for every point in turn)
``GL_UOP_k_i``                                         point k's trim (start and safe command)
``GL_UMIN_i GL_UMAX_i GL_CI_i_j GL_ALPHA GL_RATE``     limits, tracked outputs, sigma's filter gain and step limit
=====================================================  ==============================================================

All REAL32 but the header. The HEARTBEAT's ``custom_mode`` of the scheduled app is 256 (``scheduled-float32``).
"""

from __future__ import annotations

import zlib

import numpy as np

from ..shipping.artifact import Artifact
from ..shipping.codegen_scheduled import tables
from .params import HASH_ID, INT32, REAL32, ParamSpec, as_int32, check_param_id

#: The law the scheduled MAVLink app runs (its HEARTBEAT custom_mode is 256).
LAW = "scheduled-float32"
#: The read-only structure parameters of the scheduled table.
DIMENSION_IDS = ("GL_DIM_N", "GL_DIM_M", "GL_DIM_P", "GL_DIM_Q", "GL_NPTS", "GL_DIM_E")
#: Each field of gl_sched_tables_t: its id stem and whether it holds one block per point.
_STEMS = {
    "S": ("S", False), "Kx": ("KX", True), "Ky": ("KY", True), "Kz": ("KZ", True), "F": ("F", True),
    "G": ("G", True), "Ly": ("LY", True), "u_op": ("UOP", True), "u_min": ("UMIN", False),
    "u_max": ("UMAX", False), "Ci": ("CI", False), "alpha": ("ALPHA", False), "rate_step": ("RATE", False),
}  # fmt: skip


def _shapes(a: Artifact) -> dict[str, tuple[int, ...]]:
    """Each field's shape per point (empty: a scalar; one number: a vector)."""
    n, m, p, q = a.n, a.m, a.p, a.q
    mats = {"Kx": (m, n), "Ky": (m, p), "Kz": (m, q), "F": (n, n), "G": (n, m), "Ly": (n, p), "Ci": (q, p)}
    return {**mats, "S": (a.schedule.points.size,), "u_op": (m,), "u_min": (m,), "u_max": (m,), "alpha": (),
            "rate_step": ()}  # fmt: skip


def _names(stem: str, point: int | None, shape: tuple[int, ...]) -> list[str]:
    base = f"GL_{stem}" + ("" if point is None else f"_{point}")
    if not shape:
        return [base]
    if len(shape) == 1:
        return [f"{base}_{i}" for i in range(shape[0])]
    return [f"{base}_{i}_{j}" for i in range(shape[0]) for j in range(shape[1])]


def table_hash(artifact: Artifact) -> int:
    """``GL_HASH`` of the scheduled app built from ``artifact``: the CRC-32 of its tables' bytes (as an int32)."""
    blob = b"".join(np.asarray(v, dtype="<f4").tobytes() for v in tables(artifact).values())
    return as_int32(zlib.crc32(blob))


def scheduled_firmware_params(artifact: Artifact) -> tuple[ParamSpec, ...]:
    """Every parameter of the scheduled MAVLink app built for ``artifact``, in index order (module docstring)."""
    a = artifact
    dims = (a.n, a.m, a.p, a.q, a.schedule.points.size, len(a.schedule.external))
    out = [ParamSpec(k, INT32, int(v), "structure") for k, v in zip(DIMENSION_IDS, dims, strict=True)]
    out.append(ParamSpec(HASH_ID, INT32, table_hash(a), "CRC-32 of the tables"))
    shapes = _shapes(a)
    for field, values in tables(a).items():
        stem, per_point = _STEMS[field]
        flat = np.asarray(values, dtype=np.float32).reshape(-1)
        points = range(a.schedule.points.size) if per_point else [None]
        names = [name for k in points for name in _names(stem, k, shapes[field])]
        for name, v in zip(names, flat, strict=True):
            check_param_id(name)
            out.append(ParamSpec(name, REAL32, float(v), field))
    return tuple(out)
