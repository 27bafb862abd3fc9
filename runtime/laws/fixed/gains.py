"""The integers a fixed-point law runs: per-signal formats, one accumulator format per sum of products, and each
coefficient quantised in its own format, aligned to the sum's accumulator by an exact left shift.

Each output of the law (each command ``v_i``, integrator ``z_j`` and estimate ``xh_i``) is one sum of products
``sum_k c_k s_k`` over signals ``s_k`` with their own formats ``f_k``. Coefficient ``c_k`` is stored as a
mantissa ``C_k`` of the coefficient word in its own best format ``fc_k`` (the most fractional bits that still fit:
every coefficient keeps the word's full relative precision, whatever the signals' scales) and a left shift
``E_k = A - fc_k - f_k >= 0`` that brings its product into the sum's accumulator format ``A``:
``acc = sum_k (C_k S_k) << E_k``, exact, then one rounding shift ``A - f_out`` into the output's format.

``A`` is the finest product format of the row (``max_k fc_k + f_k``), capped so that the accumulator cannot
overflow (the certificate sets the cap from the signals' bounds); a coefficient whose own format is finer than the
cap allows loses those bits (it is tiny next to the row's largest term).

``Ts`` appears twice in an integrator's row (with the reference and with the sample, whose formats differ); it is
one mantissa with two shifts, so both products mean the same real ``Ts``. The limits are rounded inward and
``u_op`` to nearest, both in the coarser of the command's two formats (``v``, 32-bit, and ``u``, the command
word), so that they are exact in both; the command's format must then hold the deviation of every command within
the limits from that ``u_op`` (:func:`deviation_fits`; the certificate coarsens it until it does).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...proof.derived_law import DerivedLaw
from .qformat import WORDS, Format, format_for, quantise, quantise_inward, real


@dataclass(frozen=True)
class SignalFormats:
    """The format of every signal of the law: samples ``y`` (p) and references ``r`` (q) in the sample word,
    commands ``u`` (m) in the command word, the unsaturated command ``v`` (m), estimate ``xh`` (n) and integrator
    ``z`` (q) in the 32-bit state word."""

    numeric: str
    y: tuple[Format, ...]
    r: tuple[Format, ...]
    u: tuple[Format, ...]
    v: tuple[Format, ...]
    xh: tuple[Format, ...]
    z: tuple[Format, ...]

    def frac(self, name: str) -> np.ndarray:
        """The fractional bits of signal group ``name`` as an int64 array."""
        return np.array([f.frac for f in getattr(self, name)], dtype=np.int64)

    @property
    def coefficient_word(self) -> int:
        return WORDS[self.numeric]["coefficient"]

    def to_dict(self) -> dict:
        """JSON form: the fractional bits per signal group."""
        return {name: [f.frac for f in getattr(self, name)] for name in ("y", "r", "u", "v", "xh", "z")}

    @classmethod
    def from_dict(cls, numeric: str, fracs: dict) -> SignalFormats:
        """Rebuild from :meth:`to_dict`."""
        words = WORDS[numeric]
        role = {"y": "sample", "r": "sample", "u": "command", "v": "state", "xh": "state", "z": "state"}
        return cls(numeric, **{k: tuple(Format(words[role[k]], int(f)) for f in fracs[k]) for k in role})


@dataclass(frozen=True)
class Block:
    """Coefficients of one block of a sum of products: mantissas ``C`` (fit the coefficient word) and left shifts
    ``E`` (>= 0), both int64 arrays of the block's shape (outputs x signals)."""

    C: np.ndarray
    E: np.ndarray

    def dot(self, S: np.ndarray) -> np.ndarray:
        """``sum_k (C[i,k] S[k]) << E[i,k]`` per row, in int64 (exact when no partial sum leaves 63 bits)."""
        if self.C.size == 0:
            return np.zeros(self.C.shape[0], dtype=np.int64)
        return np.left_shift(self.C * np.asarray(S, dtype=np.int64)[None, :], self.E).sum(axis=1)

    def magnitude(self, S: np.ndarray) -> np.ndarray:
        """``sum_k |C[i,k]| 2**E[i,k] |S[k]|`` per row, in float64 (a partial sums' bound)."""
        if self.C.size == 0:
            return np.zeros(self.C.shape[0])
        return (np.abs(self.C).astype(np.float64) * np.ldexp(1.0, self.E)) @ np.abs(np.asarray(S, dtype=np.float64))

    def value(self, acc: np.ndarray, f_sig: np.ndarray) -> np.ndarray:
        """The real coefficients: ``C 2**-(A - E - f)`` with the rows' accumulator formats ``acc``."""
        return real(self.C, acc[:, None] - self.E - f_sig[None, :])


@dataclass(frozen=True)
class FixedGains:
    """What the C of a fixed-point law holds: coefficient blocks, accumulator formats and shifts, the operating
    point, limits and initial state as integers, and ``ideal``, the real values of all of them
    (:class:`~gainlink.proof.derived_law.DerivedLaw`). ``TR`` is diagonal (q x q): each integrator's gain on its
    own reference."""

    formats: SignalFormats
    acc_v: np.ndarray  # (m,) accumulator fractional bits of each command's sum
    acc_z: np.ndarray  # (q,)
    acc_x: np.ndarray  # (n,)
    KX: Block
    KY: Block
    KZ: Block
    TR: Block
    TY: Block
    KAW: Block
    F: Block
    G: Block
    LY: Block
    YOP: np.ndarray  # y_op in the sample formats
    UOP_V: np.ndarray  # u_op in the v formats
    UOP_U: np.ndarray  # u_op in the command formats
    LO_V: np.ndarray
    HI_V: np.ndarray
    LO_U: np.ndarray
    HI_U: np.ndarray
    XH0: np.ndarray
    Z0: np.ndarray
    ideal: DerivedLaw

    @property
    def shift_v(self) -> np.ndarray:
        """Rounding shift of each command's accumulator into the v format."""
        return self.acc_v - self.formats.frac("v")

    @property
    def shift_z(self) -> np.ndarray:
        return self.acc_z - self.formats.frac("z")

    @property
    def shift_x(self) -> np.ndarray:
        return self.acc_x - self.formats.frac("xh")

    @property
    def shift_u(self) -> np.ndarray:
        """Rounding shift from the v format to the command format (negative: an exact left shift)."""
        return self.formats.frac("v") - self.formats.frac("u")

    @property
    def U_SAFE(self) -> np.ndarray:
        """The safe command (``u_op`` clamped into the limits) in the command formats."""
        return np.minimum(np.maximum(self.UOP_U, self.LO_U), self.HI_U)

    def integers(self) -> dict:
        """Everything the C holds, as plain lists: each block's mantissas and left shifts (``KX`` and ``KX_shift``,
        ...), the rounding shifts per output, the operating point, limits, safe command and initial state as
        integers, and the samples' and commands' fractional bits (quantisation and scaling)."""
        out: dict = {}
        for name in ("KX", "KY", "KZ", "TR", "TY", "KAW", "F", "G", "LY"):
            block = getattr(self, name)
            out[name], out[f"{name}_shift"] = block.C.tolist(), block.E.tolist()
        for name in ("shift_v", "shift_z", "shift_x", "shift_u", "U_SAFE"):
            out[name] = getattr(self, name).tolist()
        for name in ("YOP", "UOP_V", "UOP_U", "LO_V", "HI_V", "LO_U", "HI_U", "XH0", "Z0"):
            out[name] = getattr(self, name).tolist()
        out["frac"] = {k: self.formats.frac(k).tolist() for k in ("y", "r", "u", "v", "xh", "z")}
        return out


BLOCKS = {"v": ("KX", "KY", "KZ"), "z": ("TR", "TY", "KAW"), "x": ("F", "G", "LY")}


def row_blocks(law: DerivedLaw, fm: SignalFormats) -> dict[str, list[tuple[str, np.ndarray, np.ndarray]]]:
    """Each sum's coefficient blocks ``(name, real coefficients, fractional bits of the signals)``."""
    fy, fr, fu, fv, fx, fz = (fm.frac(k) for k in ("y", "r", "u", "v", "xh", "z"))
    return {
        "v": [("KX", law.Kx, fx), ("KY", law.Ky, fy), ("KZ", law.Kz, fz)],
        "z": [("TR", np.diag(law.Tr), fr), ("TY", law.Ty, fy), ("KAW", law.Kaw, fv)],
        "x": [("F", law.F, fx), ("G", law.G, fu), ("LY", law.Ly, fy)],
    }


def _best_fracs(c: np.ndarray, word: int) -> np.ndarray:
    """Each coefficient's own best format (most fractional bits that fit ``word``); zeros get a huge value."""
    out = np.full(c.shape, np.iinfo(np.int32).max, dtype=np.int64)
    for idx, x in np.ndenumerate(c):
        if x != 0.0:
            out[idx] = format_for(abs(float(x)), word).frac
    return out


def finest_accumulator_fracs(law: DerivedLaw, fm: SignalFormats) -> dict[str, np.ndarray]:
    """For each sum, the finest product format of its coefficients at their best (a row without a non-zero
    coefficient gets its output's format: a shift of 0)."""
    word = fm.coefficient_word
    out_frac = {"v": fm.frac("v"), "z": fm.frac("z"), "x": fm.frac("xh")}
    result = {}
    for name, blocks in row_blocks(law, fm).items():
        rows = out_frac[name].size
        finest = np.full(rows, np.iinfo(np.int64).min, dtype=np.int64)
        for _, c, fsig in blocks:
            best = _best_fracs(c, word)
            product = np.where(c != 0.0, best + fsig[None, :], np.iinfo(np.int64).min)
            finest = np.maximum(finest, product.max(axis=1, initial=np.iinfo(np.int64).min))
        result[name] = np.where(finest == np.iinfo(np.int64).min, out_frac[name], finest)
    return result


def _block(c: np.ndarray, fsig: np.ndarray, acc: np.ndarray, word: int) -> Block:
    """Mantissas in each coefficient's best format, no finer than the accumulator allows, and their shifts."""
    fc = np.minimum(_best_fracs(c, word), acc[:, None] - fsig[None, :])
    C = quantise(c, fc)
    E = np.where(C != 0, acc[:, None] - fsig[None, :] - fc, 0)
    return Block(C=C, E=E.astype(np.int64))


def quantise_law(law: DerivedLaw, fm: SignalFormats, acc: dict[str, np.ndarray]) -> FixedGains:
    """The integers of ``law`` in formats ``fm`` with accumulator formats ``acc`` (keys v, z, x)."""
    word = fm.coefficient_word
    accs = {k: np.asarray(acc[k], dtype=np.int64) for k in ("v", "z", "x")}
    blocks = {}
    for row, items in row_blocks(law, fm).items():
        for name, c, fsig in items:
            blocks[name] = _block(c, fsig, accs[row], word)
    blocks["TR"], blocks["TY"] = _sampling_time(law, fm, accs["z"])
    fy, fx, fz = (fm.frac(k) for k in ("y", "xh", "z"))
    ints = {"YOP": quantise(law.y_op, fy), **command_integers(law, fm)}
    ints |= {"XH0": quantise(law.xh0, fx), "Z0": quantise(law.z0, fz)}
    _check_words(ints, fm)
    ranges = {"y_min": law.y_min, "y_max": law.y_max, "r_min": law.r_min, "r_max": law.r_max}
    ideal = _ideal(fm, accs, blocks, ints, anti_windup=law.anti_windup, ranges=ranges)
    return FixedGains(formats=fm, acc_v=accs["v"], acc_z=accs["z"], acc_x=accs["x"], ideal=ideal, **blocks, **ints)


def command_integers(law: DerivedLaw, fm: SignalFormats) -> dict[str, np.ndarray]:
    """``u_op`` (to nearest) and the limits (inward) in the coarser of the command's two formats, so that they are
    exact in both, as integers of each: ``UOP_V``, ``LO_V``, ``HI_V``, ``UOP_U``, ``LO_U``, ``HI_U``."""
    fu, fv = fm.frac("u"), fm.frac("v")
    fc = np.minimum(fu, fv)
    uop_c = quantise(law.u_op, fc)
    lo_c, hi_c = quantise_inward(law.lo, law.hi, fc)
    return {
        "UOP_V": np.left_shift(uop_c, fv - fc),
        "UOP_U": np.left_shift(uop_c, fu - fc),
        "LO_V": np.left_shift(lo_c, fv - fc),
        "HI_V": np.left_shift(hi_c, fv - fc),
        "LO_U": np.left_shift(lo_c, fu - fc),
        "HI_U": np.left_shift(hi_c, fu - fc),
    }


def deviation_fits(ints: dict, fm: SignalFormats) -> np.ndarray:
    """Per input, whether every command deviation ``dU = U - UOP_U`` with ``LO_U <= U <= HI_U`` fits the command
    word (the C forms it there: the command is clamped, then shifted exactly into the limits' multiples)."""
    top = np.maximum(ints["HI_U"] - ints["UOP_U"], ints["UOP_U"] - ints["LO_U"])
    return np.array([t <= f.max_int for t, f in zip(top, fm.u)], dtype=bool)


def from_integers(table: dict, fm: SignalFormats, acc: dict, *, anti_windup: str, ranges: dict) -> FixedGains:
    """The :class:`FixedGains` of a stored :meth:`FixedGains.integers` table (what an artifact carries), checked
    against its formats: the integers are taken as they are, never recomputed."""
    accs = {k: np.asarray(acc[k], dtype=np.int64) for k in ("v", "z", "x")}
    blocks = {}
    for name, shape in _block_shapes(fm).items():
        C = np.array(table[name], dtype=np.int64).reshape(shape)
        blocks[name] = Block(C=C, E=np.array(table[f"{name}_shift"], dtype=np.int64).reshape(shape))
    keys = ("YOP", "UOP_V", "UOP_U", "LO_V", "HI_V", "LO_U", "HI_U", "XH0", "Z0")
    ints = {k: np.array(table[k], dtype=np.int64) for k in keys}
    _check_words(ints, fm)
    ranges = {k: None if ranges.get(k) is None else np.asarray(ranges[k], dtype=float) for k in RANGE_KEYS}
    ideal = _ideal(fm, accs, blocks, ints, anti_windup=anti_windup, ranges=ranges)
    g = FixedGains(formats=fm, acc_v=accs["v"], acc_z=accs["z"], acc_x=accs["x"], ideal=ideal, **blocks, **ints)
    derived = ("shift_v", "shift_z", "shift_x", "shift_u", "U_SAFE")
    if any(table[k] != g.integers()[k] for k in derived):
        raise ValueError("the stored shifts or safe command do not match their formats")
    return g


RANGE_KEYS = ("y_min", "y_max", "r_min", "r_max")


def _block_shapes(fm: SignalFormats) -> dict[str, tuple[int, int]]:
    n, m, p, q = len(fm.xh), len(fm.u), len(fm.y), len(fm.z)
    shapes = {"KX": (m, n), "KY": (m, p), "KZ": (m, q), "TR": (q, q), "TY": (q, p), "KAW": (q, m)}
    return shapes | {"F": (n, n), "G": (n, m), "LY": (n, p)}


def _ideal(fm, accs, blocks, ints, *, anti_windup: str, ranges: dict) -> DerivedLaw:
    """The real values the integers mean (``u_op`` and the limits exactly from their v-format integers)."""
    fy, fr, fu, fv, fx, fz = (fm.frac(k) for k in ("y", "r", "u", "v", "xh", "z"))
    av, az, ax = accs["v"], accs["z"], accs["x"]
    return DerivedLaw(
        F=blocks["F"].value(ax, fx),
        G=blocks["G"].value(ax, fu),
        Ly=blocks["LY"].value(ax, fy),
        Kx=blocks["KX"].value(av, fx),
        Ky=blocks["KY"].value(av, fy),
        Kz=blocks["KZ"].value(av, fz),
        Tr=np.diag(blocks["TR"].value(az, fr)).copy(),
        Ty=blocks["TY"].value(az, fy),
        Kaw=blocks["KAW"].value(az, fv),
        u_op=real(ints["UOP_V"], fv),
        y_op=real(ints["YOP"], fy),
        lo=real(ints["LO_V"], fv),
        hi=real(ints["HI_V"], fv),
        xh0=real(ints["XH0"], fx),
        z0=real(ints["Z0"], fz),
        anti_windup=anti_windup,
        **ranges,
    )


def _sampling_time(law: DerivedLaw, fm: SignalFormats, az: np.ndarray) -> tuple[Block, Block]:
    """``TR`` (q x q, diagonal) and ``TY`` (q x p): each row's ``Ts`` one mantissa, shifted for the reference's and
    the samples' formats (the pattern ``Ty / Tr = -Ci`` has integer entries)."""
    fr, fy = fm.frac("r"), fm.frac("y")
    q, p = law.Ty.shape
    TR, ER = np.zeros((q, q), dtype=np.int64), np.zeros((q, q), dtype=np.int64)
    TY, EY = np.zeros((q, p), dtype=np.int64), np.zeros((q, p), dtype=np.int64)
    for j in range(q):
        pattern = law.Ty[j] / law.Tr[j]
        if np.any(pattern != np.round(pattern)):
            raise ValueError("the integrators' sample gains must be Ts times an integer selector (Ci)")
        used = np.flatnonzero(pattern)
        finest = max([int(fr[j])] + [int(fy[k]) for k in used])
        fc = min(format_for(abs(float(law.Tr[j])), fm.coefficient_word).frac, int(az[j]) - finest)
        ts = int(quantise(law.Tr[j], fc))
        TR[j, j], ER[j, j] = ts, az[j] - fr[j] - fc
        for k in used:
            TY[j, k], EY[j, k] = int(pattern[k]) * ts, az[j] - fy[k] - fc
    return Block(TR, ER), Block(TY, EY)


def _check_words(ints: dict, fm: SignalFormats) -> None:
    """The operating point, limits and initial state fit their signals' words, and so does every command's
    deviation from the operating point (:func:`deviation_fits`)."""
    for key, group in (("YOP", "y"), ("UOP_U", "u"), ("LO_U", "u"), ("HI_U", "u"), ("UOP_V", "v"), ("XH0", "xh")):
        formats = getattr(fm, group)
        if formats and np.max(np.abs(ints[key])) > formats[0].max_int:
            raise ValueError(f"{key} does not fit its {formats[0].word}-bit format")
    if not deviation_fits(ints, fm).all():
        raise ValueError("a command's deviation from u_op (HI_U - UOP_U or UOP_U - LO_U) does not fit the command word")
