"""The MAVLink parameter table of each law: one description, from which the export renders the firmware's table
(``gl_law_params.h``, read by ``firmware/apps/mavlink/gl_mav_params.c``) and :mod:`gainlink.mavlink` plans uploads.

Each law's table, in index order: read-only structure parameters (INT32, their compiled values), ``GL_HASH`` (the
CRC-32 of the set the node runs: setting it to the staged set's CRC commits that set), then the gain values, each
with its value in the artifact and, for the C, where it lives in the law's gain set (``gl_law_gains_t`` of gl_law.h:
a C member designator). What the parameters are named and what ``GL_HASH`` covers, per law:

- ``lq/float32``: every number of the C ``gl_gains_t`` that is a parameter (:mod:`.gains_layout`), REAL32;
  ``GL_HASH`` is ``gl_gains_crc32`` (the structure words and every float).
- ``lq/q31``, ``lq/q15``: the certified integers (INT32, bytewise): each non-zero term's mantissa and left shift,
  then the operating point, limits, safe command and initial state (``VECTORS`` of
  :mod:`gainlink.laws.fixed.codegen`, which builds this table); headers ``GL_FX_SIG`` (the formats' signature) and
  ``GL_FX_STRUCT`` (its ``structure_crc``); ``GL_HASH`` is the CRC of the gain values as int32 words (its
  ``set_crc32``).
- ``scheduled/float32``: every float of the tables, REAL32; ``GL_HASH`` the CRC of their bytes.
- ``mpc/float32``: the dimensions, horizon, box rows and cap (read-only), then every float of the tables
  (``gl_mpc_tables_t``: the observer-based law's numbers, the prediction model and the per-stage gains, the boxes and
  the solver's settings), REAL32; ``GL_HASH`` the CRC of their bytes. The horizon and cap are in the law's
  compatibility signature: a set for another horizon is refused.

The fixed-point table (``lq/q31``, ``lq/q15``), all INT32, in index order:

=============================================  ====================================================================
id                                             meaning
=============================================  ====================================================================
``GL_DIM_N .. GL_AW``                          compiled structure, as the float table's (read-only)
``GL_FX_SIG``                                  ``checks.fixed_point.signature`` (8 hex digits as a 32-bit word):
                                               the number formats compiled into the law (read-only)
``GL_FX_STRUCT``                               CRC-32 of the rest compiled in: each term's signal, each row's end,
                                               the declared ranges' clip keys and quantised bounds (read-only)
``GL_HASH``                                    CRC-32 of the values below as little-endian int32 words; setting it
                                               commits the staged values (checked, swapped between two steps)
``GL_<B>_i_j GL_<B>E_i_j``                     each non-zero term of the sums: mantissa and left shift of block
                                               ``B`` (KX KY KZ, TR TY KAW, F G LY) row ``i``, column ``j``
``GL_UOPV_i GL_LOV_i GL_HIV_i``                operating point and limits of the unsaturated command (v formats)
``GL_UOPU_i GL_USAFE_i GL_YOP_i``              operating point and safe command (command formats), y_op
``GL_XH0_i GL_Z0_i``                           initial estimate and integrators
=============================================  ====================================================================

The HEARTBEAT's ``custom_mode`` names the law the target runs (``GL_LAW_ID``, :data:`.law_c.IDS`), so a float
upload to a fixed-point target, or a q15 set to a q31 one, is refused before anything is read; a set whose formats
(``GL_FX_SIG``) or structure (``GL_FX_STRUCT``) differ from the image's is refused before anything is written.

The scheduled table (``scheduled/float32``), in index order:

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

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..registry import LawTable
from . import gains_layout as layout
from .artifact import Artifact
from .codegen import gain_set, shape_of
from .law_c import law_name

#: MAV_PARAM_TYPE of the table's parameters (MAVLink common.xml).
INT32 = 6
REAL32 = 9
HASH_ID = "GL_HASH"
SIGNATURE_ID = "GL_FX_SIG"
STRUCTURE_ID = "GL_FX_STRUCT"


@dataclass(frozen=True)
class Param:
    """One parameter of a law's table.

    ``value`` is the artifact's (an INT32 as the signed 32-bit integer it carries); ``source`` says where it comes
    from (``K[0,1]``); ``slot`` is the C designator of a gain value in ``gl_law_gains_t`` (empty for a header); a
    header is read-only but for ``GL_HASH`` (``is_hash``).
    """

    name: str
    ptype: int
    value: float | int
    source: str
    slot: str = ""
    is_hash: bool = False


def as_int32(value: int) -> int:
    """A uint32 (a CRC) as the int32 an INT32 parameter holds."""
    value &= 0xFFFFFFFF
    return value - (1 << 32) if value >= 1 << 31 else value


def table(artifact: Artifact) -> tuple[Param, ...]:
    """Every parameter of the MAVLink node built from ``artifact``, in index order (module docstring)."""
    return TABLES[law_name(artifact)](artifact)


def structure_params(artifact: Artifact) -> list[Param]:
    """The lq structure's read-only parameters (dimensions, observer form, anti-windup)."""
    header = gain_set(artifact).header
    return [Param(f.param, INT32, int(v), f.name) for f, v in zip(layout.STRUCTURE, header, strict=True)]


def _block(field: layout.Field, values: np.ndarray, shape: layout.Shape) -> list[Param]:
    if not field.dims:
        return [Param(f"GL_{field.param}", REAL32, float(values), field.name, slot=field.name)]
    exposed = field.exposed_shape(shape)  # integrator arrays are stored with max(q, 1) rows or columns
    if len(field.dims) == 1:
        return [
            Param(f"GL_{field.param}_{i}", REAL32, float(values[i]), f"{field.name}[{i}]", slot=f"{field.name}[{i}]")
            for i in range(exposed[0])
        ]
    return [
        Param(
            f"GL_{field.param}_{i}_{j}",
            REAL32,
            float(values[i, j]),
            f"{field.name}[{i},{j}]",
            slot=f"{field.name}[{i}][{j}]",
        )
        for i in range(exposed[0])
        for j in range(exposed[1])
    ]


def lq_table(artifact: Artifact) -> tuple[Param, ...]:
    """The lq/float32 law's table: the structure, ``GL_HASH`` and every parameter of ``gl_gains_t``."""
    gs, shape = gain_set(artifact), shape_of(artifact)
    out = structure_params(artifact) + [Param(HASH_ID, INT32, as_int32(gs.crc32), "crc32", is_hash=True)]
    for field in layout.NUMBERS:
        if field.param:
            out += _block(field, np.asarray(gs.fields[field.name]), shape)
    return tuple(out)


#: Each law's table (module docstring), ``artifact -> tuple[Param, ...]``: the registry the export and the upload ask,
#: registered by the law families (:mod:`gainlink.registry`; the lq/float32 table is :func:`lq_table`).
TABLES: LawTable[Callable[[Artifact], tuple[Param, ...]]] = LawTable("parameter table")


def c_header(artifact: Artifact, *, banner: str) -> str:
    """Text of ``gl_law_params.h``: the table as ``GL_LAW_PARAMS(HEADER, HASH, GAIN)``, one entry per parameter in
    index order (``HEADER(id, type, bits)`` a read-only constant, ``HASH(id)``, ``GAIN(id, type, designator)``)."""
    params = table(artifact)
    entries = []
    for p in params:
        if p.is_hash:
            entries.append(f'    HASH("{p.name}")')
        elif not p.slot:
            entries.append(f'    HEADER("{p.name}", {p.ptype}, 0x{int(p.value) & 0xFFFFFFFF:08x}u)')
        else:
            entries.append(f'    GAIN("{p.name}", {p.ptype}, {p.slot})')
    return "\n".join(
        [
            banner.rstrip("\n"),
            "/**",
            " * @file gl_law_params.h",
            f" * @brief The MAVLink parameter table of the {law_name(artifact)} law for this build, in index order",
            " *        (gainlink.shipping.params: the one description the uploader reads too).",
            " */",
            "#ifndef GL_LAW_PARAMS_H",
            "#define GL_LAW_PARAMS_H",
            "",
            f"#define GL_LAW_PARAM_COUNT {len(params)}",
            f"#define GL_LAW_HEADER_COUNT {sum(1 for p in params if not p.slot)}",
            "/** Every parameter: HEADER(id, MAV_PARAM_TYPE, value bits), HASH(id) or GAIN(id, MAV_PARAM_TYPE, member",
            " *  of gl_law_gains_t). */",
            "#define GL_LAW_PARAMS(HEADER, HASH, GAIN) \\",
            " \\\n".join(entries),
            "",
            "#endif /* GL_LAW_PARAMS_H */",
            "",
        ]
    )
