"""The fields of the C gain set ``gl_gains_t``: one table, and everything that must agree with it.

:data:`FIELDS` lists every field of ``gl_gains_t`` in declaration order: its name, C element type, dimensions
(as the firmware's size macros, e.g. ``("GL_M", "GL_N")``), role and documentation. :data:`GAINS` (a
:class:`Layout` of that table) makes from it

- the C struct (:meth:`Layout.render_header`, written as ``gl_gains_layout.h`` beside the other generated
  headers and included by ``gainlink/gl_loop.h``), with X-macros the firmware uses for the structure check, the
  CRC's header words and the MAVLink parameter table, and ``_Static_assert``s that the compiler's offsets are
  the ones below;
- the ctypes mirror (:meth:`Layout.ctypes_struct`) the host library is driven through;
- the bytes of a gain set as the C struct holds them (:meth:`Layout.pack`) and its CRC-32 (:meth:`Layout.crc32`).

Roles: ``structure`` fields (uint32) must equal a compiled macro (``compiled``) or the set is refused; ``number``
fields are the gains; the one ``checksum`` field is the CRC-32 (zlib's) of every field before it, each element
little-endian in declaration order. ``param`` is the MAVLink parameter id of a structure field, or the id stem of
a number (``GL_<stem>_<i>_<j>``; empty: not a parameter).

Extending it (the scheduled and fixed-point laws): a field of another element type names it in
:data:`ELEMENT_TYPES` (``int32_t``, ``int16_t``, ``int8_t`` shift counts); a new extent (the number of schedule
points) is a new entry of :data:`DIMENSIONS` (and an attribute of :class:`Shape`); a field meaningful only in some
builds gets a :data:`CONDITIONS` entry. A signature of the number formats is one more ``structure`` field with its
compiled macro: the check then refuses a set of other formats, the CRC covers it and MAVLink shows it read-only.
A law with a struct of its own is another :class:`Layout`. ``tests/test_gains_layout.py`` builds such an extended
table and proves the compiler lays it out as :meth:`Layout.offsets` says.

This module imports nothing else of gainlink: the C, the binding and the packers all read it.
"""

from __future__ import annotations

import ctypes
import functools
import zlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ElementType:
    """A C element type: its C name, ctypes type and little-endian numpy dtype."""

    c: str
    ctype: type
    dtype: str


ELEMENT_TYPES: dict[str, ElementType] = {
    t.c: t
    for t in (
        ElementType("float", ctypes.c_float, "<f4"),
        ElementType("uint32_t", ctypes.c_uint32, "<u4"),
        ElementType("int32_t", ctypes.c_int32, "<i4"),
        ElementType("int16_t", ctypes.c_int16, "<i2"),
        ElementType("int8_t", ctypes.c_int8, "i1"),
    )
}


@dataclass(frozen=True)
class Shape:
    """The compiled structure of a gain set: one attribute per ``structure`` field of :data:`FIELDS`, in order.

    The dimensions and the observer / anti-windup codes (``gl_gains_t`` checks them against the macros). A law
    with more structure (schedule points, a format signature) adds attributes here as it adds fields.
    """

    n: int
    m: int
    p: int
    q: int
    observer_form: int
    anti_windup: int


@dataclass(frozen=True)
class Dimension:
    """One array extent: its C macro, its value for a shape, and what of it is a parameter.

    ``exposed``/``exposed_size`` are the extent a user sees (``GL_Q`` for integrator arrays, which are stored
    with at least one row because C has no zero-length arrays).
    """

    size: Callable[[Shape], int]
    exposed: str
    exposed_size: Callable[[Shape], int]


DIMENSIONS: dict[str, Dimension] = {
    "GL_N": Dimension(lambda s: s.n, "GL_N", lambda s: s.n),
    "GL_M": Dimension(lambda s: s.m, "GL_M", lambda s: s.m),
    "GL_P": Dimension(lambda s: s.p, "GL_P", lambda s: s.p),
    "GL_QA": Dimension(lambda s: max(s.q, 1), "GL_Q", lambda s: s.q),
}


@dataclass(frozen=True)
class Condition:
    """When a field is meaningful (else it is zero and not a parameter): as C over the macros, and in Python."""

    c: str
    holds: Callable[[Shape], bool]


CONDITIONS: dict[str, Condition] = {
    "current_form": Condition("(GL_OBSERVER_FORM == GL_FORM_CURRENT)", lambda s: s.observer_form == 1),
}


@dataclass(frozen=True)
class Field:
    """One field of ``gl_gains_t`` (see the module docstring for the roles)."""

    name: str
    element: str
    dims: tuple[str, ...]
    role: str
    doc: str
    param: str = ""
    compiled: str = ""
    when: str = ""

    @property
    def type(self) -> ElementType:
        """The element type."""
        return ELEMENT_TYPES[self.element]

    def shape(self, shape: Shape) -> tuple[int, ...]:
        """The array shape stored in C (``()`` for a scalar)."""
        return tuple(DIMENSIONS[d].size(shape) for d in self.dims)

    def exposed_shape(self, shape: Shape) -> tuple[int, ...]:
        """The part a user sees and sets (empty when its condition does not hold)."""
        if self.when and not CONDITIONS[self.when].holds(shape):
            return tuple(0 for _ in self.dims) or (0,)
        return tuple(DIMENSIONS[d].exposed_size(shape) for d in self.dims)


def _number(name: str, dims: tuple[str, ...], doc: str, *, when: str = "") -> Field:
    return Field(name, "float", dims, "number", doc, param=name.upper().replace("_", ""), when=when)


def _structure(name: str, compiled: str, param: str, doc: str) -> Field:
    return Field(name, "uint32_t", (), "structure", doc, param=param, compiled=compiled)


FIELDS: tuple[Field, ...] = (
    _structure("n", "GL_N", "GL_DIM_N", "States; must equal GL_N."),
    _structure("m", "GL_M", "GL_DIM_M", "Inputs; must equal GL_M."),
    _structure("p", "GL_P", "GL_DIM_P", "Outputs; must equal GL_P."),
    _structure("q", "GL_Q", "GL_DIM_Q", "Integrators; must equal GL_Q."),
    _structure("observer_form", "GL_OBSERVER_FORM", "GL_FORM", "GL_FORM_*; must equal GL_OBSERVER_FORM."),
    _structure("anti_windup", "GL_ANTI_WINDUP", "GL_AW", "GL_AW_*; must equal GL_ANTI_WINDUP."),
    _number("Ts", (), "Sample time [s], > 0."),
    _number("Ad", ("GL_N", "GL_N"), "Discrete state matrix."),
    _number("Bd", ("GL_N", "GL_M"), "Discrete input matrix."),
    _number("Cd", ("GL_P", "GL_N"), "Output matrix."),
    _number("Dd", ("GL_P", "GL_M"), "Feed-through matrix (zero in the current form)."),
    _number("K", ("GL_M", "GL_N"), "State feedback gain."),
    _number("L", ("GL_N", "GL_P"), "Observer (predictor) gain; L = Ad M in the current form."),
    _number("M", ("GL_N", "GL_P"), "Current-estimator filter gain (zero in the predictor form).", when="current_form"),
    _number("Ci", ("GL_QA", "GL_P"), "Tracked-output selector."),
    _number("Ki", ("GL_M", "GL_QA"), "Integral gain."),
    _number("Kaw", ("GL_QA", "GL_M"), "Back-calculation anti-windup gain."),
    _number("u_min", ("GL_M",), "Lower command limits."),
    _number("u_max", ("GL_M",), "Upper command limits."),
    _number("xh0", ("GL_N",), "Initial estimate (gl_loop_reset())."),
    _number("z0", ("GL_QA",), "Initial integrator (gl_loop_reset())."),
    _number("u_op", ("GL_M",), "Operating point: absolute command there."),
    _number("y_op", ("GL_P",), "Operating point: absolute measurement there."),
    Field("crc32", "uint32_t", (), "checksum", "CRC-32 (IEEE 802.3, as zlib.crc32) of the payload."),
)

STRUCT_DOC = """\
@brief One complete gain set, as in the artifact (float32). May live in flash (const).

Generated from the field table gainlink.shipping.gains_layout: the C struct, the Python ctypes mirror and the
packers all come from it. Matrices are row-major `[rows][cols]`. Integrator-sized arrays have GL_QA
rows/cols and are all zero when GL_Q == 0. `M` is all zero in the predictor form. `u_op`, `y_op` are zero
for a plant about the origin (an artifact without an operating point). `crc32` covers every other field,
serialised as little-endian: n, m, p, q, observer_form, anti_windup as uint32, then every float in
declaration order (see gl_gains_crc32())."""

_ROLES = ("structure", "number", "checksum")


@dataclass(frozen=True)
class Layout:
    """A C struct described field by field, and what is made from the description.

    Parameters
    ----------
    struct : str
        The C struct tag; the typedef is ``<struct>_t``, the header ``<struct>_layout.h`` and the macros
        ``<STRUCT>_STRUCTURE``, ``<STRUCT>_FLOATS``, ``<STRUCT>_PARAMS``.
    fields : tuple of Field
        In declaration order: the structure fields, the numbers (their floats contiguous), then one checksum.
    doc : str
        Doxygen text of the struct.
    """

    struct: str
    fields: tuple[Field, ...]
    doc: str

    def __post_init__(self) -> None:
        roles = [f.role for f in self.fields]
        if roles != sorted(roles, key=_ROLES.index) or roles.count("checksum") != 1 or roles[-1] != "checksum":
            raise ValueError(f"{self.struct}_t fields must be the structure fields, the numbers, then the checksum")
        for f in self.fields:
            if f.element not in ELEMENT_TYPES or any(d not in DIMENSIONS for d in f.dims):
                raise ValueError(f"{self.struct}_t.{f.name}: unknown element type or dimension")
            if f.when and f.when not in CONDITIONS:
                raise ValueError(f"{self.struct}_t.{f.name}: unknown condition {f.when!r}")
            if f.role != "number" and f.element != "uint32_t":
                raise ValueError(f"{self.struct}_t.{f.name}: structure and checksum fields are uint32_t")
        floats = [f for f in self.numbers if f.element == "float"]
        first = self.numbers.index(floats[0]) if floats else 0
        if self.numbers[first : first + len(floats)] != tuple(floats):
            raise ValueError(f"the float numbers of {self.struct}_t must be contiguous")

    @property
    def header_name(self) -> str:
        """File name of the generated header."""
        return f"{self.struct}_layout.h"

    @property
    def structure(self) -> tuple[Field, ...]:
        """The structure fields, in order."""
        return tuple(f for f in self.fields if f.role == "structure")

    @property
    def numbers(self) -> tuple[Field, ...]:
        """The number fields (the gains), in order."""
        return tuple(f for f in self.fields if f.role == "number")

    @property
    def checksum(self) -> Field:
        """The checksum field."""
        return self.fields[-1]

    def structure_values(self, shape: Shape) -> tuple[int, ...]:
        """The structure fields' values for ``shape``, in declaration order."""
        return tuple(int(getattr(shape, f.name)) for f in self.structure)

    def ctypes_struct(self, shape: Shape) -> type[ctypes.Structure]:
        """A ctypes mirror of the struct for ``shape`` (one class per set of extents).

        ctypes keeps the POINTER type of every Structure class it meets forever, so a class per loop would leak
        one per run: classes are cached by extents.
        """
        used = sorted({d for f in self.fields for d in f.dims})
        return _struct_for(self, tuple((d, DIMENSIONS[d].size(shape)) for d in used))

    def offsets(self, shape: Shape) -> dict[str, tuple[int, int]]:
        """``name -> (offset, size)`` in bytes of every field as the ctypes mirror (so the C compiler) lays it out."""
        t = self.ctypes_struct(shape)
        return {f.name: (getattr(t, f.name).offset, getattr(t, f.name).size) for f in self.fields}

    def _values_in_order(self, shape: Shape, values: Mapping[str, object]) -> list[tuple[Field, np.ndarray]]:
        """Each field with its value as an array of its C shape and element type (missing numbers are zero)."""
        given = dict(zip((f.name for f in self.structure), self.structure_values(shape), strict=True))
        given.update(values)
        out = []
        for f in self.fields:
            v = given.get(f.name)
            arr = np.zeros(f.shape(shape), dtype=f.type.dtype) if v is None else np.asarray(v, dtype=f.type.dtype)
            out.append((f, arr.reshape(f.shape(shape))))
        return out

    def crc32(self, shape: Shape, values: Mapping[str, object]) -> int:
        """CRC-32 of a set's payload: every field but the checksum, each element little-endian, in order.

        Parameters
        ----------
        shape : Shape
            The compiled structure (also the structure fields' values unless ``values`` overrides them).
        values : mapping of str to array_like
            Number fields by name, in their C shape (missing ones count as zero).

        Returns
        -------
        int
            What ``gl_gains_crc32`` computes for the same set.
        """
        blob = b"".join(a.tobytes() for f, a in self._values_in_order(shape, values) if f.role != "checksum")
        return zlib.crc32(blob) & 0xFFFFFFFF

    def pack(self, shape: Shape, values: Mapping[str, object]) -> bytes:
        """The bytes of the struct as the C compiler lays it out on a little-endian target (padding zero).

        ``values`` holds the number fields by name and, optionally, the checksum (default: the set's own
        :meth:`crc32`) and structure fields (default: ``shape``'s).
        """
        values = dict(values)
        values.setdefault(self.checksum.name, self.crc32(shape, values))
        struct_type = self.ctypes_struct(shape)
        out = struct_type()
        for f, arr in self._values_in_order(shape, values):
            data = np.ascontiguousarray(arr).tobytes()
            ctypes.memmove(ctypes.addressof(out) + getattr(struct_type, f.name).offset, data, len(data))
        return bytes(out)

    def render_header(self, *, banner: str, shape: Shape | None = None) -> str:
        """Text of the generated header: the struct, its X-macros and layout checks.

        Parameters
        ----------
        banner : str
            The ``DO NOT EDIT`` line (with its newline) naming what it was generated from.
        shape : Shape, optional
            The artifact's structure: adds ``_Static_assert``s that every field's offset and size are those of
            :meth:`offsets` (the ctypes mirror and :meth:`pack` are then proved to match the compiler in every
            build, host and target).

        Returns
        -------
        str
            The header; ``gainlink/gl_loop.h`` includes ``gl_gains_layout.h`` after the size macros.
        """
        macro = self.struct.upper()
        guard = f"{macro}_LAYOUT_H"
        lines = [
            banner.rstrip("\n"),
            "/**",
            f" * @file {self.header_name}",
            f" * @brief The fields of ::{self.struct}_t, from the table in gainlink.shipping.gains_layout.",
            " */",
            f"#ifndef {guard}",
            f"#define {guard}",
            "",
            "#include <stddef.h>",
            "#include <stdint.h>",
            "",
            *self._struct_lines(),
            *self._structure_macros(macro),
            *self._number_macros(macro),
            *(self._layout_asserts(shape) if shape is not None else []),
            f"#endif /* {guard} */",
            "",
        ]
        return "\n".join(lines)

    def _struct_lines(self) -> list[str]:
        lines = [
            "/**",
            *[f" * {ln}".rstrip() for ln in self.doc.splitlines()],
            " */",
            f"typedef struct {self.struct} {{",
        ]
        for f in self.fields:
            decl = f"{f.type.c} {f.name}" + "".join(f"[{d}]" for d in f.dims) + ";"
            lines.append(f"    {decl:<26} /**< {f.doc} */")
        return [*lines, f"}} {self.struct}_t;", ""]

    def _structure_macros(self, macro: str) -> list[str]:
        entries = [f'X({f.name}, {f.compiled}, "{f.param}")' for f in self.structure]
        return [
            "/** Number of structure fields (uint32, first in the struct, checked against the compiled macros). */",
            f"#define {macro}_STRUCTURE_FIELDS {len(entries)}",
            "",
            *_x_macro(f"{macro}_STRUCTURE", "The structure fields: X(field, compiled macro, MAVLink id).", entries),
        ]

    def _number_macros(self, macro: str) -> list[str]:
        floats = [f for f in self.numbers if f.element == "float"]
        if not floats:
            return []
        first, last = floats[0].name, floats[-1].name
        count = " + ".join(" * ".join(f.dims) if f.dims else "1" for f in floats)
        params = [_param_entry(f) for f in self.numbers if f.param]
        member = f"sizeof((({self.struct}_t *)0)->{last})"
        return [
            f"/** Number of floats from `{first}` through `{last}` (contiguous): the float numbers of the set. */",
            f"#define {macro}_FLOATS \\",
            *_wrapped(f"({count})", indent="    ", suffix=" \\"),
            "",
            *(
                _x_macro(
                    f"{macro}_PARAMS",
                    "The numbers that are MAVLink parameters: X(field, id stem, rank, rows, cols, row stride).",
                    params,
                )
                if params
                else []
            ),
            f"_Static_assert(offsetof({self.struct}_t, {last}) + {member} - offsetof({self.struct}_t, {first}) ==",
            f"                   sizeof(float) * ({macro}_FLOATS),",
            f'               "{self.struct}_t float numbers must be contiguous (no padding)");',
            "",
        ]

    def _layout_asserts(self, shape: Shape) -> list[str]:
        """``_Static_assert``s that the compiler lays the struct out as the ctypes mirror does for ``shape``."""
        t = f"{self.struct}_t"
        lines = [
            "/* The layout gainlink.shipping.gains_layout computes for this artifact (ctypes mirror and packers). */",
            f"_Static_assert(sizeof({t}) == {ctypes.sizeof(self.ctypes_struct(shape))}u, "
            f'"{t}: size differs from gainlink.shipping.gains_layout");',
        ]
        for name, (offset, size) in self.offsets(shape).items():
            lines.append(
                f"_Static_assert(offsetof({t}, {name}) == {offset}u && sizeof((({t} *)0)->{name}) == {size}u,\n"
                f'               "{t}.{name}: layout differs from gainlink.shipping.gains_layout");'
            )
        return [*lines, ""]


@functools.cache
def _struct_for(layout: Layout, extents: tuple[tuple[str, int], ...]) -> type[ctypes.Structure]:
    size = dict(extents)

    def c_type(f: Field) -> type:
        t = f.type.ctype
        for d in reversed(f.dims):
            t = t * size[d]
        return t

    name = "".join(part.capitalize() for part in layout.struct.split("_"))
    return type(name, (ctypes.Structure,), {"_fields_": [(f.name, c_type(f)) for f in layout.fields]})


def _param_entry(f: Field) -> str:
    """``X(field, "STEM", rank, rows, cols, row stride)`` of a number that is a MAVLink parameter."""
    if len(f.dims) > 2:
        raise ValueError(f"{f.name}: MAVLink ids name at most two indices")
    exposed = [DIMENSIONS[d].exposed for d in f.dims] + ["1"] * (2 - len(f.dims))
    if f.when:
        exposed[0] = f"({CONDITIONS[f.when].c} ? {exposed[0]} : 0)"
    stride = f.dims[1] if len(f.dims) == 2 else "1"
    return f'X({f.name}, "{f.param}", {len(f.dims)}, {exposed[0]}, {exposed[1]}, {stride})'


def _wrapped(text: str, *, indent: str, suffix: str, width: int = 110) -> list[str]:
    """``text`` broken at spaces into lines of at most ``width``; every line but the last ends with ``suffix``."""
    lines, line = [], indent
    for word in text.split(" "):
        if len(line) + len(word) + 1 > width and line.strip():
            lines.append(line.rstrip() + suffix)
            line = indent
        line += word + " "
    return [*lines, line.rstrip()]


def _x_macro(name: str, doc: str, entries: list[str]) -> list[str]:
    lines = [f"/** {doc} */", f"#define {name}(X) \\"]
    lines += [f"    {e} \\" for e in entries[:-1]] + [f"    {entries[-1]}", ""]
    return lines


#: ``gl_gains_t``, the gain set of the float32 law.
GAINS = Layout("gl_gains", FIELDS, STRUCT_DOC)
HEADER_NAME = GAINS.header_name
STRUCTURE = GAINS.structure
NUMBERS = GAINS.numbers
CHECKSUM = GAINS.checksum
