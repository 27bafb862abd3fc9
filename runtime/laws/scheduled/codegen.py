"""C code generation for a scheduled (schema-2) artifact: the per-point tables of the velocity-form law.

``render_scheduled(artifact)`` returns ``{"gl_gains.h": ..., "gl_sched_gains.c": ...}``: the dimensions and the
shape of sigma as macros (``GL_SCHEDULED 1``, ``GL_NPTS``, ``GL_E``, ``GL_SIGMA_*``) and the tables as one
``const gl_sched_tables_t gl_sched_default`` (``firmware/include/gainlink/gl_sched.h``), every float printed
round-trip. The firmware builds the scheduled law (``firmware/src/gl_sched.c``) when ``gl_gains.h`` names it
(``GL_LAW_STRUCTURE scheduled``); :func:`gainlink.shipping.export_c.render_export` is what ``gainlink export`` and
the firmware build call; it asks :func:`render_scheduled`, and the MAVLink upload :func:`param_table`, through the
tables this family registers them in (``export_c.RENDERINGS``, ``params.TABLES``).
"""

from __future__ import annotations

import numpy as np

from ...shipping import codegen
from ...shipping.artifact import Artifact
from ...shipping.law_c import macros as law_macros
from ...shipping.law_c import require_law
from ...shipping.params import HASH_ID, INT32, REAL32, Param, as_int32
from .block import COEFFICIENTS

SOURCE_NAME = "gl_sched_gains.c"
FORM_CODES = {"predictor": 0, "current": 1}
_MISMATCH = '"gl_gains.h does not match"'


def tables(artifact: Artifact) -> dict[str, np.ndarray]:
    """The tables exactly as ``gl_sched_default`` holds them (float32, each point's matrices row-major).

    Keys in ``gl_sched_tables_t`` order: ``S``, ``Kx Ky Kz F G Ly`` (N, rows * cols), ``u_op`` (N, m), ``u_min``,
    ``u_max``, ``Ci`` (q * p), ``alpha``, ``rate_step`` (``Ts rate_max``; without a limit the envelope's width,
    unused).
    """
    a = artifact
    S = a.schedule
    npts = S.points.size
    f32 = lambda x: np.asarray(x, dtype=np.float64).astype(np.float32)  # noqa: E731
    out = {"S": f32(S.points)}
    out.update({k: f32(S.coef[k].reshape(npts, -1)) for k in COEFFICIENTS})
    out["u_op"] = f32(S.u_op)
    out["u_min"], out["u_max"] = f32(a.u_min), f32(a.u_max)
    out["Ci"] = f32(a.Ci.reshape(-1))
    out["alpha"] = f32(S.filter_alpha)
    width = float(S.points[-1] - S.points[0])
    out["rate_step"] = f32(width if S.rate_max is None else a.Ts * S.rate_max)
    return out


def fixed_masks(artifact: Artifact) -> dict[str, int]:
    """Per coefficient group, bit k (k < 32) set when coefficient k is the same float32 at every point and not -0.0:
    the scheduled step does not interpolate it (``fmaf(lam, +0, x) == x`` for such an ``x``; gl_sched.c checks the
    tables it runs on against these masks at init)."""
    t = tables(artifact)
    out = {}
    for name in COEFFICIENTS:
        bits = np.ascontiguousarray(t[name]).view(np.uint32)
        fixed = np.all(bits == bits[0], axis=0) & (bits[0] != 0x80000000)
        out[name] = sum(1 << int(k) for k in np.flatnonzero(fixed[:32]))
    return out


def render_header(artifact: Artifact) -> str:
    """Text of the scheduled ``gl_gains.h``: dimensions and the shape of sigma as macros."""
    a = artifact
    S = a.schedule
    external = S.source == "external"
    return (
        codegen.structure_banner(SOURCE_NAME) + "/**\n * @file gl_gains.h\n"
        " * @brief Dimensions and the shape of sigma of the scheduled artifact the firmware is built for (its name,\n"
        " *        sha256 and tables: gl_sched_gains.c, gainlink/gl_artifact.h).\n */\n"
        "#ifndef GL_GAINS_H\n#define GL_GAINS_H\n\n"
        "#define GL_SCHEDULED 1\n"
        f"#define GL_N {a.n}\n#define GL_M {a.m}\n#define GL_P {a.p}\n#define GL_Q {a.q}\n"
        f"#define GL_NPTS {S.points.size}\n#define GL_E {len(S.external)}\n"
        f"#define GL_OBSERVER_FORM {FORM_CODES[a.observer_form]} /* {a.observer_form} */\n"
        f"#define GL_SIGMA_EXTERNAL {int(external)} /* sigma = {S.sigma} ({S.source}) */\n"
        f"#define GL_SIGMA_INDEX {S.index}\n"
        f"#define GL_SIGMA_FILTERED {int(S.filter_alpha != 1.0)}\n"
        f"#define GL_SIGMA_RATE_LIMITED {int(S.rate_max is not None)} /* {_rate_comment(S)} */\n"
        + "".join(f"#define GL_SCHED_FIXED_{k.upper()} {v:#010x}u\n" for k, v in fixed_masks(a).items())
        + f"#define GL_WATCHDOG_PERIODS_DEFAULT {codegen.DEFAULT_WATCHDOG_PERIODS}u\n"
        + law_macros(a, described=described(a))
        + "\n#endif /* GL_GAINS_H */\n"
    )


def _rate_comment(S) -> str:
    """What the rate limit is and whether a Lyapunov certificate covers it (docs/design.md, verdicts)."""
    value = "rate_max none" if S.rate_max is None else f"rate_max {S.rate_max:g}/s"
    return f"{value}, {'certified' if S.rate_certified else 'NOT certified'}"


def described(artifact: Artifact) -> str:
    """What the compiled scheduled step depends on besides the law's pair (its compatibility signature's text):
    dimensions, points, external signals, the shape of sigma and the coefficients it does not interpolate."""
    a, S = artifact, artifact.schedule
    masks = ",".join(f"{k}={v:08x}" for k, v in fixed_masks(a).items())
    return (
        f"n={a.n};m={a.m};p={a.p};q={a.q};npts={S.points.size};e={len(S.external)};form={a.observer_form};"
        f"sigma={S.source}:{S.index};filtered={int(S.filter_alpha != 1.0)};rate={int(S.rate_max is not None)};"
        f"fixed={masks}"
    )


def tables_crc32(artifact: Artifact) -> int:
    """CRC-32 of the tables' bytes as ``gl_sched_default`` holds them (gl_sched_tables_crc32(), the MAVLink
    ``GL_HASH``)."""
    return codegen.float32_tables_crc32(tables(artifact))


def render_source(artifact: Artifact) -> str:
    """Text of ``gl_sched_gains.c``: the tables as one const ``gl_sched_set_t`` (with their CRC and the law's
    signature)."""
    a = artifact
    S = a.schedule
    lines = [
        codegen.source_banner(a),
        '#include "gainlink/gl_sched.h"\n',
        f"_Static_assert(GL_N == {a.n} && GL_M == {a.m} && GL_P == {a.p} && GL_Q == {a.q}, {_MISMATCH});",
        f"_Static_assert(GL_NPTS == {S.points.size} && GL_E == {len(S.external)}, {_MISMATCH});",
        "",
        *codegen.identity_lines(a),
        "",
        "const gl_sched_set_t gl_sched_default = {",
        "    .t = {",
    ]
    for name, value in tables(a).items():
        text = codegen.c_float(value) if value.ndim == 0 else codegen._c_array(value, "        ")
        lines.append(f"        .{name} = {text},")
    lines.append("    },")
    lines.append(f"    .crc32 = 0x{tables_crc32(a):08X}u,")
    lines.append("    .signature = GL_LAW_SIGNATURE,")
    lines.append("};")
    return "\n".join(lines) + "\n"


def render_scheduled(artifact: Artifact) -> dict[str, str]:
    """The export of a scheduled artifact: ``{"gl_gains.h": ..., "gl_sched_gains.c": ...}``; same artifact, same
    bytes."""
    require_law(artifact, ("scheduled/float32",), "the scheduled tables")
    return {codegen.HEADER_NAME: render_header(artifact), SOURCE_NAME: render_source(artifact)}


#: The scheduled table's read-only structure parameters.
SCHEDULED_DIMENSION_IDS = ("GL_DIM_N", "GL_DIM_M", "GL_DIM_P", "GL_DIM_Q", "GL_NPTS", "GL_DIM_E")

#: Each field of gl_sched_tables_t: its id stem and whether it holds one block per point.
_SCHEDULED_STEMS = {
    "S": ("S", False), "Kx": ("KX", True), "Ky": ("KY", True), "Kz": ("KZ", True), "F": ("F", True),
    "G": ("G", True), "Ly": ("LY", True), "u_op": ("UOP", True), "u_min": ("UMIN", False),
    "u_max": ("UMAX", False), "Ci": ("CI", False), "alpha": ("ALPHA", False), "rate_step": ("RATE", False),
}  # fmt: skip


def _scheduled_shapes(a: Artifact) -> dict[str, tuple[int, ...]]:
    """Each field's shape per point (empty: a scalar; one number: a vector)."""
    n, m, p, q = a.n, a.m, a.p, a.q
    mats = {"Kx": (m, n), "Ky": (m, p), "Kz": (m, q), "F": (n, n), "G": (n, m), "Ly": (n, p), "Ci": (q, p)}
    return {**mats, "S": (a.schedule.points.size,), "u_op": (m,), "u_min": (m,), "u_max": (m,), "alpha": (),
            "rate_step": ()}  # fmt: skip


def _scheduled_names(field: str, point: int | None, shape: tuple[int, ...]) -> list[tuple[str, str]]:
    """Each element's parameter id and C designator in ``gl_sched_set_t`` (``t.Kx[k][i * n + j]``)."""
    stem = _SCHEDULED_STEMS[field][0]
    base, slot = (
        f"GL_{stem}" + ("" if point is None else f"_{point}"),
        f"t.{field}" + ("" if point is None else f"[{point}]"),
    )
    if not shape:
        return [(base, slot)]
    if len(shape) == 1:
        return [(f"{base}_{i}", f"{slot}[{i}]") for i in range(shape[0])]
    return [(f"{base}_{i}_{j}", f"{slot}[{i * shape[1] + j}]") for i in range(shape[0]) for j in range(shape[1])]


def param_table(artifact: Artifact) -> tuple[Param, ...]:
    """The scheduled law's MAVLink parameter table (:mod:`gainlink.shipping.params`): the structure, ``GL_HASH``,
    then every float of the tables, REAL32."""
    a = artifact
    dims = (a.n, a.m, a.p, a.q, a.schedule.points.size, len(a.schedule.external))
    out = [Param(k, INT32, int(v), "structure") for k, v in zip(SCHEDULED_DIMENSION_IDS, dims, strict=True)]
    out.append(Param(HASH_ID, INT32, as_int32(tables_crc32(a)), "CRC-32 of the tables", is_hash=True))
    shapes = _scheduled_shapes(a)
    for field, values in tables(a).items():
        flat = np.asarray(values, dtype=np.float32).reshape(-1)
        points = range(a.schedule.points.size) if _SCHEDULED_STEMS[field][1] else [None]
        named = [pair for k in points for pair in _scheduled_names(field, k, shapes[field])]
        out += [Param(name, REAL32, float(v), field, slot=slot) for (name, slot), v in zip(named, flat, strict=True)]
    return tuple(out)
