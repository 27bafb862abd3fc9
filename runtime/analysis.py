"""Structural analysis of a plant: controllability, observability, zeros, sampling, scaling.

The PBH test is run per distinct eigenvalue so that a failure names the mode, which is what a
designer needs to fix the plant or the sensor set. Rank decisions use singular values relative
to the matrices' size, never exact zero tests.
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass, field

import numpy as np
import scipy.linalg

from .spec import PlantSpec

log = logging.getLogger(__name__)

RANK_RTOL = 1e-9
SAMPLE_RATE_FACTOR = 10.0
BADLY_SCALED_RATIO = 1e4


@dataclass(frozen=True)
class Mode:
    """One distinct eigenvalue of A with its PBH verdicts."""

    eigenvalue: complex
    stable: bool
    controllable: bool
    observable: bool


@dataclass(frozen=True)
class AnalysisReport:
    """Everything ``gainlink analyze`` reports; ``to_dict`` gives the JSON form."""

    name: str
    kind: str
    n: int
    m: int
    p: int
    Ts: float
    open_loop_poles: list[complex]
    modes: list[Mode]
    controllability_rank: int
    controllability_cond: float
    observability_rank: int
    observability_cond: float
    stabilizable: bool
    detectable: bool
    transmission_zeros: list[complex]
    nonminimum_phase_zeros: list[complex]
    bandwidth_rad_s: float
    bandwidth_source: str
    sample_rate_ratio: float
    state_scale_ratio: float
    badly_scaled_states: list[str]
    warnings: list[str] = field(default_factory=list)
    compensator: dict | None = None  # the spec's designed compensator: poles, spectral radius, stability
    float32: dict | None = None  # float32 closed-loop fidelity of that design (gainlink.fidelity)
    dead_time: dict | None = None  # that design against the exact sampled dead times (gainlink.deadtime)

    def to_dict(self) -> dict:
        """JSON-friendly dict; complex numbers become [re, im] pairs."""
        d = asdict(self)
        d["open_loop_poles"] = complex_pairs(self.open_loop_poles)
        d["transmission_zeros"] = complex_pairs(self.transmission_zeros)
        d["nonminimum_phase_zeros"] = complex_pairs(self.nonminimum_phase_zeros)
        d["modes"] = [dict(m.__dict__, eigenvalue=complex_pairs([m.eigenvalue])[0]) for m in self.modes]
        return d


def complex_pairs(values) -> list[list[float]]:
    """Complex numbers as ``[re, im]`` lists of floats (for JSON)."""
    return [[float(np.real(v)) + 0.0, float(np.imag(v)) + 0.0] for v in values]


def is_stable(eigenvalue: complex, *, discrete: bool, margin: float = 1e-9) -> bool:
    """True when the eigenvalue is strictly inside the stability region."""
    if discrete:
        return abs(eigenvalue) < 1.0 - margin
    return eigenvalue.real < -margin


def distinct_eigenvalues(A: np.ndarray, tol: float = 1e-7) -> list[complex]:
    """Eigenvalues of A with repeats (within ``tol`` relative) merged."""
    out: list[complex] = []
    scale = max(1.0, float(np.max(np.abs(A)))) if A.size else 1.0
    for lam in sorted(np.linalg.eigvals(A), key=lambda z: (z.real, z.imag)):
        if not any(abs(lam - o) <= tol * scale for o in out):
            out.append(complex(lam))
    return out


def _rank_deficient(M: np.ndarray, n: int) -> bool:
    s = np.linalg.svd(M, compute_uv=False)
    return s.size < n or s[n - 1] <= RANK_RTOL * max(1.0, s[0])


def pbh_controllable(A: np.ndarray, B: np.ndarray, lam: complex) -> bool:
    """PBH: the mode ``lam`` is controllable iff rank [lam I - A, B] = n."""
    n = A.shape[0]
    return not _rank_deficient(np.hstack([lam * np.eye(n) - A, B]), n)


def pbh_observable(A: np.ndarray, C: np.ndarray, lam: complex) -> bool:
    """PBH: the mode ``lam`` is observable iff rank [lam I - A; C] = n."""
    n = A.shape[0]
    return not _rank_deficient(np.vstack([lam * np.eye(n) - A, C]), n)


def modes(A: np.ndarray, B: np.ndarray, C: np.ndarray, *, discrete: bool) -> list[Mode]:
    """PBH verdicts for every distinct eigenvalue of A."""
    return [
        Mode(
            eigenvalue=lam,
            stable=is_stable(lam, discrete=discrete),
            controllable=pbh_controllable(A, B, lam),
            observable=pbh_observable(A, C, lam),
        )
        for lam in distinct_eigenvalues(A)
    ]


def uncontrollable_unstable(A: np.ndarray, B: np.ndarray, *, discrete: bool) -> list[complex]:
    """The modes that make (A, B) not stabilizable (empty when stabilizable)."""
    return [
        lam
        for lam in distinct_eigenvalues(A)
        if not is_stable(lam, discrete=discrete) and not pbh_controllable(A, B, lam)
    ]


def unobservable_unstable(A: np.ndarray, C: np.ndarray, *, discrete: bool) -> list[complex]:
    """The modes that make (A, C) not detectable (empty when detectable)."""
    return [
        lam
        for lam in distinct_eigenvalues(A)
        if not is_stable(lam, discrete=discrete) and not pbh_observable(A, C, lam)
    ]


def rank_and_cond(M: np.ndarray, n: int) -> tuple[int, float]:
    """Numerical rank of M and the condition number of its first n singular values."""
    s = np.linalg.svd(M, compute_uv=False)
    rank = int(np.sum(s > RANK_RTOL * max(1.0, s[0])))
    cond = float(s[0] / s[n - 1]) if s.size >= n and s[n - 1] > 0 else float("inf")
    return rank, cond


def transmission_zeros(A, B, C, D) -> np.ndarray:
    """Invariant (transmission) zeros of (A, B, C, D), from the generalized eigenvalues of Rosenbrock's pencil."""
    n, m, p = A.shape[0], B.shape[1], C.shape[0]
    if p != m:
        # Non-square: the normal rank drops only at zeros common to every square sub-pencil,
        # which SLICOT's AB08ND computes through python-control.
        import control

        return np.asarray(control.ss(A, B, C, D).zeros())
    pencil_a = np.block([[A, B], [C, D]])
    pencil_b = np.block([[np.eye(n), np.zeros((n, m))], [np.zeros((p, n)), np.zeros((p, m))]])
    with np.errstate(all="ignore"):
        z = scipy.linalg.eigvals(pencil_a, pencil_b)
    return z[np.isfinite(z) & (np.abs(z) < 1e10)]


def pole_frequency(pole: complex, *, discrete: bool, Ts: float) -> float:
    """Natural frequency (rad/s) of a pole; discrete poles through s = ln(z)/Ts."""
    if discrete:
        return float(abs(np.log(max(abs(pole), 1e-12)) + 1j * np.angle(pole)) / Ts)
    return float(abs(pole))


def state_scaling(A: np.ndarray, B: np.ndarray, C: np.ndarray, names) -> tuple[float, list[str]]:
    """Spread of the balancing scale factors of the system matrix and the states at its extremes."""
    n = A.shape[0]
    big = np.zeros((n + 1, n + 1))
    big[:n, :n] = A
    big[:n, n] = np.max(np.abs(B), axis=1)
    big[n, :n] = np.max(np.abs(C), axis=0)
    _, (scale, _) = scipy.linalg.matrix_balance(big, permute=False, separate=True)
    s = scale[:n]
    ratio = float(np.max(s) / np.min(s))
    if ratio < BADLY_SCALED_RATIO:
        return ratio, []
    lo, hi = int(np.argmin(s)), int(np.argmax(s))
    return ratio, [names[lo], names[hi]]


def analyze(spec: PlantSpec) -> AnalysisReport:
    """Analyse a spec's plant; include the closed-loop bandwidth when the spec designs."""
    import control

    A, B, C, D = spec.A, spec.B, spec.C, spec.D
    discrete = not spec.continuous
    n = spec.n
    c_rank, c_cond = rank_and_cond(control.ctrb(A, B), n)
    o_rank, o_cond = rank_and_cond(control.obsv(A, C), n)
    mode_list = modes(A, B, C, discrete=discrete)
    warnings = _mode_warnings(mode_list, c_rank=c_rank, c_cond=c_cond, n=n)
    zeros = transmission_zeros(A, B, C, D)
    nmp = [z for z in zeros if not is_stable(complex(z), discrete=discrete, margin=0.0)]
    if nmp:
        origin = " (from the Padé approximation of dead time)" if spec.kind == "transfer_function" else ""
        warnings.append(f"non-minimum-phase zeros {', '.join(_fmt(z) for z in nmp)}{origin} limit bandwidth")
    bandwidth, source, checks = _bandwidth(spec, warnings)
    ratio = (2 * np.pi / spec.Ts) / bandwidth if bandwidth > 0 else float("inf")
    if ratio < SAMPLE_RATE_FACTOR:
        warnings.append(
            f"sample rate is only {ratio:.1f}x the {source} bandwidth {bandwidth:.3g} rad/s "
            f"(want at least {SAMPLE_RATE_FACTOR:.0f}x: Ts <= {2 * np.pi / (SAMPLE_RATE_FACTOR * bandwidth):.3g} s)"
        )
    scale_ratio, bad_states = state_scaling(A, B, C, spec.states)
    if bad_states:
        warnings.append(
            f"badly scaled states (balancing factors spread {scale_ratio:.2g}x): "
            f"{bad_states[0]} vs {bad_states[1]}; rescale units before design"
        )
    return AnalysisReport(
        name=spec.name,
        kind=spec.kind,
        n=n,
        m=spec.m,
        p=spec.p,
        Ts=spec.Ts,
        open_loop_poles=[complex(z) for z in np.linalg.eigvals(A)],
        modes=mode_list,
        controllability_rank=c_rank,
        controllability_cond=c_cond,
        observability_rank=o_rank,
        observability_cond=o_cond,
        stabilizable=all(md.stable or md.controllable for md in mode_list),
        detectable=all(md.stable or md.observable for md in mode_list),
        transmission_zeros=[complex(z) for z in zeros],
        nonminimum_phase_zeros=[complex(z) for z in nmp],
        bandwidth_rad_s=bandwidth,
        bandwidth_source=source,
        sample_rate_ratio=float(ratio),
        state_scale_ratio=scale_ratio,
        badly_scaled_states=bad_states,
        warnings=warnings,
        compensator=checks.get("compensator"),
        float32=checks.get("float32"),
        dead_time=checks.get("dead_time"),
    )


def _mode_warnings(mode_list: list, *, c_rank: int, c_cond: float, n: int) -> list[str]:
    """Uncontrollable and unobservable modes (saying which are unstable), an ill-conditioned ctrb matrix."""
    warnings = []
    for md in mode_list:
        lam = _fmt(md.eigenvalue)
        if not md.controllable:
            warnings.append(f"mode {lam} is uncontrollable ({'stable' if md.stable else 'UNSTABLE'})")
        if not md.observable:
            warnings.append(f"mode {lam} is unobservable ({'stable' if md.stable else 'UNSTABLE'})")
    if c_rank == n and c_cond > 1e8:
        warnings.append(f"controllability matrix is ill-conditioned (cond {c_cond:.3g})")
    return warnings


def _bandwidth(spec: PlantSpec, warnings: list[str]) -> tuple[float, str, dict]:
    """The closed-loop bandwidth of the spec's own design (and its checks), or the fastest open-loop pole
    when the spec does not design (saying why)."""
    from .design import design, loop_bandwidth  # analysis reports the closed-loop bandwidth of the spec's own design
    from .errors import GainlinkError

    try:
        result = design(spec)
    except GainlinkError as exc:
        warnings.append(f"design of this spec fails: {exc}")
        fastest = max(pole_frequency(z, discrete=not spec.continuous, Ts=spec.Ts) for z in np.linalg.eigvals(spec.A))
        return fastest, "open loop", {}
    for w in (
        result.compensator.warning(),
        result.float32 and result.float32.warning(),
        result.dead_time and result.dead_time.warning(),
    ):
        if w:
            warnings.append(w)
    return (
        loop_bandwidth(result.margins, result.controller_poles, spec.Ts),
        "closed-loop (gain crossover)",
        result.artifact["checks"],
    )


def _fmt(z: complex) -> str:
    z = complex(z)
    if abs(z.imag) < 1e-12:
        return f"{z.real:.4g}"
    return f"{z.real:.4g}{z.imag:+.4g}j"
