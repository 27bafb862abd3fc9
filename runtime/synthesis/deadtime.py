"""The design against the plant's true dead times: a transfer-function spec models each delay by a Padé
approximant, but sampled with a zero-order hold a dead time has an exact discrete model.

For an element ``g(s) e^{-tau s}`` with ``tau = d Ts + theta`` (``d`` whole periods, ``0 <= theta < Ts``) and a
realisation ``(A, B, C, D)`` of ``g``, the ZOH model is (Åström & Wittenmark, Computer-Controlled Systems,
sec. 2.3, "Systems with time delays")::

    x[k+1] = Phi x[k] + Gamma0 u[k-d] + Gamma1 u[k-d-1]
    y[k]   = C x[k] + D u(k Ts - tau)                  (u[k-d] when theta = 0, else u[k-d-1])

    Phi = e^{A Ts},  Gamma0 = int_0^{Ts-theta} e^{A s} ds B,  Gamma1 = e^{A (Ts-theta)} int_0^{theta} e^{A s} ds B

with the ``d`` (or ``d + 1``) past inputs as extra states. :func:`dead_time_check` closes the designed law
(unsaturated) around that exact plant and reports the closed loop's spectral radius: a Padé order too low
for the dead times (the loop's phase at crossover is wrong) shows up as an unstable loop that the design's own
checks, made on the Padé model, cannot see.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.linalg

if TYPE_CHECKING:
    import control

    from ..shipping.artifact import Artifact
    from ..spec import PlantSpec


@dataclass(frozen=True)
class DeadTimeCheck:
    """The designed law in closed loop with the exact sampled dead times (no Padé)."""

    pade_order: int
    max_delay_periods: float
    spectral_radius: float
    stable: bool
    order: int  # states of the exact plant model

    def to_dict(self) -> dict:
        return {
            "pade_order": self.pade_order,
            "max_delay_periods": self.max_delay_periods,
            "spectral_radius": self.spectral_radius,
            "stable": self.stable,
            "exact_plant_order": self.order,
        }

    def describe(self) -> str:
        verdict = "stable" if self.stable else "UNSTABLE"
        return (
            f"with the exact dead times (up to {self.max_delay_periods:.3g} periods, sampled model of order "
            f"{self.order}; the design used Padé order {self.pade_order}): closed loop {verdict}, spectral "
            f"radius {self.spectral_radius:.4f}"
        )

    def warning(self) -> str | None:
        if self.stable:
            return None
        return (
            f"the design is unstable on the plant with its true dead times (closed-loop spectral radius "
            f"{self.spectral_radius:.4f} with the exact sampled delays; Padé order {self.pade_order} misjudges "
            "their phase): raise plant.pade_order, or slow the loop down (Bryson limits / weights)"
        )


def _zoh_integrals(A: np.ndarray, B: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    """``(e^{A t}, int_0^t e^{A s} ds B)`` from one matrix exponential (Van Loan)."""
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n], M[:n, n:] = A * t, B * t
    E = scipy.linalg.expm(M)
    return E[:n, :n], E[:n, n:]


def element_model(num: Any, den: Any, tau: float, Ts: float) -> control.StateSpace:
    """The exact ZOH-sampled model of one SISO element ``num/den e^{-tau s}`` (discrete, ``dt = Ts``)."""
    import control

    g = control.ss(control.tf(np.atleast_1d(np.asarray(num, float)), np.atleast_1d(np.asarray(den, float))))
    A, B, C, D = (np.atleast_2d(np.asarray(M, float)) for M in (g.A, g.B, g.C, g.D))
    n = A.shape[0]
    d = int(np.floor(tau / Ts + 1e-9))
    theta = max(tau - d * Ts, 0.0)
    if theta <= 1e-9 * Ts:
        theta = 0.0
    Phi, Gamma0 = _zoh_integrals(A, B, Ts - theta)
    Phi_full, _ = _zoh_integrals(A, B, Ts)
    if theta > 0.0:
        _, G_theta = _zoh_integrals(A, B, theta)
        Gamma1 = Phi @ G_theta  # e^{A (Ts - theta)} int_0^theta e^{A s} ds B
        taps = d + 1  # u[k-1] .. u[k-d-1] kept as states
    else:
        Gamma1 = np.zeros_like(Gamma0)
        taps = d
    # State: [x; w_1 .. w_taps] with w_i[k] = u[k-i].
    N = n + taps
    Ad = np.zeros((N, N))
    Bd = np.zeros((N, 1))
    Cd = np.zeros((1, N))
    Dd = np.zeros((1, 1))
    Ad[:n, :n] = Phi_full
    for i in range(1, taps):  # shift register
        Ad[n + i, n + i - 1] = 1.0
    if taps:
        Bd[n, 0] = 1.0
    # Which input feeds Gamma0 (u[k-d]) and Gamma1 / D (u[k-d-1] when theta > 0).
    _feed(Ad, Bd, n, d, Gamma0)
    if theta > 0.0:
        _feed(Ad, Bd, n, d + 1, Gamma1)
    Cd[0, :n] = C[0]
    late = d + 1 if theta > 0.0 else d
    if late == 0:
        Dd[0, 0] = D[0, 0]
    else:
        Cd[0, n + late - 1] += D[0, 0]
    return control.ss(Ad, Bd, Cd, Dd, Ts)


def _feed(Ad: np.ndarray, Bd: np.ndarray, n: int, lag: int, G: np.ndarray) -> None:
    """Add ``G u[k-lag]`` to the plant state's update (``lag = 0``: the current input)."""
    if lag == 0:
        Bd[:n] += G
    else:
        Ad[:n, n + lag - 1] += G[:, 0]


def exact_plant(num: list, den: list, delay: list, Ts: float) -> control.StateSpace:
    """The p x m transfer-function matrix with exact sampled dead times, one element model per entry
    (non-minimal: each element keeps its own states and delay line)."""
    import control

    p, m = len(num), len(num[0])
    blocks = [element_model(num[i][j], den[i][j], float(delay[i][j]), Ts) for i in range(p) for j in range(m)]
    big = control.append(*blocks)
    A, B, C, D = (np.asarray(M, float) for M in (big.A, big.B, big.C, big.D))
    T_in = np.zeros((p * m, m))  # element (i, j) takes input j
    T_out = np.zeros((p, p * m))  # output i sums its row
    for i in range(p):
        for j in range(m):
            T_in[i * m + j, j] = 1.0
            T_out[i, i * m + j] = 1.0
    return control.ss(A, B @ T_in, T_out @ C, T_out @ D @ T_in, Ts)


def applies(spec: PlantSpec) -> bool:
    """A transfer-function spec with a dead time, sampled with a zero-order hold, and stable elements (the
    element-wise exact model is non-minimal: an unstable element repeated across a row would add spurious
    unstable modes)."""
    tf = spec.plant.transfer_function
    if spec.plant.kind != "transfer_function" or tf is None or spec.discretization != "zoh":
        return False
    if not any(float(t) > 0 for row in tf.delay for t in row):
        return False
    return all(np.all(np.roots(np.asarray(a, float)).real < 0) for row in tf.den for a in row)


def dead_time_check(spec: PlantSpec, artifact: Artifact) -> DeadTimeCheck | None:
    """Close the artifact's law (unsaturated, r = 0) around the exact sampled dead-time plant of ``spec``;
    ``None`` when :func:`applies` says the check does not apply."""
    import control

    from ..shipping.systems import controller_matrices

    if not applies(spec):
        return None
    tf = spec.plant.transfer_function
    plant = exact_plant(tf.num, tf.den, tf.delay, spec.Ts)
    Ac, Bc, Cc, Dc = controller_matrices(artifact)
    law = control.ss(Ac, Bc[:, : artifact.p], Cc, Dc[:, : artifact.p], spec.Ts)  # dy -> du
    loop = control.feedback(plant, law, sign=+1)  # du = law(dy): positive feedback in control's convention
    radius = float(np.max(np.abs(loop.poles())))
    longest = max(float(t) for row in tf.delay for t in row) / spec.Ts
    return DeadTimeCheck(
        pade_order=int(spec.plant.pade_order or 0),
        max_delay_periods=longest,
        spectral_radius=radius,
        stable=radius < 1.0,
        order=plant.nstates,
    )
