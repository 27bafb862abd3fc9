"""MAVLink parameters of a fixed-point gain set: the integers the target runs (gainlink.shipping.params).

The MAVLink app built from a fixed-point export (``[implementation] numeric = "q31" | "q15"``) runs the integer law
(``gl_law.h``) and its parameter table holds that law's integers, all INT32, in index order:

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

The HEARTBEAT's ``custom_mode`` names the law the target runs (:data:`LAW_IDS`), so a float upload to a fixed-point
target, or a q15 set to a q31 one, is refused before anything is read; a set whose formats (``GL_FX_SIG``) or
structure (``GL_FX_STRUCT``) differ from the image's is refused before anything is written.
"""

from __future__ import annotations

from ..shipping import params as law_params
from ..shipping.artifact import Artifact
from ..shipping.codegen_fixed import is_fixed
from ..shipping.law_c import IDS, LABELS
from .params import ParamSpec, firmware_params

#: What the HEARTBEAT's custom_mode says the gainlink MAVLink app runs (GL_LAW_ID of gl_law.h).
LAW_IDS = {LABELS[law]: IDS[law] for law in IDS}
SIGNATURE_ID = law_params.SIGNATURE_ID
STRUCTURE_ID = law_params.STRUCTURE_ID


def law_name(custom_mode: int) -> str:
    """The law a HEARTBEAT's custom_mode names (``"law 7"`` when it is none of :data:`LAW_IDS`)."""
    return next((k for k, v in LAW_IDS.items() if v == custom_mode), f"law {custom_mode}")


def fixed_firmware_params(artifact: Artifact) -> tuple[ParamSpec, ...]:
    """Every parameter of the MAVLink app built from the fixed-point ``artifact``, in index order (the integer law's
    table: :func:`gainlink.shipping.params.table`)."""
    if not is_fixed(artifact):
        raise ValueError(f"artifact {artifact.name} is not a fixed-point design")
    return firmware_params(artifact)
