"""The record of a step: one description per law, rendered as the C the firmware writes it with and the numpy dtype
that reads it back.

Every stream that carries a law's steps carries this record: the Cortex-M image's replay and PIL streams over
semihosting (``gl_in.bin`` / ``gl_out.bin``), the host library's block and single-step calls (ctypes) and the host
executable's ``step`` lines. A sample goes in as ``{tag, y (p), r (q), s (e)}`` (:func:`sample_layout`, every law);
a command comes out as ``{status, flags, sat, u (m)}`` followed by the law's own fields (:func:`layout`): the float32
loop's estimate and integrators, the integer law's words, masks and state, the scheduled law's sigma and state.

The export renders both into ``gl_record_<law>.h`` (:func:`c_header`; one per law it builds): the structs,
``gl_law_record()`` that fills a record from the law and its answer, and ``GL_LAW_RECORD_FIELDS`` (each field's name,
kind and the elements that mean something) for a printer. :meth:`Layout.dtype` reads the same bytes;
:meth:`Layout.from_text` the host executable's lines. An array whose length is 0 (no integrators, no external
signals) is stored with one element, unused.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .law_c import c_name, externals, law_name

#: Kinds of a record's words: C type, numpy type, the printer's format letter.
KINDS = {"i32": ("int32_t", "<i4", "i"), "u32": ("uint32_t", "<u4", "u"), "f32": ("float", "<f4", "f")}
#: Tags of a sample (``gl_law_sample_t::tag``): what the image does with it.
TAG_STEP, TAG_IDLE, TAG_STAGE, TAG_RESET = 0, 1, 2, 3


@dataclass(frozen=True)
class Field:
    """One field of a record.

    ``used`` elements mean something (0 for an integrator array without integrators); the field stores
    ``max(used, 1)``, or is a scalar when ``array`` is False. ``fill`` is the C that gives element ``i``
    (``law``: the ``gl_law_t``, ``out``: the ``gl_law_out_t``), or, starting with ``=``, a statement that fills the
    whole field (``rec`` is the record).
    """

    name: str
    kind: str
    used: int = 1
    array: bool = False
    fill: str = ""
    doc: str = ""

    @property
    def stored(self) -> int:
        """Elements stored (arrays: at least one)."""
        return max(self.used, 1) if self.array else 1


@dataclass(frozen=True)
class Layout:
    """A record: its C type name and fields in order."""

    c_name: str
    fields: tuple[Field, ...]

    @property
    def dtype(self) -> np.dtype:
        """The numpy dtype of one record (little-endian, packed: every word is 4 bytes)."""
        return np.dtype(
            [(f.name, KINDS[f.kind][1], (f.stored,)) if f.array else (f.name, KINDS[f.kind][1]) for f in self.fields]
        )

    @property
    def words(self) -> int:
        """32-bit words of one record."""
        return sum(f.stored for f in self.fields)

    def from_text(self, values: list[list[str]]) -> np.ndarray:
        """Records from the host executable's ``step`` lines (each split into words, ``step`` removed): every field's
        used elements in order, integers in decimal, floats round-trip."""
        out = np.zeros(len(values), dtype=self.dtype)
        width = sum(f.used for f in self.fields)
        for k, words in enumerate(values):
            if len(words) != width:
                raise ValueError(f"a step line holds {len(words)} numbers, not {width}")
            at = 0
            for f in self.fields:
                cast = float if f.kind == "f32" else int
                part = [cast(w) for w in words[at : at + f.used]]
                at += f.used
                if f.array:
                    out[f.name][k, : f.used] = part
                else:
                    out[f.name][k] = part[0]
        return out

    def c_struct(self, doc: str) -> str:
        """The C typedef of the record and the assertion that it is packed."""
        lines = [f"/** {doc} */", f"typedef struct {self.c_name} {{"]
        for f in self.fields:
            ctype = KINDS[f.kind][0]
            decl = f"{ctype} {f.name}[{f.stored}];" if f.array else f"{ctype} {f.name};"
            lines.append(f"    {decl:<28} /**< {f.doc} */" if f.doc else f"    {decl}")
        lines.append(f"}} {self.c_name}_t;")
        lines.append(f'_Static_assert(sizeof({self.c_name}_t) == {4 * self.words}u, "{self.c_name}_t must be packed");')
        return "\n".join(lines)


def dims(artifact) -> tuple[int, int, int, int, int]:
    """``n, m, p, q, e`` of ``artifact``'s law (e: the external scheduling signals a sample carries)."""
    a = artifact
    return a.n, a.m, a.p, a.q, len(externals(a))


def sample_layout(artifact) -> Layout:
    """One sample in (every law): its tag (:data:`TAG_STEP` ...), y, r and the external scheduling signals s."""
    _, _, p, q, e = dims(artifact)
    return Layout(
        "gl_law_sample",
        (
            Field("tag", "u32", doc="TAG_STEP 0, TAG_IDLE 1, TAG_STAGE 2 (gl_stageK.bin), TAG_RESET 3"),
            Field("y", "f32", p, True, doc="samples, absolute"),
            Field("r", "f32", q, True, doc="references"),
            Field("s", "f32", e, True, doc="external scheduling signals"),
        ),
    )


def samples(artifact, Y, R=None, S=None, *, tags: np.ndarray | None = None) -> np.ndarray:
    """The samples ``Y`` (N, p), ``R`` (N, q), ``S`` (N, e) as records in (:func:`sample_layout`; float32, missing
    ones zero; each a step unless ``tags`` says otherwise)."""
    _, _, p, q, e = dims(artifact)
    with np.errstate(over="ignore"):  # beyond float32 is inf, as on the wire: the law's fault path answers it
        Y = np.asarray(Y).reshape(-1, p)
        out = np.zeros(Y.shape[0], dtype=sample_layout(artifact).dtype)
        out["y"] = Y  # cast to float32 in place, as astype would
        for name, values, width in (("r", R, q), ("s", S, e)):
            if values is not None and width:
                out[name][:, :width] = np.asarray(values).reshape(-1, width)
    if tags is not None:
        out["tag"] = tags
    return out


def column(records: np.ndarray, name: str) -> np.ndarray:
    """Field ``name`` of ``records`` as its own C-contiguous array (a copy): the field's bytes are copied as one
    opaque item per record, then seen as its values (numpy's copy of a strided 2-D field is several times slower)."""
    base, offset = records.dtype.fields[name][:2]
    value, shape = base.subdtype or (base, ())
    raw = np.array(records.getfield(np.dtype((np.void, base.itemsize)), offset))
    return raw.view(value).reshape(records.shape + shape)


def _common(m: int) -> tuple[Field, ...]:
    return (
        Field("status", "i32", fill="out->status", doc="gl_status_t of the call"),
        Field("flags", "u32", fill="out->flags", doc="GL_FLAG_* (gl_flags.h)"),
        Field("sat", "u32", fill="out->sat", doc="bit j: input j clamped"),
        Field("u", "f32", m, True, fill="out->u[i]", doc="commands"),
    )


def layout(artifact, *, law: str | None = None) -> Layout:
    """The command record of the law ``artifact`` runs, or of ``law`` (another its export builds, e.g. the float32
    baseline of an integer law: :func:`gainlink.shipping.law_c.buildable`) (module docstring)."""
    n, m, p, q, _ = dims(artifact)
    law = law or law_name(artifact)
    if law == "lq/float32":
        own: tuple[Field, ...] = (
            Field("xh", "f32", n, True, fill="law->xh[i]", doc="estimate after the step"),
            Field("z", "f32", q, True, fill="law->z[i]", doc="integrators after the step"),
        )
    elif law in ("lq/q31", "lq/q15"):
        own = (
            Field("U", "i32", m, True, fill="out->word[i]", doc="command words"),
            Field("V", "i32", m, True, fill="law->loop.v[i]", doc="unsaturated commands (v formats)"),
            Field("XH", "i32", n, True, fill="law->loop.sig[GL_FX_SIG_XH + i]", doc="estimate after the step"),
            Field("Z", "i32", q, True, fill="law->loop.sig[GL_FX_SIG_Z + i]", doc="integrators after the step"),
            Field("clip", "u32", fill="law->loop.clip_mask", doc="bit k: sample k, bit p+j: reference j clipped"),
            Field("overflow", "u32", fill="law->loop.overflow_mask", doc="GL_FX_OVF_* that fired"),
        )
    elif law == "scheduled/float32":
        own = (
            Field("sigma", "f32", fill="out->sigma", doc="the sigma the step used"),
            Field(
                "state",
                "f32",
                n + m + p + q + 3,
                True,
                fill="=gl_sched_state(&law->loop, rec->state);",
                doc="gl_sched_state() after the step",
            ),
        )
    elif law == "mpc/float32":
        b = artifact.mpc
        own = (
            Field("iters", "u32", fill="law->loop.iterations", doc="ADMM iterations of the step (0: refused)"),
            Field(
                "state",
                "f32",
                n + q + 2 * b.horizon * (m + b.nc),
                True,
                fill="=gl_mpc_state(&law->loop, rec->state);",
                doc="gl_mpc_state() after the step: xh, z, the warm start",
            ),
        )
    else:
        raise ValueError(f"no record for the {law} law")
    return Layout("gl_law_record", _common(m) + own)


def _fill_lines(f: Field) -> list[str]:
    if f.fill.startswith("="):
        return [f"    {f.fill[1:]}"]
    if not f.array:
        return [f"    rec->{f.name} = {f.fill};"]
    if f.used == 0:
        return [f"    rec->{f.name}[0] = 0;"]
    return [f"    for (unsigned i = 0; i < {f.used}u; ++i) {{", f"        rec->{f.name}[i] = {f.fill};", "    }"]


def header_name(law: str) -> str:
    """The record header of ``law`` in an export (gl_law.h includes the one of the law it builds)."""
    return f"gl_record_{c_name(law)}.h"


def c_header(artifact, *, law: str, banner: str) -> str:
    """Text of the record header of ``law`` (:func:`header_name`; included by gl_law.h once it has declared
    ``gl_law_t`` and ``gl_law_out_t``)."""
    sample, record = sample_layout(artifact), layout(artifact, law=law)
    fields = " ".join(f"X({f.name}, '{KINDS[f.kind][2]}', {f.used if f.array else 1})" for f in record.fields)
    used = {f.name: f.used for f in sample.fields if f.array}
    body = [line for f in record.fields for line in _fill_lines(f)]
    return "\n".join(
        [
            banner.rstrip("\n"),
            "/**",
            f" * @file {header_name(law)}",
            f" * @brief The record of a step of the {law} law for these dimensions: one sample in, one",
            " *        answer out (gainlink.shipping.records: the replay/PIL streams, host bindings, executable).",
            " */",
            f"#ifndef GL_RECORD_{c_name(law).upper()}_H",
            f"#define GL_RECORD_{c_name(law).upper()}_H",
            "",
            "#include <stdint.h>",
            "",
            sample.c_struct("One sample in: what the image does with it, and its values."),
            "",
            f"#define GL_LAW_SAMPLE_R_USED {used['r']} /**< references a sample carries */",
            f"#define GL_LAW_SAMPLE_S_USED {used['s']} /**< external signals a sample carries */",
            "#define GL_LAW_TAG_STEP 0u",
            "#define GL_LAW_TAG_IDLE 1u",
            "#define GL_LAW_TAG_STAGE 2u",
            "#define GL_LAW_TAG_RESET 3u",
            "",
            record.c_struct("One answer out: the common part, then the law's own fields."),
            "",
            "/** Each field of gl_law_record_t for a printer: X(name, kind 'i' int32 / 'u' uint32 / 'f' float,",
            " *  elements that mean something). */",
            f"#define GL_LAW_RECORD_FIELDS(X) {fields}",
            "",
            "/**",
            " * @brief Fill a record from the law after a call and that call's answer.",
            " * @param[in] law The law. @param[in] out Its answer. @param[out] rec The record.",
            " */",
            "static inline void gl_law_record(const gl_law_t *law, const gl_law_out_t *out, gl_law_record_t *rec)",
            "{",
            "    (void)law;",
            *body,
            "}",
            "",
            f"#endif /* GL_RECORD_{c_name(law).upper()}_H */",
            "",
        ]
    )
