"""C code generation: the gains header and source that the firmware library is built with.

``render_c(artifact)`` returns ``{"gl_gains.h": ..., "gl_gains.c": ...}``: the dimensions and structure
as macros with ``_Static_assert``s, and the whole gain set as one ``const gl_gains_t`` with designated
initialisers, every float printed round-trip (``%.9g`` + ``f``) and the payload's CRC-32 computed here
the same way the C library computes it (``gl_gains_crc32``). The same artifact always gives the same
bytes: no timestamps, no paths, nothing from the environment.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .artifact import Artifact
from .fileio import publish_files

FORM_CODES = {"predictor": 0, "current": 1}
ANTI_WINDUP_CODES = {"none": 0, "clamp": 1, "backcalc": 2}
DEFAULT_WATCHDOG_PERIODS = 10

HEADER_NAME = "gl_gains.h"
SOURCE_NAME = "gl_gains.c"


@dataclass(frozen=True)
class GainSet:
    """The artifact's numbers exactly as the C ``gl_gains_t`` holds them (float32, integrator arrays padded).

    ``fields`` maps each C field name to a float32 array in declaration order; ``header`` holds the six
    uint32 structure fields. ``crc32`` is the checksum of that payload.
    """

    header: tuple[int, int, int, int, int, int]
    fields: dict[str, np.ndarray]
    crc32: int


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
    a = artifact
    qa = max(a.q, 1)

    def pad(x: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
        out = np.zeros(shape, dtype=np.float32)
        x = np.asarray(x, dtype=np.float64)
        out[tuple(slice(0, s) for s in x.shape)] = x.astype(np.float32)
        return out

    fields = {
        "Ts": np.array([a.Ts], dtype=np.float32),
        "Ad": pad(a.Ad, (a.n, a.n)),
        "Bd": pad(a.Bd, (a.n, a.m)),
        "Cd": pad(a.Cd, (a.p, a.n)),
        "Dd": pad(a.Dd, (a.p, a.m)),
        "K": pad(a.K, (a.m, a.n)),
        "L": pad(a.L, (a.n, a.p)),
        "M": pad(a.M if a.M is not None else np.zeros((a.n, a.p)), (a.n, a.p)),
        "Ci": pad(a.Ci, (qa, a.p)),
        "Ki": pad(a.Ki, (a.m, qa)),
        "Kaw": pad(a.Kaw, (qa, a.m)),
        "u_min": pad(a.u_min, (a.m,)),
        "u_max": pad(a.u_max, (a.m,)),
        "xh0": pad(a.xh0, (a.n,)),
        "z0": pad(a.z0, (qa,)),
    }
    header = (a.n, a.m, a.p, a.q, FORM_CODES[a.observer_form], ANTI_WINDUP_CODES[a.anti_windup])
    return GainSet(header=header, fields=fields, crc32=payload_crc32(header=header, fields=fields))


def payload_crc32(*, header: tuple[int, ...], fields: dict[str, np.ndarray]) -> int:
    """CRC-32 (zlib) of the little-endian serialisation the C library checksums."""
    blob = struct.pack(f"<{len(header)}I", *header)
    blob += b"".join(np.ascontiguousarray(v, dtype="<f4").tobytes() for v in fields.values())
    return zlib.crc32(blob) & 0xFFFFFFFF


def c_float(x: float) -> str:
    """A float32 as a C literal that reads back to the same float (``%.9g`` + ``f``)."""
    text = "%.9g" % float(np.float32(x))
    if not any(ch in text for ch in ".e"):
        text += ".0"
    return text + "f"


def _c_array(a: np.ndarray, indent: str) -> str:
    if a.ndim == 1:
        return "{" + ", ".join(c_float(v) for v in a) + "}"
    rows = [f"{indent}    [{i}] = {{" + ", ".join(c_float(v) for v in row) + "}," for i, row in enumerate(a)]
    return "{\n" + "\n".join(rows) + f"\n{indent}}}"


def _banner(artifact: Artifact) -> str:
    return f"/* DO NOT EDIT — generated from {artifact.name} sha256:{artifact.sha256} by gainlink export. */\n"


def render_header(artifact: Artifact, gains: GainSet) -> str:
    """Text of ``gl_gains.h``: dimensions, structure and identity of the artifact as macros."""
    a = artifact
    return (
        _banner(a)
        + "/**\n * @file gl_gains.h\n * @brief Dimensions and structure of the artifact the firmware is built for.\n */\n"
        "#ifndef GL_GAINS_H\n#define GL_GAINS_H\n\n"
        f'#define GL_NAME "{a.name}"\n'
        f'#define GL_ARTIFACT_SHA256 "{a.sha256}"\n'
        f"#define GL_N {a.n}\n#define GL_M {a.m}\n#define GL_P {a.p}\n#define GL_Q {a.q}\n"
        f"#define GL_OBSERVER_FORM {FORM_CODES[a.observer_form]} /* {a.observer_form} */\n"
        f"#define GL_ANTI_WINDUP {ANTI_WINDUP_CODES[a.anti_windup]} /* {a.anti_windup} */\n"
        f"#define GL_GAINS_CRC32 0x{gains.crc32:08X}u\n"
        f"#define GL_TS_SECONDS {c_float(a.Ts)}\n"
        f"#define GL_WATCHDOG_PERIODS_DEFAULT {DEFAULT_WATCHDOG_PERIODS}u\n\n"
        "#endif /* GL_GAINS_H */\n"
    )


def render_source(artifact: Artifact, gains: GainSet) -> str:
    """Text of ``gl_gains.c``: the artifact's gain set as one const ``gl_gains_t``."""
    a = artifact
    n, m, p, q, form, aw = gains.header
    lines = [
        _banner(a),
        '#include "gainlink/gl_loop.h"\n',
        f'_Static_assert(GL_N == {n} && GL_M == {m} && GL_P == {p} && GL_Q == {q}, "gl_gains.h does not match");',
        f'_Static_assert(GL_OBSERVER_FORM == {form} && GL_ANTI_WINDUP == {aw}, "gl_gains.h does not match");',
        "",
        "const gl_gains_t gl_gains_default = {",
        f"    .n = {n}u,",
        f"    .m = {m}u,",
        f"    .p = {p}u,",
        f"    .q = {q}u,",
        f"    .observer_form = {form}u,",
        f"    .anti_windup = {aw}u,",
    ]
    for name, value in gains.fields.items():
        if name == "Ts":
            lines.append(f"    .Ts = {c_float(value[0])},")
        else:
            lines.append(f"    .{name} = {_c_array(value, '    ')},")
    lines.append(f"    .crc32 = 0x{gains.crc32:08X}u,")
    lines.append("};")
    return "\n".join(lines) + "\n"


def render_c(artifact: Artifact) -> dict[str, str]:
    """Render the gains header and source for ``artifact``.

    Returns
    -------
    dict of str to str
        ``{"gl_gains.h": text, "gl_gains.c": text}``; identical for the same artifact.
    """
    gains = gain_set(artifact)
    return {HEADER_NAME: render_header(artifact, gains), SOURCE_NAME: render_source(artifact, gains)}


def export(artifact: Artifact, *, out_dir: str | Path) -> list[Path]:
    """Render the C files for ``artifact`` and publish them atomically into ``out_dir``."""
    return publish_files(out_dir, render_c(artifact))
