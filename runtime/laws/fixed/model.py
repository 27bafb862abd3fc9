"""The fixed-point law on integers, bit for bit what the C does (as :mod:`gainlink.laws.lq.model` is for the
float C): the reference a fixed-point C build is tested against.

Formats, integers and their names are those of :class:`~gainlink.laws.fixed.gains.FixedGains`: a signal in
format ``f`` is an integer ``X`` meaning ``X * 2**-f``. Words: q31 = 32-bit coefficients, samples (``Y``,
``R``, ``dY``) and commands (``U``, ``dU``); q15 = 16-bit ones; both keep ``XH``, ``Z``, ``V`` and ``Uv - V`` in
32 bits and every accumulator in 64. A coefficient is a mantissa ``C`` and a left shift ``E``; each product
``(int64)C * S`` is exact (at most 32 x 32 -> 64 bits), shifted left by ``E`` (exact) and added to the int64
accumulator; a sum may be accumulated in any order (integer addition is exact and associative when no partial sum
overflows, which the certificate proves for inputs in range); each sum is rounded once. Written ``C.S`` below:
``sum_k (C[i,k] S[k]) << E[i,k]``.

Operations (``rshift_round(a, s)`` = ``(a + (1 << (s-1))) >> s`` for ``s > 0``, ``a`` for ``s = 0``, ``a << -s``
for ``s < 0``; ``>>`` is the arithmetic shift, so ties round up; ``sat_W`` clips to ``[-2**(W-1), 2**(W-1)-1]``
and raises the overflow flag when it has to)::

    0. if any y or r is not finite: return U = U_SAFE (clamp(UOP_U, LO_U, HI_U)), fault flag; state untouched
    1. samples (doubles; a float32 widens exactly): yc = min(max(y, y_min), y_max), clip flag if yc != y;
       Y = quantise(yc, f_y) = floor(yc 2**f_y + 1/2) exactly (q = floor(x); q += (x - q >= 0.5)); same for R
    2. dY = sat_Ws(Y - YOP)                                           (exact; never saturates in range)
    3. for each input i: acc = KX.XH + KY.dY + KZ.Z                 (row i of each block)
                         V[i] = sat_32(UOP_V[i] + rshift_round(acc, shift_v[i]))
    4. Uv[i] = min(max(V[i], LO_V[i]), HI_V[i]); saturated[i] = (Uv[i] != V[i])
    5. U[i] = rshift_round(Uv[i], shift_u[i])  (= f_v - f_u; stays within [LO_U, HI_U]); dU[i] = U[i] - UOP_U[i]
    6. for each integrator j: acc = TR[j,j] R[j] << ER[j,j] + TY.Y + KAW.(Uv - V)
                         Z'[j] = sat_32(Z[j] + rshift_round(acc, shift_z[j]))
       clamp: Z' = Z when any input saturated (step 4); none: not allowed for fixed point
    7. for each state i: acc = F.XH + G.dU + LY.dY
                         XH'[i] = sat_32(rshift_round(acc, shift_x[i]))
    8. commit XH = XH', Z = Z' (both computed from the old state); return U (command word), flags

The operating point enters as in the float law: ``dY`` is formed before any gain multiplies a sample, the
feedback is summed in deviations and ``u_op`` added once, ``dU = U - UOP_U`` feeds the estimate. ``KY`` is zero
for the predictor form; ``KAW`` is zero unless back-calculation. An int64 accumulator whose partial sums could
leave 63 bits (the certificate proves they cannot, for inputs in range) is computed exactly here and flagged.

The steps run on Python integers (exact; each row a list of ``(C, E, signal index)`` of its non-zero
coefficients), which is also the plainest statement of what the C loops do.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import ArtifactError
from ...proof.reference import StepResult, Trace
from ...shipping.artifact import Artifact
from .gains import Block, FixedGains, SignalFormats, from_integers
from .qformat import WORDS, quantise, real

_INT64 = 1 << 63


@dataclass(frozen=True)
class FixedStep:
    """One integer step: the command ``U`` (command formats), the unsaturated command ``V`` (v formats), which
    inputs saturated, which samples and references were clipped to their ranges, the variables the second-line
    saturation had to clip (empty when none), and the fault flag."""

    U: np.ndarray
    V: np.ndarray
    saturated: np.ndarray
    clipped_y: np.ndarray
    clipped_r: np.ndarray
    overflow: tuple[str, ...]
    fault: bool


def gains_from_artifact(a: Artifact) -> FixedGains:
    """The integers a fixed-point artifact carries (``checks.fixed_point.integers``, with its formats and ranges),
    as they are: the C is rendered from these, never from a recomputation."""
    fp = a.checks.get("fixed_point")
    if fp is None:
        raise ArtifactError(f"artifact {a.name} is not a fixed-point design (no checks.fixed_point)")
    fm = SignalFormats.from_dict(fp["numeric"], fp["formats"])
    try:
        return from_integers(fp["integers"], fm, fp["accumulators"], anti_windup=a.anti_windup, ranges=fp["ranges"])
    except (KeyError, ValueError) as exc:
        raise ArtifactError(f"artifact {a.name}: checks.fixed_point.integers is inconsistent ({exc})") from None


def rshift_round(a: int, s: int) -> int:
    """``(a + (1 << (s-1))) >> s`` for ``s > 0`` (round half up), ``a`` for 0, ``a << -s`` below."""
    if s > 0:
        return (a + (1 << (s - 1))) >> s
    return a << -s


class _Sum:
    """One row of a sum of products: its non-zero terms ``(C, E, which signal, index)`` and its rounding shift."""

    def __init__(self, blocks: list[tuple[Block, int]], row: int, shift: int) -> None:
        self.terms = [
            (int(b.C[row, k]), int(b.E[row, k]), signal, k)
            for b, signal in blocks
            for k in range(b.C.shape[1])
            if b.C[row, k] != 0
        ]
        self.shift = int(shift)

    def rounded(self, signals: tuple[list[int], ...], name: str, flags: list) -> int:
        """The sum, exact, rounded once by the row's shift; flagged when a partial sum could leave int64."""
        acc = magnitude = 0
        for c, e, signal, k in self.terms:
            t = (c * signals[signal][k]) << e
            acc += t
            magnitude += abs(t)
        if magnitude + (1 << max(self.shift - 1, 0)) >= _INT64:
            flags.append(name)
        return rshift_round(acc, self.shift)


def _sat(x: int, word: int, name: str, flags: list) -> int:
    hi = (1 << (word - 1)) - 1
    if x > hi or x < -hi - 1:
        flags.append(name)
        return hi if x > hi else -hi - 1
    return x


class FixedPointLoop:
    """The integer law (module docstring) with state ``XH`` (n) and ``Z`` (q).

    Same interface as :class:`~gainlink.proof.reference.ReferenceLoop` (``step`` on doubles returning real
    commands, ``run``, ``reset``, ``xh``/``z`` as real values) so it can close a loop; :meth:`step_samples` and
    :meth:`step_int` give the integer view with every flag.

    Parameters
    ----------
    gains : FixedGains or Artifact
        The integers, or a fixed-point artifact they are rebuilt from (:func:`gains_from_artifact`).
    """

    def __init__(self, gains: FixedGains | Artifact) -> None:
        self.g = g = gains_from_artifact(gains) if isinstance(gains, Artifact) else gains
        fm = g.formats
        self.f = {k: fm.frac(k) for k in ("y", "r", "u", "v", "xh", "z")}
        self.words = WORDS[fm.numeric]
        # signals: 0 XH, 1 dY, 2 Z, 3 dU, 4 R, 5 Y, 6 Uv - V
        self.v_rows = [_Sum([(g.KX, 0), (g.KY, 1), (g.KZ, 2)], i, s) for i, s in enumerate(g.shift_v)]
        self.z_rows = [_Sum([(g.TR, 4), (g.TY, 5), (g.KAW, 6)], j, s) for j, s in enumerate(g.shift_z)]
        self.x_rows = [_Sum([(g.F, 0), (g.G, 3), (g.LY, 1)], i, s) for i, s in enumerate(g.shift_x)]
        ints = ("YOP", "UOP_V", "UOP_U", "LO_V", "HI_V", "LO_U", "HI_U", "U_SAFE")
        self.c = {k: [int(x) for x in getattr(g, k)] for k in ints}
        self.shift_u = [int(s) for s in g.shift_u]
        self.clamp = g.ideal.anti_windup == "clamp"
        self.reset()

    def reset(self) -> None:
        """Back to the initial estimate and integrator."""
        self.XH = [int(x) for x in self.g.XH0]
        self.Z = [int(x) for x in self.g.Z0]

    @property
    def xh(self) -> np.ndarray:
        return real(np.array(self.XH, dtype=np.int64), self.f["xh"])

    @property
    def z(self) -> np.ndarray:
        return real(np.array(self.Z, dtype=np.int64), self.f["z"])

    def quantise_samples(self, y, r) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Step 1: samples and references clipped to their ranges and quantised; with the clip flags."""
        law = self.g.ideal
        y = np.asarray(y, dtype=np.float64).reshape(law.p)
        r = np.zeros(law.q) if r is None else np.asarray(r, dtype=np.float64).reshape(law.q)
        yc = np.minimum(np.maximum(y, law.y_min), law.y_max)
        rc = np.minimum(np.maximum(r, law.r_min), law.r_max) if law.q else r
        return quantise(yc, self.f["y"]), quantise(rc, self.f["r"]), yc != y, rc != r

    def step_samples(self, y, r=None) -> FixedStep:
        """Steps 0-8 on double samples ``y`` (p) and references ``r`` (q)."""
        law = self.g.ideal
        yy = np.asarray(y, dtype=np.float64)
        rr = np.zeros(law.q) if r is None else np.asarray(r, dtype=np.float64)
        if not (np.all(np.isfinite(yy)) and np.all(np.isfinite(rr))):
            safe = np.array(self.c["U_SAFE"], dtype=np.int64)
            none = np.zeros(0, dtype=bool)
            return FixedStep(safe, safe.copy(), np.zeros(law.m, dtype=bool), none, none, (), True)
        Y, R, cy, cr = self.quantise_samples(yy, rr)
        res = self.step_int(Y, R)
        return FixedStep(res.U, res.V, res.saturated, cy, cr, res.overflow, False)

    def step_int(self, Y, R) -> FixedStep:
        """Steps 2-8 on quantised samples ``Y`` and references ``R``."""
        c, flags = self.c, []
        Y, R = [int(x) for x in Y], [int(x) for x in R]
        dY = [_sat(y - yop, self.words["sample"], "dY", flags) for y, yop in zip(Y, c["YOP"])]
        sig = (self.XH, dY, self.Z)
        V = [_sat(uop + row.rounded(sig, "acc_v", flags), 32, "V", flags) for row, uop in zip(self.v_rows, c["UOP_V"])]
        Uv = [min(max(v, lo), hi) for v, lo, hi in zip(V, c["LO_V"], c["HI_V"])]
        saturated = [uv != v for uv, v in zip(Uv, V)]
        U = [rshift_round(uv, s) for uv, s in zip(Uv, self.shift_u)]
        dU = [_sat(u - uop, self.words["command"], "dU", flags) for u, uop in zip(U, c["UOP_U"])]
        W = [_sat(uv - v, 32, "Uv-V", flags) for uv, v in zip(Uv, V)]
        Z = self.Z
        if not (self.clamp and any(saturated)):
            sig = (self.XH, dY, self.Z, dU, R, Y, W)
            Z = [_sat(z + row.rounded(sig, "acc_z", flags), 32, "Z", flags) for row, z in zip(self.z_rows, self.Z)]
        self.XH = self.estimate_update(self.XH, dU, dY, flags)
        self.Z = Z
        none = np.zeros(0, dtype=bool)
        return FixedStep(
            np.array(U, dtype=np.int64),
            np.array(V, dtype=np.int64),
            np.array(saturated),
            none,
            none,
            tuple(flags),
            False,
        )

    def estimate_update(self, XH, dU, dY, flags: list | None = None) -> list[int]:
        """Step 7, on its own: the next estimate from ``XH``, ``dU`` and ``dY`` (a test harness injects ``dU``)."""
        flags = [] if flags is None else flags
        sig = ([int(x) for x in XH], [int(x) for x in dY], None, [int(x) for x in dU])
        return [_sat(row.rounded(sig, "acc_x", flags), 32, "XH", flags) for row in self.x_rows]

    def step(self, y: np.ndarray, r: np.ndarray | None = None) -> StepResult:
        """One step on doubles; the command and the unsaturated command in real units."""
        res = self.step_samples(y, r)
        return StepResult(
            u=real(res.U, self.f["u"]),
            saturated=res.saturated,
            fault=res.fault,
            v=real(res.V, self.f["u"] if res.fault else self.f["v"]),
        )

    def run(self, Y: np.ndarray, R: np.ndarray | None = None) -> Trace:
        """One step per row of ``Y`` (N, p) and ``R`` (N, q); real values, as the other laws' traces."""
        law = self.g.ideal
        Y = np.asarray(Y, dtype=float).reshape(-1, law.p)
        N = Y.shape[0]
        R = np.zeros((N, law.q)) if R is None else np.asarray(R, dtype=float).reshape(N, law.q)
        U, S = np.empty((N, law.m)), np.empty((N, law.m), dtype=bool)
        XH, Z, F = np.empty((N, law.n)), np.empty((N, law.q)), np.empty(N, dtype=bool)
        for k in range(N):
            res = self.step(Y[k], R[k])
            U[k], S[k], F[k] = res.u, res.saturated, res.fault
            XH[k], Z[k] = self.xh, self.z
        return Trace(u=U, saturated=S, xh=XH, z=Z, fault=F)
