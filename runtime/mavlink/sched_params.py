"""MAVLink parameters of a scheduled gain set: every float of the tables the scheduled law runs
(``firmware/apps/mavlink/gl_mav_params.c`` on the table gainlink.shipping.params describes), in index order:

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

from ..shipping import params as law_params
from ..shipping.artifact import Artifact
from ..shipping.codegen_scheduled import tables_crc32
from .params import ParamSpec, as_int32, firmware_params

#: The law the scheduled MAVLink app runs (its HEARTBEAT custom_mode is 256).
LAW = "scheduled-float32"
#: The read-only structure parameters of the scheduled table.
DIMENSION_IDS = law_params.SCHEDULED_DIMENSION_IDS


def table_hash(artifact: Artifact) -> int:
    """``GL_HASH`` of the scheduled app built from ``artifact``: the CRC-32 of its tables' bytes (as an int32)."""
    return as_int32(tables_crc32(artifact))


def scheduled_firmware_params(artifact: Artifact) -> tuple[ParamSpec, ...]:
    """Every parameter of the scheduled MAVLink app built for ``artifact``, in index order (the scheduled law's
    table: :func:`gainlink.shipping.params.table`; module docstring)."""
    if artifact.schedule is None:
        raise ValueError(f"artifact {artifact.name} is not scheduled")
    return firmware_params(artifact)
