"""MAVLink parameters of a fixed-point gain set: the integers the target runs (apps/mavlink/gl_mav_fxset.h).

The MAVLink app built from a fixed-point export (``[implementation] numeric = "q31" | "q15"``) runs the integer law
(``gl_mav_law.h``) and its parameter table holds that law's integers, all INT32, in index order:

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

import struct
import zlib

from ..shipping import gains_layout as layout
from ..shipping.artifact import Artifact
from ..shipping.codegen import gain_set
from ..shipping.codegen_fixed import ROWS, is_fixed, quantise, range_keys, terms
from .params import HASH_ID, INT32, ParamSpec, as_int32, check_param_id

#: What the HEARTBEAT's custom_mode says the gainlink MAVLink app runs.
LAW_IDS = {"float32": 0, "q31": 31, "q15": 15, "scheduled-float32": 256}
SIGNATURE_ID = "GL_FX_SIG"
STRUCTURE_ID = "GL_FX_STRUCT"


def law_of(artifact: Artifact) -> str:
    """``"q31"``, ``"q15"`` or ``"float32"``: the law the MAVLink app built from ``artifact`` runs."""
    return artifact.checks["fixed_point"]["numeric"] if is_fixed(artifact) else "float32"


def law_name(custom_mode: int) -> str:
    """The law a HEARTBEAT's custom_mode names (``"law 7"`` when it is none of :data:`LAW_IDS`)."""
    return next((k for k, v in LAW_IDS.items() if v == custom_mode), f"law {custom_mode}")


def _crc_words(words: list[int]) -> int:
    return zlib.crc32(b"".join(struct.pack("<i", int(w)) for w in words))


def structure_word(artifact: Artifact) -> int:
    """``GL_FX_STRUCT`` of the image built from ``artifact`` (as an int32)."""
    fp = artifact.checks["fixed_point"]
    rows, ends = terms(artifact)
    words = [s for _, _, s in rows] + list(ends)
    ranges, frac = fp["ranges"], fp["formats"]
    keys, bounds = {}, {}
    for s in ("y", "r"):
        lo, hi = ranges.get(f"{s}_min") or [], ranges.get(f"{s}_max") or []
        pairs = [range_keys(float(a), float(b)) for a, b in zip(lo, hi, strict=True)]
        keys[s] = ([k[0] for k in pairs], [k[1] for k in pairs])
        bounds[s] = (
            [quantise(x, f) for x, f in zip(lo, frac[s], strict=True)],
            [quantise(x, f) for x, f in zip(hi, frac[s], strict=True)],
        )
    words += keys["y"][0] + keys["y"][1] + keys["r"][0] + keys["r"][1]
    words += bounds["y"][0] + bounds["y"][1] + bounds["r"][0] + bounds["r"][1]
    return as_int32(_crc_words(words))


def signature_word(artifact: Artifact) -> int:
    """``GL_FX_SIG`` of the image built from ``artifact`` (as an int32)."""
    return as_int32(int(artifact.checks["fixed_point"]["signature"], 16))


def _term_params(artifact: Artifact) -> list[ParamSpec]:
    """Mantissa and shift of each non-zero term, in the order of ``codegen_fixed.terms``."""
    table = artifact.checks["fixed_point"]["integers"]
    out = []
    for kind, count in (("v", artifact.m), ("z", artifact.q), ("x", artifact.n)):
        for i in range(count):
            for block, _ in ROWS[kind]:
                for j, (c, e) in enumerate(zip(table[block][i], table[f"{block}_shift"][i], strict=True)):
                    if c != 0:
                        out.append(ParamSpec(f"GL_{block}_{i}_{j}", INT32, int(c), f"{block}[{i},{j}]"))
                        out.append(ParamSpec(f"GL_{block}E_{i}_{j}", INT32, int(e), f"{block}_shift[{i},{j}]"))
    return out


_VECTORS = (
    ("UOPV", "UOP_V"),
    ("LOV", "LO_V"),
    ("HIV", "HI_V"),
    ("UOPU", "UOP_U"),
    ("USAFE", "U_SAFE"),
    ("YOP", "YOP"),
    ("XH0", "XH0"),
    ("Z0", "Z0"),
)


def gain_params(artifact: Artifact) -> list[ParamSpec]:
    """The integer gain parameters of ``artifact``, in index order (module docstring)."""
    table = artifact.checks["fixed_point"]["integers"]
    out = _term_params(artifact)
    for stem, key in _VECTORS:
        out += [ParamSpec(f"GL_{stem}_{i}", INT32, int(v), f"{key}[{i}]") for i, v in enumerate(table[key])]
    return out


def fixed_firmware_params(artifact: Artifact) -> tuple[ParamSpec, ...]:
    """Every parameter of the MAVLink app built from the fixed-point ``artifact``, in index order."""
    gains = gain_params(artifact)
    header = [
        ParamSpec(name=f.param, ptype=INT32, value=int(v), source=f.name)
        for f, v in zip(layout.STRUCTURE, gain_set(artifact).header, strict=True)
    ]
    header.append(ParamSpec(SIGNATURE_ID, INT32, signature_word(artifact), "checks.fixed_point.signature"))
    header.append(ParamSpec(STRUCTURE_ID, INT32, structure_word(artifact), "structure"))
    header.append(ParamSpec(HASH_ID, INT32, as_int32(_crc_words([int(s.value) for s in gains])), "crc32"))
    out = tuple(header + gains)
    for spec in out:
        check_param_id(spec.name)
    return out
