"""C code generation for a fixed-point artifact: the certified integers as ``gl_fixed_gains.h`` / ``.c``.

A fixed-point artifact (``checks.fixed_point`` present, ``[implementation] numeric = "q31" | "q15"``) carries
the integers its certificate covers (``checks.fixed_point.integers``, with the formats and declared ranges). The
C of ``firmware/src/gl_fixed.c`` runs them; this module lays them out as its const ``gl_fixed_gains_t``
(``firmware/include/gainlink/gl_fixed.h``): each sum's non-zero coefficients row by row (mantissa, left shift,
the signal it multiplies), the rounding shifts, operating point, limits, safe command and initial state, the
fractional bits of samples and commands, and the declared ranges as the order keys and quantised values the
step clips with. The integers are taken as stored, never recomputed (docs/design.md, "Fixed point"); the only
values formed here are those of the ranges (their quantisation is the model's, ``floor(x 2**f + 1/2)``) and
the powers of two that turn a command word into a float.

The export asks :func:`render_export` and the MAVLink upload :func:`param_table`, through the tables this family
registers them in (``gainlink.shipping.export_c.RENDERINGS``, ``gainlink.shipping.params.TABLES``).
"""

from __future__ import annotations

import math
import struct
import zlib

import numpy as np

from ...errors import ArtifactError
from ...shipping import codegen
from ...shipping.artifact import Artifact
from ...shipping.law_c import require_law
from ...shipping.params import HASH_ID, INT32, SIGNATURE_ID, STRUCTURE_ID, Param, as_int32, structure_params

#: The laws whose export this module renders (the lq structure on integers).
INTEGER_LAWS = ("lq/q31", "lq/q15")
HEADER_NAME = "gl_fixed_gains.h"
SOURCE_NAME = "gl_fixed_gains.c"
STEP_NAME = "gl_fixed_step.h"
COEFFICIENT_BITS = {"q31": 32, "q15": 16}
ANTI_WINDUP_CODES = {"none": 0, "clamp": 1, "backcalc": 2}

# each row's blocks in the order of laws.fixed.model: (block, signal group); signal groups as in gl_fixed.h
ROWS = {
    "v": (("KX", "XH"), ("KY", "DY"), ("KZ", "Z")),
    "z": (("TR", "R"), ("TY", "Y"), ("KAW", "W")),
    "x": (("F", "XH"), ("G", "DU"), ("LY", "DY")),
}


def _offsets(n: int, m: int, p: int, q: int) -> dict[str, int]:
    """Where each signal group starts in ``gl_fixed_loop_t::sig`` (GL_FX_SIG_* of gl_fixed.h)."""
    sizes = (("XH", n), ("DY", p), ("Z", q), ("DU", m), ("R", q), ("Y", p), ("W", m))
    out, pos = {}, 0
    for name, size in sizes:
        out[name], pos = pos, pos + size
    return out


def terms(artifact: Artifact) -> tuple[list[tuple[int, int, int]], list[int]]:
    """The sums' non-zero terms ``(mantissa, shift, signal index)`` row by row (the m commands, q integrators,
    n estimates) and each row's end, from the artifact's stored integers."""
    a, table = artifact, artifact.checks["fixed_point"]["integers"]
    off = _offsets(a.n, a.m, a.p, a.q)
    out: list[tuple[int, int, int]] = []
    ends: list[int] = []
    for kind, rows in (("v", a.m), ("z", a.q), ("x", a.n)):
        for i in range(rows):
            for block, group in ROWS[kind]:
                for k, (c, e) in enumerate(zip(table[block][i], table[f"{block}_shift"][i], strict=True)):
                    if c != 0:
                        out.append((int(c), int(e), off[group] + k))
            ends.append(len(out))
    return out, ends


def float_key(x: float) -> int:
    """The order key gl_fixed_key() gives a float32 ``x``: its magnitude bits, negated for a negative sign."""
    bits = struct.unpack("<I", struct.pack("<f", x))[0]
    mag = bits & 0x7FFFFFFF
    return -mag if bits >> 31 else mag


def range_keys(lo: float, hi: float) -> tuple[int, int]:
    """Keys of the least float32 >= ``lo`` and the greatest <= ``hi``: a float y is below ``lo`` exactly when
    its key is below the first (and above ``hi`` when above the second)."""
    flo, fhi = np.float32(lo), np.float32(hi)
    if float(flo) < lo:
        flo = np.nextafter(flo, np.float32(np.inf))
    if float(fhi) > hi:
        fhi = np.nextafter(fhi, np.float32(-np.inf))
    return float_key(float(flo)), float_key(float(fhi))


def quantise(x: float, frac: int) -> int:
    """``floor(x 2**frac + 1/2)``, exactly (as gainlink.laws.fixed.qformat.quantise)."""
    s = math.ldexp(float(x), int(frac))
    q = math.floor(s)
    return q + (1 if s - q >= 0.5 else 0)


def _check(artifact: Artifact, numeric: str, rows: list[tuple[int, int, int]]) -> None:
    """Refuse, in one line, integers that the C's types cannot hold."""
    word = COEFFICIENT_BITS.get(numeric)
    if word is None:
        raise ArtifactError(f"artifact {artifact.name}: checks.fixed_point.numeric {numeric!r} is not q31 or q15")
    bad = [c for c, e, _ in rows if not -(1 << (word - 1)) <= c < (1 << (word - 1)) or not 0 <= e < 64]
    if bad:
        raise ArtifactError(f"artifact {artifact.name}: a mantissa or shift does not fit the {numeric} C types")


def _ranges(artifact: Artifact, fp: dict) -> dict[str, list]:
    """The clip keys and quantised bounds of the samples (and references)."""
    frac, ranges = fp["formats"], fp["ranges"]
    out: dict[str, list] = {}
    for s, count in (("y", artifact.p), ("r", artifact.q)):
        lo, hi = ranges.get(f"{s}_min") or [], ranges.get(f"{s}_max") or []
        if len(lo) != count or len(hi) != count:
            raise ArtifactError(f"artifact {artifact.name}: checks.fixed_point.ranges lacks {s}_min/{s}_max")
        keys = [range_keys(float(a), float(b)) for a, b in zip(lo, hi, strict=True)]
        out[f"key_{s}_lo"], out[f"key_{s}_hi"] = [k[0] for k in keys], [k[1] for k in keys]
        out[f"{s}_lo"] = [quantise(x, f) for x, f in zip(lo, frac[s], strict=True)]
        out[f"{s}_hi"] = [quantise(x, f) for x, f in zip(hi, frac[s], strict=True)]
    return out


#: The integer vectors of a set after its terms, in the order of the MAVLink table and of gl_fixed_set_crc32():
#: (parameter stem, key of ``checks.fixed_point.integers``).
VECTORS = (
    ("UOPV", "UOP_V"),
    ("LOV", "LO_V"),
    ("HIV", "HI_V"),
    ("UOPU", "UOP_U"),
    ("USAFE", "U_SAFE"),
    ("YOP", "YOP"),
    ("XH0", "XH0"),
    ("Z0", "Z0"),
)


def _crc_words(words: list[int]) -> int:
    return zlib.crc32(b"".join(struct.pack("<i", int(w)) for w in words))


def gain_values(artifact: Artifact) -> list[int]:
    """The set's gain values in table order: each term's mantissa and shift (:func:`terms`), then :data:`VECTORS`."""
    rows, _ = terms(artifact)
    table = artifact.checks["fixed_point"]["integers"]
    return [v for c, e, _ in rows for v in (c, e)] + [int(v) for _, key in VECTORS for v in table[key]]


def set_crc32(artifact: Artifact) -> int:
    """CRC-32 of :func:`gain_values` as little-endian int32 words (gl_fixed_set_crc32(), the MAVLink ``GL_HASH``)."""
    return _crc_words(gain_values(artifact))


def structure_crc(artifact: Artifact) -> int:
    """CRC-32 of what a set shares with the build besides its formats (the MAVLink ``GL_FX_STRUCT``): each term's
    signal, each row's end, and the declared ranges' clip keys and quantised bounds, as little-endian int32 words."""
    fp = artifact.checks["fixed_point"]
    rows, ends = terms(artifact)
    r = _ranges(artifact, fp)
    words = [s for _, _, s in rows] + list(ends)
    words += (
        r["key_y_lo"] + r["key_y_hi"] + r["key_r_lo"] + r["key_r_hi"] + r["y_lo"] + r["y_hi"] + r["r_lo"] + r["r_hi"]
    )
    return _crc_words(words)


def described(artifact: Artifact) -> str:
    """What a fixed-point law's step depends on beyond its dimensions (part of its compatibility signature): its
    formats' signature and :func:`structure_crc`."""
    return f"formats={artifact.checks['fixed_point']['signature']};structure={structure_crc(artifact):08x}"


def _c_floats(values: list[float]) -> str:
    return "{" + ", ".join(f"{float(np.float32(v)):.9g}f" for v in values) + "}"


def _c_ints(values: list[int]) -> str:
    return "{" + ", ".join(str(int(v)) for v in values) + "}"


def _banner(a: Artifact) -> str:
    return f"/* DO NOT EDIT — generated from {a.name} sha256:{a.sha256} by gainlink export. */\n"


def render_header(artifact: Artifact) -> str:
    """Text of ``gl_fixed_gains.h``: the number format and dimensions as macros."""
    a, fp = artifact, artifact.checks["fixed_point"]
    numeric = fp["numeric"]
    rows, _ = terms(a)
    return (
        _banner(a) + "/**\n * @file gl_fixed_gains.h\n"
        " * @brief Number format and dimensions of the fixed-point law the firmware is built for (gl_fixed.h).\n */\n"
        "#ifndef GL_FIXED_GAINS_H\n#define GL_FIXED_GAINS_H\n\n"
        f"#define GL_NUMERIC_{numeric.upper()} 1\n"
        f'#define GL_FX_SIGNATURE "{fp["signature"]}" /* the formats (checks.fixed_point.signature) */\n'
        f"#define GL_FX_N {a.n}\n#define GL_FX_M {a.m}\n#define GL_FX_P {a.p}\n#define GL_FX_Q {a.q}\n"
        f"#define GL_FX_QA {max(a.q, 1)}\n"
        f"#define GL_FX_TERMS {len(rows)}\n#define GL_FX_TERMS_A {max(len(rows), 1)}\n"
        f"#define GL_FX_ANTI_WINDUP {ANTI_WINDUP_CODES[a.anti_windup]} /* {a.anti_windup} */\n\n"
        "#endif /* GL_FIXED_GAINS_H */\n"
    )


def render_source(artifact: Artifact) -> str:
    """Text of ``gl_fixed_gains.c``: the certified integers as one const ``gl_fixed_set_t`` (with the CRC of its gain
    values and the law's signature)."""
    a, fp = artifact, artifact.checks["fixed_point"]
    table, frac = fp["integers"], fp["formats"]
    rows, ends = terms(a)
    _check(a, fp["numeric"], rows)
    pad = [0] if a.q == 0 else []
    fields = {
        "coef": [c for c, _, _ in rows] or [0],
        "shift": [e for _, e, _ in rows] or [0],
        "signal": [s for _, _, s in rows] or [0],
        "row_end": ends,
        "row_shift": table["shift_v"] + table["shift_z"] + table["shift_x"],
        "shift_u": table["shift_u"],
        "uop_v": table["UOP_V"],
        "lo_v": table["LO_V"],
        "hi_v": table["HI_V"],
        "uop_u": table["UOP_U"],
        "u_safe": table["U_SAFE"],
        "yop": table["YOP"],
        "xh0": table["XH0"],
        "z0": table["Z0"] + pad,
        "frac_y": frac["y"],
        "frac_r": frac["r"] + pad,
        "frac_u": frac["u"],
    }
    ranges = _ranges(a, fp)
    for key in ("key_y_lo", "key_y_hi", "key_r_lo", "key_r_hi", "y_lo", "y_hi", "r_lo", "r_hi"):
        fields[key] = ranges[key] + (pad if key.startswith(("key_r", "r_")) else [])
    lines = [
        _banner(a),
        '#include "gainlink/gl_fixed.h"\n',
        '#include "gainlink/gl_artifact.h"',
        '#include "gl_gains.h" /* GL_LAW_SIGNATURE */\n',
        f"_Static_assert(GL_FX_N == {a.n} && GL_FX_M == {a.m} && GL_FX_P == {a.p} && GL_FX_Q == {a.q}, "
        '"gl_fixed_gains.h does not match");',
        f'_Static_assert(GL_FX_TERMS == {len(rows)}, "gl_fixed_gains.h does not match");',
        "",
        f'const char gl_artifact_name[] = "{a.name}";',
        f'const char gl_artifact_sha256[] = "{a.sha256}";',
        "",
        "const gl_fixed_set_t gl_fixed_default = {",
        "    .g = {",
    ]
    lines += [f"        .{name} = {_c_ints(values)}," for name, values in fields.items()]
    lines.append(f"        .u_lsb = {_c_floats([math.ldexp(1.0, -int(f)) for f in frac['u']])},")
    lines.append(f"        .clamp = {1 if a.anti_windup == 'clamp' else 0}u,")
    lines.append("    },")
    lines.append(f"    .crc32 = 0x{set_crc32(a):08X}u,")
    lines.append("    .signature = GL_LAW_SIGNATURE,")
    lines.append("};")
    return "\n".join(lines) + "\n"


def render_step(artifact: Artifact) -> str:
    """Text of ``gl_fixed_step.h``: each row's sum written out (``gl_fx_row``), the signals and shifts fixed
    as in the table, the mantissas read from it; the same terms in the same order as the generic loop of
    gl_fixed.c (an integer sum, exact: any order gives the same bits)."""
    rows, ends = terms(artifact)
    body, start = [], 0
    for row, end in enumerate(ends):
        body.append(f"    case {row}u:")
        for k in range(start, end):
            _, e, sig = rows[k]
            if e == 0:
                body.append(f"        GL_FX_MAC(lo, hi, c[{k}], s[{sig}]);")
            else:
                body.append(f"        GL_FX_MAC_SHIFTED(shifted, c[{k}], s[{sig}], {e}u);")
        body.append("        break;")
        start = end
    return (
        _banner(artifact) + "/**\n * @file gl_fixed_step.h\n"
        " * @brief The sums of the fixed-point law written out row by row (included by gl_fixed.c when\n"
        " *        GL_FX_UNROLLED): the terms of gl_fixed_default, same order, so bit for bit the generic loop.\n"
        " */\n#ifndef GL_FIXED_STEP_H\n#define GL_FIXED_STEP_H\n\n"
        f"_Static_assert(GL_FX_TERMS == {len(rows)} && GL_FX_ROWS == {len(ends)},\n"
        '               "gl_fixed_step.h does not match");\n\n'
        "static inline int64_t gl_fx_row(const gl_fixed_gains_t *g, const int32_t *s, unsigned row)\n{\n"
        "    uint32_t lo = 0u;\n    uint32_t hi = 0u;\n    uint64_t shifted = 0u;\n"
        "    const gl_fx_coef_t *c = g->coef;\n    (void)c;\n    (void)s;\n    switch (row) {\n"
        + "\n".join(body)
        + "\n    default:\n        break;\n    }\n"
        "    return (int64_t)((((uint64_t)hi << 32) | lo) + shifted);\n}\n\n#endif /* GL_FIXED_STEP_H */\n"
    )


def render_fixed(artifact: Artifact) -> dict[str, str]:
    """``{"gl_fixed_gains.h": ..., "gl_fixed_gains.c": ..., "gl_fixed_step.h": ...}`` for a fixed-point
    artifact; identical for the same artifact."""
    require_law(artifact, INTEGER_LAWS, "the fixed-point C")
    return {
        HEADER_NAME: render_header(artifact),
        SOURCE_NAME: render_source(artifact),
        STEP_NAME: render_step(artifact),
    }


def render_export(artifact: Artifact) -> dict[str, str]:
    """The fixed-point law's own files of the export: the lq structure's, whose signature covers the integers'
    formats and terms (:func:`described`), and the integers (:func:`render_fixed`)."""
    return codegen.render_c(artifact, more=described(artifact)) | render_fixed(artifact)


def param_table(artifact: Artifact) -> tuple[Param, ...]:
    """The fixed-point law's MAVLink parameter table (:mod:`gainlink.shipping.params`): the structure, the formats' and
    the terms' signatures, ``GL_HASH``, then each term's mantissa and shift and the vectors, INT32."""
    fp = artifact.checks["fixed_point"]
    table_, k = fp["integers"], 0
    gains: list[Param] = []
    for kind, count in (("v", artifact.m), ("z", artifact.q), ("x", artifact.n)):
        for i in range(count):
            for block, _ in ROWS[kind]:
                for j, (c, e) in enumerate(zip(table_[block][i], table_[f"{block}_shift"][i], strict=True)):
                    if c != 0:  # the order of terms(): term k
                        gains.append(
                            Param(f"GL_{block}_{i}_{j}", INT32, int(c), f"{block}[{i},{j}]", slot=f"g.coef[{k}]")
                        )
                        gains.append(Param(f"GL_{block}E_{i}_{j}", INT32, int(e), f"{block}_shift[{i},{j}]",
                                           slot=f"g.shift[{k}]"))  # fmt: skip
                        k += 1
    for stem, key in VECTORS:
        field = key.lower()  # gl_fixed_gains_t's field: uop_v, lo_v, ..., z0
        gains += [Param(f"GL_{stem}_{i}", INT32, int(v), f"{key}[{i}]", slot=f"g.{field}[{i}]")
                  for i, v in enumerate(table_[key])]  # fmt: skip
    header = structure_params(artifact) + [
        Param(SIGNATURE_ID, INT32, as_int32(int(fp["signature"], 16)), "checks.fixed_point.signature"),
        Param(STRUCTURE_ID, INT32, as_int32(structure_crc(artifact)), "structure"),
        Param(HASH_ID, INT32, as_int32(set_crc32(artifact)), "crc32", is_hash=True),
    ]
    return tuple(header + gains)
