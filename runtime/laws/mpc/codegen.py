"""C code generation for an MPC artifact: ``gl_gains.h`` (the dimensions, horizon, cap and forms as macros) and
``gl_mpc_gains.c`` (the tables as one ``const gl_mpc_set_t gl_mpc_default``, ``firmware/include/gainlink/gl_mpc.h``),
every float printed round-trip. The firmware builds ``firmware/src/gl_mpc.c`` when ``gl_gains.h`` names the law
(``GL_LAW_STRUCTURE mpc``); :func:`gainlink.shipping.export_c.render_export` calls :func:`render_mpc` (registered in
``export_c.RENDERINGS`` by this family), the MAVLink upload :func:`param_table` (``params.TABLES``).
"""

from __future__ import annotations

import numpy as np

from ...shipping import codegen
from ...shipping.artifact import Artifact
from ...shipping.law_c import macros as law_macros
from ...shipping.params import HASH_ID, INT32, REAL32, Param, as_int32

SOURCE_NAME = "gl_mpc_gains.c"
FORM_CODES = {"predictor": 0, "current": 1}
ANTI_WINDUP_CODES = {"none": 0, "clamp": 1, "backcalc": 2}
FLT_MAX = float(np.finfo(np.float32).max)
_MISMATCH = '"gl_gains.h does not match"'


def _pad(x: np.ndarray, length: int) -> np.ndarray:
    """``x`` flattened, zero-padded to ``length`` (an array C stores with at least one element)."""
    out = np.zeros(length)
    flat = np.asarray(x, dtype=np.float64).reshape(-1)
    out[: flat.size] = flat
    return out


def tables(artifact: Artifact) -> dict[str, np.ndarray]:
    """The tables exactly as ``gl_mpc_default`` holds them (float32, ``gl_mpc_tables_t`` order, each field flat;
    the integrator and box arrays padded to at least one row)."""
    a, b = artifact, artifact.mpc
    qa, nca = max(a.q, 1), max(b.nc, 1)
    eps = b.eps
    M = np.zeros((a.n, a.p)) if a.M is None else a.M
    f64 = {
        "Ad": a.Ad, "Bd": a.Bd, "Cd": a.Cd, "Dd": a.Dd, "L": a.L, "M": M, "Ci": _pad(a.Ci, qa * a.p),
        "Kaw": _pad(a.Kaw, qa * a.m), "Ts": a.Ts, "u_op": a.u_op, "y_op": a.y_op, "u_min": a.u_min,
        "u_max": a.u_max, "xh0": a.xh0, "z0": _pad(a.z0, qa), "A": b.A, "B": b.B, "K": b.K, "C1": b.C1,
        "Hx": _pad(b.Hx, nca * b.nx), "lo_u": b.lo_u, "hi_u": b.hi_u,
        "lo_x": _pad(np.maximum(b.lo_x, -FLT_MAX), nca), "hi_x": _pad(np.minimum(b.hi_x, FLT_MAX), nca),
        "rho": b.rho, "rho_x": b.rho_state, "kappa": b.kappa, "eps_pu": eps["pu"], "eps_du": eps["du"],
        "eps_px": _pad(eps["px"], nca), "eps_dx": _pad(eps["dx"], nca),
    }  # fmt: skip
    out = {}
    for k, v in f64.items():
        v = np.asarray(v, dtype=np.float64)
        out[k] = v.astype(np.float32) if v.ndim == 0 else v.reshape(v.shape[0], -1).astype(np.float32) if k in (
            "K", "C1") else v.reshape(-1).astype(np.float32)  # fmt: skip
    return out


def described(artifact: Artifact) -> str:
    """What the compiled MPC step depends on besides the law's pair (its compatibility signature's text)."""
    a, b = artifact, artifact.mpc
    return (
        f"n={a.n};m={a.m};p={a.p};q={a.q};horizon={b.horizon};nc={b.nc};max_iter={b.max_iter};"
        f"form={a.observer_form};aw={a.anti_windup}"
    )


def tables_crc32(artifact: Artifact) -> int:
    """CRC-32 of the tables' bytes as ``gl_mpc_default`` holds them (gl_mpc_tables_crc32(), the MAVLink
    ``GL_HASH``)."""
    return codegen.float32_tables_crc32(tables(artifact))


def render_header(artifact: Artifact) -> str:
    """Text of the MPC ``gl_gains.h``."""
    a, b = artifact, artifact.mpc
    return (
        codegen.structure_banner(SOURCE_NAME) + "/**\n * @file gl_gains.h\n"
        " * @brief Dimensions, horizon, cap and forms of the MPC artifact the firmware is built for (its name, sha256\n"
        " *        and tables: gl_mpc_gains.c, gainlink/gl_artifact.h).\n */\n"
        "#ifndef GL_GAINS_H\n#define GL_GAINS_H\n\n"
        "#define GL_MPC 1\n"
        f"#define GL_N {a.n}\n#define GL_M {a.m}\n#define GL_P {a.p}\n#define GL_Q {a.q}\n"
        f"#define GL_H {b.horizon} /* the horizon: moves u0..u(H-1) */\n"
        f"#define GL_NC {b.nc} /* soft box rows */\n"
        f"#define GL_MPC_MAX_ITER {b.max_iter}u /* the ADMM cap: a step's cost is bounded by it */\n"
        f"#define GL_OBSERVER_FORM {FORM_CODES[a.observer_form]} /* {a.observer_form} */\n"
        f"#define GL_ANTI_WINDUP {ANTI_WINDUP_CODES[a.anti_windup]} /* {a.anti_windup} */\n"
        f"#define GL_WATCHDOG_PERIODS_DEFAULT {codegen.DEFAULT_WATCHDOG_PERIODS}u\n"
        + law_macros(a, described=described(a))
        + "\n#endif /* GL_GAINS_H */\n"
    )


def render_source(artifact: Artifact) -> str:
    """Text of ``gl_mpc_gains.c``: the tables as one const ``gl_mpc_set_t`` (with their CRC and the signature)."""
    a, b = artifact, artifact.mpc
    lines = [
        codegen.source_banner(a),
        '#include "gainlink/gl_mpc.h"\n',
        f"_Static_assert(GL_N == {a.n} && GL_M == {a.m} && GL_P == {a.p} && GL_Q == {a.q}, {_MISMATCH});",
        f"_Static_assert(GL_H == {b.horizon} && GL_NC == {b.nc}, {_MISMATCH});",
        "",
        *codegen.identity_lines(a),
        "",
        "const gl_mpc_set_t gl_mpc_default = {",
        "    .t = {",
    ]
    for name, value in tables(a).items():
        text = codegen.c_float(value) if value.ndim == 0 else codegen._c_array(value, "        ")
        lines.append(f"        .{name} = {text},")
    lines += ["    },", f"    .crc32 = 0x{tables_crc32(a):08X}u,", "    .signature = GL_LAW_SIGNATURE,", "};"]
    return "\n".join(lines) + "\n"


def render_mpc(artifact: Artifact) -> dict[str, str]:
    """The export of an MPC artifact: ``{"gl_gains.h": ..., "gl_mpc_gains.c": ...}``; same artifact, same bytes."""
    return {codegen.HEADER_NAME: render_header(artifact), SOURCE_NAME: render_source(artifact)}


#: The MPC table's read-only structure parameters.
MPC_DIMENSION_IDS = ("GL_DIM_N", "GL_DIM_M", "GL_DIM_P", "GL_DIM_Q", "GL_HORIZON", "GL_DIM_NC", "GL_MAXIT")


def param_table(artifact: Artifact) -> tuple[Param, ...]:
    """The MPC law's MAVLink parameter table (:mod:`gainlink.shipping.params`): the structure, ``GL_HASH``, then
    every float of the tables, REAL32."""
    a, b = artifact, artifact.mpc
    dims = (a.n, a.m, a.p, a.q, b.horizon, b.nc, b.max_iter)
    out = [Param(k, INT32, int(v), "structure") for k, v in zip(MPC_DIMENSION_IDS, dims, strict=True)]
    out.append(Param(HASH_ID, INT32, as_int32(tables_crc32(a)), "CRC-32 of the tables", is_hash=True))
    for field, values in tables(a).items():
        stem = field.upper().replace("_", "")
        if values.ndim == 0:
            out.append(Param(f"GL_{stem}", REAL32, float(values), field, slot=f"t.{field}"))
        elif values.ndim == 1:
            out += [Param(f"GL_{stem}_{j}", REAL32, float(v), field, slot=f"t.{field}[{j}]")
                    for j, v in enumerate(values)]  # fmt: skip
        else:
            out += [Param(f"GL_{stem}{k}_{j}", REAL32, float(v), field, slot=f"t.{field}[{k}][{j}]")
                    for k, row in enumerate(values) for j, v in enumerate(row)]  # fmt: skip
    return tuple(out)
