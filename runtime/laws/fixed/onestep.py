"""The one-step check of a fixed-point artifact: every step of a trace against the bit-exact integer law.

A fixed-point artifact's implementation is the integer law (:mod:`.model`), so there is no rounding to bound:
before each step ``k`` the law is put into the trace's own state after step ``k - 1`` (the artifact's initial
``XH0``, ``Z0`` for step 0), runs step ``k`` on the same samples (cast to float32, as the C takes them), and the
trace's fault flag, command words ``U``, saturation flags and next state ``XH``, ``Z`` must equal the law's bit
for bit.

A replay trace of a fixed-point engine (``fixed``, ``native``, ``qemu``) has the float columns (``u``, ``sat``,
``fault``, ``xh``, ``z``) holding the words as the real values they mean (``word * 2**-frac``, exact in a double),
so the words are read back exactly. The commands must be words of the artifact's command formats, or the trace
is refused (:class:`~gainlink.errors.DataError`): it comes from another artifact or numeric format. The state is
read as words when every value is one (``state_words``); otherwise (a state written with fewer digits) it is
quantised to the state formats, and the check says so.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import DataError
from ...proof.reference import Trace
from ...shipping.artifact import Artifact
from .model import FixedPointLoop
from .qformat import WORDS, quantise


@dataclass(frozen=True)
class FixedTrace:
    """A trace as integer words: commands ``U`` (N, m), state after each step ``XH`` (N, n), ``Z`` (N, q)."""

    U: np.ndarray
    saturated: np.ndarray
    fault: np.ndarray
    XH: np.ndarray
    Z: np.ndarray
    state_words: bool  # True: the state was read as words; False: quantised from real values


def _words(x: np.ndarray, frac: np.ndarray, word: int) -> tuple[np.ndarray, np.ndarray]:
    """``x`` quantised to ``frac`` and, per entry, whether ``x`` is exactly such a word within ``word`` bits."""
    x = np.asarray(x, dtype=np.float64)
    finite = np.isfinite(x)
    W = quantise(np.where(finite, x, 0.0), frac)
    exact = finite & (np.ldexp(x, np.asarray(frac, dtype=np.int64)) == W)
    exact &= (W >= -(1 << (word - 1))) & (W < (1 << (word - 1)))
    return W, exact


def trace_words(artifact: Artifact, trace: Trace, what: str) -> FixedTrace:
    """The words of a fixed-point artifact's trace ``trace`` (``what`` names it in the error).

    Raises
    ------
    DataError
        A command is not a word of the artifact's command format: the trace is not from this artifact's numeric
        format (one line naming the first such step and input).
    """
    fp = artifact.checks["fixed_point"]
    f, words = fp["formats"], WORDS[fp["numeric"]]
    U, exact = _words(trace.u, np.array(f["u"]), words["command"])
    bad = np.argwhere(~exact)
    if bad.size:
        k, i = (int(v) for v in bad[0])
        raise DataError(
            f"{what} is not a trace of {fp['numeric']} artifact {artifact.name}: u{i} at step {k} "
            f"({trace.u[k, i]!r}) is not a {words['command']}-bit word with {f['u'][i]} fractional bits"
        )
    XH, xh_exact = _words(trace.xh, np.array(f["xh"]), words["state"])
    Z, z_exact = _words(trace.z, np.array(f["z"]), words["state"])
    return FixedTrace(
        U=U,
        saturated=np.asarray(trace.saturated, dtype=bool),
        fault=np.asarray(trace.fault, dtype=bool),
        XH=XH,
        Z=Z,
        state_words=bool(xh_exact.all() and z_exact.all()),
    )


@dataclass(frozen=True)
class FixedMismatch:
    """The first field of a step where the trace and the integer law differ."""

    step: int
    field: str  # "fault", "u0", "sat1", "xh3", "z0"
    got: int
    expected: int

    def describe(self, engine: str = "the engine") -> str:
        """One line naming the step and the field."""
        kind = "" if self.field == "fault" or self.field.startswith("sat") else " word"
        return (
            f"step {self.step}: {self.field} of {engine} is{kind} {self.got} where the integer law from its own "
            f"state gives {self.expected} (equal bit for bit required)"
        )


@dataclass(frozen=True)
class FixedOneStepCheck:
    """The outcome of :func:`fixed_one_step_check` (the interface of :class:`.onestep.OneStepCheck`)."""

    steps: int
    failures: int
    first_failure: FixedMismatch | None
    numeric: str
    state_words: bool

    @property
    def passed(self) -> bool:
        """True when every step equals the integer law bit for bit."""
        return self.failures == 0

    def summary(self) -> str:
        """One line: pass/fail, and which state the law was started from."""
        head = "pass" if self.passed else f"FAIL on {self.failures} step(s)"
        start = (
            "the trace's own XH, Z words"
            if self.state_words
            else "the trace's real-valued state quantised to the state formats (it does not carry the words)"
        )
        return f"{head}, {self.steps} steps bit for bit against the {self.numeric} integer law from {start}"


def fixed_one_step_check(artifact: Artifact, Y: np.ndarray, R: np.ndarray | None, ft: FixedTrace) -> FixedOneStepCheck:
    """Check every step of ``ft`` against the integer law of ``artifact`` started from the trace's own state.

    Parameters
    ----------
    artifact : Artifact
        The fixed-point artifact the engine ran.
    Y, R : ndarray
        The samples it was fed, (N, p) and (N, q) (``R`` may be None without integral action); cast to float32
        as the C takes them.
    ft : FixedTrace
        The engine's trace as words (:func:`trace_words`).

    Raises
    ------
    DataError
        ``ft`` does not hold one step per sample.
    """
    a = artifact
    law = FixedPointLoop(a)
    Y32 = np.asarray(Y, dtype=np.float32).astype(np.float64).reshape(-1, a.p)
    N = Y32.shape[0]
    R32 = np.zeros((N, a.q)) if R is None or a.q == 0 else np.asarray(R, dtype=np.float32).astype(np.float64)
    R32 = R32.reshape(N, a.q)
    if ft.U.shape[0] != N:
        raise DataError(f"the trace has {ft.U.shape[0]} steps, the samples {N}")
    failures, first = 0, None
    for k in range(N):
        if k:
            law.XH, law.Z = [int(x) for x in ft.XH[k - 1]], [int(x) for x in ft.Z[k - 1]]
        res = law.step_samples(Y32[k], R32[k])
        bad = _first_difference(k, ft, res, law)
        if bad is not None:
            failures += 1
            first = first or bad
    return FixedOneStepCheck(N, failures, first, a.checks["fixed_point"]["numeric"], ft.state_words)


def _first_difference(k: int, ft: FixedTrace, res, law: FixedPointLoop) -> FixedMismatch | None:
    fields = (
        ("fault", [ft.fault[k]], [res.fault]),
        ("u", ft.U[k], res.U),
        ("sat", ft.saturated[k], res.saturated),
        ("xh", ft.XH[k], law.XH),
        ("z", ft.Z[k], law.Z),
    )
    for name, got, want in fields:
        for i, (g, w) in enumerate(zip(got, want)):
            if int(g) != int(w):
                return FixedMismatch(k, name if name == "fault" else f"{name}{i}", int(g), int(w))
    return None
