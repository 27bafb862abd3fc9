"""C code generation: the gains header and source that the firmware library is built with.

``render_c(artifact)`` returns ``{"gl_gains.h": ..., "gl_gains_layout.h": ..., "gl_gains.c": ...,
"gl_step.h": ...}``: the dimensions and structure as macros with ``_Static_assert``s, the ``gl_gains_t`` struct
from the field table (:mod:`gainlink.shipping.gains_layout`), and the whole gain set as one ``const gl_gains_t``
with designated initialisers, every float printed round-trip (``%.9g`` + ``f``) and the payload's CRC-32 computed here
the same way the C library computes it (``gl_gains_crc32``). The same artifact always gives the same
bytes: no timestamps, no paths, nothing from the environment. Only ``gl_gains.c`` names the artifact (its name and
sha256 as ``gl_artifact_name``, ``gl_artifact_sha256``); the headers hold its structure and nothing else, so two
artifacts of one structure differ in that one translation unit.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np

from . import gains_layout as layout
from .artifact import Artifact
from .law_c import macros as law_macros
from .law_c import require_structure

FORM_CODES = {"predictor": 0, "current": 1}
ANTI_WINDUP_CODES = {"none": 0, "clamp": 1, "backcalc": 2}
DEFAULT_WATCHDOG_PERIODS = 10

HEADER_NAME = "gl_gains.h"
SOURCE_NAME = "gl_gains.c"
STEP_NAME = "gl_step.h"
CHUNK = 16  # coefficients per vldmia on the Cortex-M4F (registers s16..s31)
STATE_CHUNK = 8  # states held in s8..s15


@dataclass(frozen=True)
class GainSet:
    """The artifact's numbers exactly as the C ``gl_gains_t`` holds them (float32, integrator arrays padded).

    ``fields`` maps each number field of :data:`gainlink.shipping.gains_layout.NUMBERS` to a float32 array of its C
    shape, in declaration order; ``header`` holds the uint32 structure fields. ``crc32`` is the checksum of that
    payload.
    """

    header: tuple[int, ...]
    fields: dict[str, np.ndarray]
    crc32: int


def shape_of(artifact: Artifact) -> layout.Shape:
    """The compiled structure of ``artifact`` (the structure fields of its ``gl_gains_t``)."""
    a = artifact
    return layout.Shape(
        n=a.n,
        m=a.m,
        p=a.p,
        q=a.q,
        observer_form=FORM_CODES[a.observer_form],
        anti_windup=ANTI_WINDUP_CODES[a.anti_windup],
    )


def gain_set(artifact: Artifact) -> GainSet:
    """Lay out ``artifact`` as the C ``gl_gains_t`` payload and compute its CRC-32.

    Parameters
    ----------
    artifact : Artifact
        A validated artifact.

    Returns
    -------
    GainSet
        Float32 fields in C declaration order and the checksum ``gl_gains_crc32`` will compute.
    """
    require_structure(artifact, "lq", "the C gain set")
    shape = shape_of(artifact)
    fields = {}
    for f in layout.NUMBERS:
        value = getattr(artifact, f.name)  # every number is the artifact's attribute of that name
        out = np.zeros(f.shape(shape), dtype=f.type.dtype)
        if value is not None:  # an artifact without M (predictor form): zeros
            x = np.asarray(value, dtype=np.float64)
            out[tuple(slice(0, s) for s in x.shape)] = x.astype(out.dtype)
        fields[f.name] = out
    header = layout.GAINS.structure_values(shape)
    return GainSet(header=header, fields=fields, crc32=payload_crc32(header=header, fields=fields))


def payload_crc32(*, header: tuple[int, ...], fields: dict[str, np.ndarray]) -> int:
    """CRC-32 (zlib) of the little-endian serialisation the C library checksums."""
    return layout.GAINS.crc32(layout.Shape(*header), fields)


def float32_tables_crc32(tables: dict[str, np.ndarray]) -> int:
    """CRC-32 (zlib) of tables as a law's const set holds them: each one's float32 little-endian bytes, in order."""
    return zlib.crc32(b"".join(np.asarray(v, dtype="<f4").tobytes() for v in tables.values()))


def c_float(x: float) -> str:
    """A float32 as a C literal that reads back to the same float (``%.9g`` + ``f``)."""
    text = f"{float(np.float32(x)):.9g}"
    if not any(ch in text for ch in ".e"):
        text += ".0"
    return text + "f"


def _c_array(a: np.ndarray, indent: str) -> str:
    if a.ndim == 1:
        return "{" + ", ".join(c_float(v) for v in a) + "}"
    rows = [f"{indent}    [{i}] = {{" + ", ".join(c_float(v) for v in row) + "}," for i, row in enumerate(a)]
    return "{\n" + "\n".join(rows) + f"\n{indent}}}"


def source_banner(artifact: Artifact) -> str:
    """The first line of a generated source: the artifact it holds."""
    return f"/* DO NOT EDIT — generated from {artifact.name} sha256:{artifact.sha256} by gainlink export. */\n"


def structure_banner(source: str) -> str:
    """The first line of a generated header: it holds the artifact's structure only, and names the source holding
    the rest. Every header of a build is the same text for every artifact of that structure, so the firmware's other
    translation units compile to the same objects and the compiler cache serves them across artifacts."""
    return f"/* DO NOT EDIT — generated by gainlink export: structure only, the artifact is in {source}. */\n"


def identity_lines(artifact: Artifact) -> list[str]:
    """The definitions of ``gl_artifact_name`` and ``gl_artifact_sha256`` (``gainlink/gl_artifact.h``)."""
    return [
        f'const char gl_artifact_name[] = "{artifact.name}";',
        f'const char gl_artifact_sha256[] = "{artifact.sha256}";',
    ]


def render_header(artifact: Artifact, *, more: str = "") -> str:
    """Text of ``gl_gains.h``: the dimensions and structure of the artifact as macros (the same text for every
    artifact of that structure: its identity is in ``gl_gains.c``)."""
    a = artifact
    return (
        structure_banner(SOURCE_NAME) + "/**\n * @file gl_gains.h\n"
        " * @brief Dimensions and structure of the artifact the firmware is built for (its name, sha256 and gains:\n"
        " *        gl_gains.c, gainlink/gl_artifact.h).\n */\n"
        "#ifndef GL_GAINS_H\n#define GL_GAINS_H\n\n"
        f"#define GL_N {a.n}\n#define GL_M {a.m}\n#define GL_P {a.p}\n#define GL_Q {a.q}\n"
        f"#define GL_OBSERVER_FORM {FORM_CODES[a.observer_form]} /* {a.observer_form} */\n"
        f"#define GL_ANTI_WINDUP {ANTI_WINDUP_CODES[a.anti_windup]} /* {a.anti_windup} */\n"
        f"#define GL_WATCHDOG_PERIODS_DEFAULT {DEFAULT_WATCHDOG_PERIODS}u\n"
        + law_macros(a, described=described(a, more=more))
        + "\n#endif /* GL_GAINS_H */\n"
    )


def described(artifact: Artifact, *, more: str = "") -> str:
    """What the compiled lq step depends on besides the law's pair (its compatibility signature's text): the
    dimensions, observer form and anti-windup mode, and ``more`` that the law's own files add (a fixed-point law's
    formats and term structure: :func:`gainlink.laws.fixed.codegen.described`)."""
    a = artifact
    text = f"n={a.n};m={a.m};p={a.p};q={a.q};form={a.observer_form};aw={a.anti_windup}"
    return text + (f";{more}" if more else "")


def render_source(artifact: Artifact, gains: GainSet) -> str:
    """Text of ``gl_gains.c``: the artifact's name and sha256, and its gain set as one const ``gl_gains_t``."""
    a = artifact
    n, m, p, q, form, aw = gains.header[:6]
    lines = [
        source_banner(a),
        '#include "gainlink/gl_loop.h"\n',
        f'_Static_assert(GL_N == {n} && GL_M == {m} && GL_P == {p} && GL_Q == {q}, "gl_gains.h does not match");',
        f'_Static_assert(GL_OBSERVER_FORM == {form} && GL_ANTI_WINDUP == {aw}, "gl_gains.h does not match");',
        "",
        *identity_lines(a),
        "",
        "const gl_gains_t gl_gains_default = {",
    ]
    lines += [f"    .{f.name} = {v}u," for f, v in zip(layout.STRUCTURE, gains.header, strict=True)]
    for name, value in gains.fields.items():
        text = c_float(value) if value.ndim == 0 else _c_array(value, "    ")
        lines.append(f"    .{name} = {text},")
    lines.append(f"    .{layout.CHECKSUM.name} = 0x{gains.crc32:08X}u,")
    lines.append("};")
    return "\n".join(lines) + "\n"


class _Stream:
    """Emits the loads of the coefficient stream ``w`` in chunks of :data:`CHUNK`, in consumption order."""

    def __init__(self, length: int, out: list[str]) -> None:
        self.length, self.pos, self.out = length, 0, out

    def next(self) -> str:
        k = self.pos
        if k % CHUNK == 0:
            count = min(CHUNK, self.length - k)
            names = ", ".join(f"w{k + i}" for i in range(count))
            self.out.append(f"    GL_LD{count}(w + {k}, {names});")
        self.pos += 1
        return f"w{k}"


def render_step(artifact: Artifact) -> str:
    """Text of ``gl_step.h``: the law for these fixed dimensions, fully unrolled.

    It performs exactly the operations of the library's generic ``gl_step_core`` in the same order
    (so both are bit-identical), with every coefficient read once from the stream in chunks
    (``GL_LDk``: one ``vldmia`` per chunk on the Cortex-M4F).
    """
    a = artifact
    n, m, p, q = a.n, a.m, a.p, a.q
    current = a.observer_form == "current"
    vrow = 1 + n + (p if current else 0) + q + 2
    zrow = p + 1 + (m if a.anti_windup == "backcalc" else 0)
    length = p + m * vrow + q * zrow + n * (n + m + p)
    body: list[str] = []
    st = _Stream(length, body)
    _step_inputs(a, st, body)
    _step_commands(a, st, body)
    _step_integrators(a, st, body)
    _step_estimate(a, st, body)
    assert st.pos == length
    body += [f"    xh_io[{i}] = xn{i};" for i in range(n)]
    body += [f"    z_io[{j}] = zn{j};" for j in range(q)]
    body += [f"    u[{i}] = u{i};" for i in range(m)]
    if q == 0:
        body += ["    (void)z_io;", "    (void)rs;"]
    body.append("    return sat;")
    return _step_file(a, body, length)


def _step_inputs(a: Artifact, st: _Stream, body: list[str]) -> None:
    """States, integrators, samples and references into locals; dy = y - y_op."""
    # The first states in one multi-register load (registers s8..s15, kept for the whole step).
    first = min(a.n, STATE_CHUNK)
    body.append(f"    GL_LDS{first}(xh_io, " + ", ".join(f"x{j}" for j in range(first)) + ");")
    body += [f"    const float x{j} = xh_io[{j}];" for j in range(first, a.n)]
    body += [f"    const float z{j} = z_io[{j}];" for j in range(a.q)]
    body += [f"    const float y{k} = ys[{k}];" for k in range(a.p)]
    body += [f"    const float r{j} = rs[{j}];" for j in range(a.q)]
    body += [f"    const float dy{k} = y{k} - {st.next()};" for k in range(a.p)]
    body.append("    uint32_t sat = 0u;")


def _step_commands(a: Artifact, st: _Stream, body: list[str]) -> None:
    """v = u_op + dv, clamped to the limits (saturation bits), du = u - u_op, one input at a time."""
    for i in range(a.m):
        uop = st.next()
        body.append(f"    float dv{i} = {st.next()} * x0;")
        body += [f"    dv{i} = GL_FMA({st.next()}, x{j}, dv{i});" for j in range(1, a.n)]
        if a.observer_form == "current":
            body += [f"    dv{i} = GL_FMA({st.next()}, dy{k}, dv{i});" for k in range(a.p)]
        body += [f"    dv{i} = GL_FMA({st.next()}, z{j}, dv{i});" for j in range(a.q)]
        lo, hi = st.next(), st.next()
        body += [
            f"    const float v{i} = {uop} + dv{i};",
            f"    float u{i} = v{i};",
            f"    if (v{i} < {lo}) {{",
            f"        u{i} = {lo};",
            f"        sat |= {1 << i}u;",
            f"    }} else if (v{i} > {hi}) {{",
            f"        u{i} = {hi};",
            f"        sat |= {1 << i}u;",
            "    }",
            f"    const float du{i} = u{i} - {uop};",
        ]


def _step_integrators(a: Artifact, st: _Stream, body: list[str]) -> None:
    """zn = z + Ts (r - Ci y) with the artifact's anti-windup (back-calculation term or clamp)."""
    for j in range(a.q):
        body.append(f"    float e{j} = r{j};")
        body += [f"    e{j} = GL_FMA({st.next()}, y{k}, e{j});" for k in range(a.p)]
        body.append(f"    float zn{j} = GL_FMA({st.next()}, e{j}, z{j});")
        if a.anti_windup == "backcalc":
            body += [f"    zn{j} = GL_FMA({st.next()}, u{k} - v{k}, zn{j});" for k in range(a.m)]
        if a.anti_windup == "clamp":
            body.append(f"    zn{j} = (sat == 0u) ? zn{j} : z{j};")


def _step_estimate(a: Artifact, st: _Stream, body: list[str]) -> None:
    """xn = (Ad - L Cd) xh + (Bd - L Dd) du + L dy, one row at a time."""
    for i in range(a.n):
        body.append(f"    float xn{i} = {st.next()} * x0;")
        body += [f"    xn{i} = GL_FMA({st.next()}, x{j}, xn{i});" for j in range(1, a.n)]
        body += [f"    xn{i} = GL_FMA({st.next()}, du{k}, xn{i});" for k in range(a.m)]
        body += [f"    xn{i} = GL_FMA({st.next()}, dy{k}, xn{i});" for k in range(a.p)]


# how firmware/src/gl_loop.c opens the generic gl_step_core; the generated one keeps its layout
_STEP_CORE_OPEN = "static inline __attribute__((always_inline)) uint32_t gl_step_core("


def _step_file(a: Artifact, body: list[str], length: int) -> str:
    n, m, p, q = a.n, a.m, a.p, a.q
    return (
        structure_banner(SOURCE_NAME) + "/**\n * @file gl_step.h\n"
        f" * @brief The control law for n={n} m={m} p={p} q={q} ({a.observer_form}, {a.anti_windup}), fully unrolled.\n"
        " *\n * Included by gl_loop.c in GL_STEP_UNROLLED builds in place of the generic loops; same operations,\n"
        f" * same order, so the results are bit-identical. Stream length {length} coefficients.\n */\n"
        + "#ifndef GL_STEP_H\n#define GL_STEP_H\n\n"
        f'_Static_assert(GL_STREAM_LEN == {length}, "gl_step.h does not match the library\'s stream layout");\n\n'
        f"{_STEP_CORE_OPEN}const float *w, float *xh_io, float *z_io,\n"
        f"{' ' * (len(_STEP_CORE_OPEN) - 1)}const float *ys, const float *rs, float *u)\n"
        "{\n" + "\n".join(body) + "\n}\n\n#endif /* GL_STEP_H */\n"
    )


def render_c(artifact: Artifact, *, more: str = "") -> dict[str, str]:
    """Render the lq structure's gains header and source for ``artifact`` (``more``: what the law's own files add to
    the compatibility signature, :func:`described`).

    Returns
    -------
    dict of str to str
        ``{"gl_gains.h": ..., "gl_gains_layout.h": ..., "gl_gains.c": ..., "gl_step.h": ...}``; identical for the
        same artifact. A fixed-point law's export adds its integers (:mod:`gainlink.laws.fixed.codegen`,
        :func:`gainlink.shipping.export_c.render_export`).
    """
    require_structure(artifact, "lq", "codegen")
    gains = gain_set(artifact)
    return {
        HEADER_NAME: render_header(artifact, more=more),
        layout.HEADER_NAME: layout.GAINS.render_header(banner=structure_banner(SOURCE_NAME), shape=shape_of(artifact)),
        SOURCE_NAME: render_source(artifact, gains),
        STEP_NAME: render_step(artifact),
    }
