"""float32 fidelity at design time: the C's arithmetic and the float64 law, each closing its own loop.

``gainlink design`` runs the law twice against the design plant (the artifact's discrete model, one copy
per loop): once as the C computes it (:class:`~gainlink.laws.lq.model.Float32Loop`: coefficients derived in
double from the float32 gain set, a float32 fused multiply-add chain per step, bit for bit the host and
Cortex-M4F builds) and once in float64 (:class:`~gainlink.proof.reference.ReferenceLoop`). Both see the same
scenario:

- measurement noise (standard deviation ``sqrt(diag V)`` of a Kalman design, otherwise 1e-3 of each
  output's excursion);
- a reference step on the tracked outputs (an initial output offset without integral action), sized so
  the command's linear peak is half the distance from the operating point to the nearer limit;
- halfway through, an input disturbance pulse of 1.5 times that distance which saturates the inputs,
  as long as the float64 loop still returns to the undisturbed trajectory (the pulse is shortened until
  it does; without any such pulse the run has no disturbance and says so).

The result is the worst command deviation ``max |u32 - u64|`` relative to each input's limit span, and
the worst output deviation relative to each output's excursion over the run. The run is written for any law about
one operating point (:class:`LoopPoint`: the design plant there, the unsaturated controller that sizes the scenario,
and the two laws to close the loop with): :func:`float32_fidelity` is the observer-based law's, and a scheduled law
runs it at each sigma of a sweep (:mod:`gainlink.laws.scheduled.fidelity`). Above
:data:`THRESHOLD` (1/4096 of the span: one step of a 12-bit actuator command, the usual PWM or DAC
resolution of a microcontroller; below it float32 is invisible at the actuator) ``design`` warns and
names the remedy, the balanced realisation (``[implementation] realization = "balanced"``), with the
deviation measured for it. Measured on the examples: pendulum 1.8e-5, quadrotor_lateral 8.0e-6,
wood_berry 8.9e-7 of the span (tests/test_fidelity.py checks these figures against the designs).
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from ...proof.reference import ReferenceLoop
from ...proof.sampled_plant import SampledPlant
from ...shipping.artifact import Artifact
from .model import Float32Loop

THRESHOLD = 1.0 / 4096
MIN_STEPS, MAX_STEPS = 400, 800
SETTLE_TIME_CONSTANTS = 6.0  # steps = this many closed-loop time constants per half run (clipped)
PULSE_FACTOR = 1.5
RECOVERY_TOL = 0.1  # the disturbed run must end this close (of the excursion) to where the linear loop ends


@dataclass(frozen=True)
class Float32Fidelity:
    """What float32 costs a design in closed loop (see the module docstring)."""

    steps: int
    max_rel_u: float
    max_rel_y: float
    threshold: float
    saturated_fraction: float
    disturbance_steps: int
    worst_input: str

    @property
    def ok(self) -> bool:
        """True when the command deviation is within :data:`THRESHOLD` of the limit span."""
        return self.max_rel_u <= self.threshold

    def warning(self, realization: str = "as_designed", *, balanced: float | None = None) -> str | None:
        """A warning naming the remedy when float32 costs more than the threshold, else None.

        ``balanced`` is the deviation measured with the balanced realisation, when known.
        """
        if self.ok:
            return None
        if realization == "as_designed":
            gain = "" if balanced is None else f" (measured with it: {balanced:.3g})"
            remedy = f'set [implementation] realization = "balanced" in the spec{gain}'
        else:
            remedy = (
                f'the realisation is already "{realization}": try another one, a slower sample rate, a '
                "slower observer, or rescaled plant units"
            )
        return (
            f"float32 changes the closed loop: the C's command deviates from the float64 law's by up to "
            f"{self.max_rel_u:.3g} of the limit span on {self.worst_input} (threshold {self.threshold:g}) in a "
            f"{self.steps}-step run with noise, a reference step and a saturating disturbance; {remedy}"
        )

    def to_dict(self) -> dict:
        """JSON form for the artifact's ``checks``."""
        return asdict(self)


@dataclass(frozen=True)
class LoopPoint:
    """A design about one operating point, as the fidelity run needs it: the sampled plant (deviations about the
    trim ``u_op``, ``y_op``), the references that hold it there (``r_op``), the limits, the unsaturated controller
    ``(A, B, C, D)`` from ``[dy; dr]`` to ``du`` (:func:`~gainlink.shipping.systems.controller_matrices`) that sizes
    the scenario, the measurement noise's standard deviations of a Kalman design (None: 1e-3 of the excursion), the
    closed loop's spectral radius (the run's length; None: that of the plant with the unsaturated controller) and
    the inputs' names.

    ``model`` and ``reference`` make the two laws that close the loop (anything with ``step(y, r)`` returning
    ``u`` and ``saturated``): the C's arithmetic and the float64 law. ``shared`` are objects a copy of a running law
    keeps sharing (the artifact), not copied with it.
    """

    Ad: np.ndarray
    Bd: np.ndarray
    Cd: np.ndarray
    Dd: np.ndarray
    u_op: np.ndarray
    y_op: np.ndarray
    r_op: np.ndarray
    u_min: np.ndarray
    u_max: np.ndarray
    controller: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
    noise_sd: np.ndarray | None
    radius: float | None
    inputs: tuple[str, ...]
    model: Callable[[], Any]
    reference: Callable[[], Any]
    shared: tuple = field(default=())

    @property
    def n(self) -> int:
        """States of the plant."""
        return self.Ad.shape[0]

    @property
    def m(self) -> int:
        """Inputs."""
        return self.Bd.shape[1]

    @property
    def p(self) -> int:
        """Outputs."""
        return self.Cd.shape[0]

    @property
    def q(self) -> int:
        """Tracked outputs (references)."""
        return self.r_op.shape[0]


def artifact_point(artifact: Artifact, *, implementation: Callable[[Artifact], Any] = Float32Loop) -> LoopPoint:
    """The observer-based law of ``artifact`` about its operating point (``implementation``: the law under test)."""
    from ...shipping.systems import controller_matrices

    a = artifact
    V = a.data.get("design", {}).get("observer", {}).get("V")
    return LoopPoint(
        Ad=a.Ad, Bd=a.Bd, Cd=a.Cd, Dd=a.Dd, u_op=a.u_op, y_op=a.y_op, r_op=a.r_op, u_min=a.u_min, u_max=a.u_max,
        controller=controller_matrices(a), noise_sd=None if V is None else noise_sd(V),
        radius=float(a.data.get("checks", {}).get("spectral_radius", 0.99)), inputs=tuple(a.signals["inputs"]),
        model=lambda: implementation(a), reference=lambda: ReferenceLoop(a), shared=(a,),
    )  # fmt: skip


def noise_sd(V: Any) -> np.ndarray:
    """Standard deviations of a measurement noise covariance's diagonal (negative entries read as 0)."""
    return np.sqrt(np.maximum(np.diag(np.asarray(V, dtype=float)), 0.0))


@dataclass(frozen=True)
class _Scenario:
    steps: int
    x0: np.ndarray
    r: np.ndarray  # (q,) the reference step, from the operating point's reference r_op
    r_step_at: int
    noise: np.ndarray  # (steps, p)
    pulse: np.ndarray  # (m,)
    pulse_at: int
    pulse_steps: int


@dataclass(frozen=True)
class _Run:
    x: np.ndarray
    y: np.ndarray
    u: np.ndarray
    saturated: np.ndarray


def float32_fidelity(artifact: Artifact, *, seed: int = 0, implementation=Float32Loop) -> Float32Fidelity:
    """Run the C's float32 arithmetic and the float64 law in closed loop on the design plant and compare.

    Parameters
    ----------
    artifact : Artifact
        The design (its discrete plant model is the plant of both loops).
    seed : int
        Seed of the measurement noise.
    implementation : callable
        Builds the loop under test from the artifact (anything with ``step(y, r)`` returning a
        :class:`~gainlink.proof.reference.StepResult`); the default is the C's arithmetic in numpy.

    Returns
    -------
    Float32Fidelity

    Examples
    --------
    >>> import control as ct, numpy as np, gainlink as gl
    >>> art = gl.design(ct.ss([[0.9]], [[0.1]], [[1.0]], [[0.0]], 0.01), Q=[[1.0]], R=[[1.0]],
    ...                 W=[[1e-3]], V=[[1e-4]], u_min=[-1.0], u_max=[1.0])
    >>> fid = float32_fidelity(art)
    >>> fid.ok, 0.0 < fid.max_rel_u < 1e-5
    (True, True)
    """
    return fidelity_at(artifact_point(artifact, implementation=implementation), seed=seed)


def fidelity_at(a: LoopPoint, *, seed: int = 0) -> Float32Fidelity:
    """Close the loop around ``a``'s plant with its model and its float64 law (module docstring) and compare."""
    sc, ref = _scenario_and_reference_run(a, seed=seed)
    f32, _ = _simulate(a, a.model(), sc)
    span = a.u_max - a.u_min
    du = np.abs(f32.u - ref.u) / span
    excursion = np.ptp(ref.y, axis=0)
    excursion = np.where(excursion > 0, excursion, 1.0)
    dy = np.abs(f32.y - ref.y) / excursion
    worst = int(np.argmax(du.max(axis=0))) if du.size else 0
    return Float32Fidelity(
        steps=sc.steps,
        max_rel_u=float(du.max(initial=0.0)),
        max_rel_y=float(dy.max(initial=0.0)),
        threshold=THRESHOLD,
        saturated_fraction=float(ref.saturated.any(axis=1).mean()),
        disturbance_steps=sc.pulse_steps,
        worst_input=a.inputs[worst],
    )


def _simulate(a: LoopPoint, law, sc: _Scenario, *, start: tuple | None = None, stop: int | None = None):
    """Close ``law`` around ``x+ = Ad x + Bd (u - u_op + d)``, ``y = y_op + Cd x + Dd (u_prev - u_op) + noise``.

    Runs steps ``start[0]`` (0 by default) to ``stop`` (the end) from the plant state of ``start``
    (``(k, plant snapshot)``; the law carries its own state). Returns the run and the state to resume from.
    """
    plant = SampledPlant(a.Ad, a.Bd, a.Cd, a.Dd, u_op=a.u_op, y_op=a.y_op)
    if start is None:
        k0 = 0
        plant.reset(sc.x0)
    else:
        k0 = start[0]
        plant.restore(start[1])
    k1 = sc.steps if stop is None else stop
    N = k1 - k0
    X, Y, U, S = np.empty((N, a.n)), np.empty((N, a.p)), np.empty((N, a.m)), np.empty((N, a.m), dtype=bool)
    r0, r1 = a.r_op, a.r_op + sc.r  # references are absolute: the step is taken from the operating point
    for i in range(N):
        k = k0 + i
        y = plant.outputs() + sc.noise[k]
        res = law.step(y, r1 if k >= sc.r_step_at else r0)
        X[i], Y[i], U[i], S[i] = plant.x, y, res.u, res.saturated
        d = sc.pulse if sc.pulse_at <= k < sc.pulse_at + sc.pulse_steps else 0.0
        plant.advance(res.u, d=d)
    return _Run(x=X, y=Y, u=U, saturated=S), (k1, plant.save())


class _LinearLoop:
    """The unsaturated loop (plant + compensator), for sizing the scenario: linear, so cheap.

    State ``[x; xh; z; du_prev]`` (the plant's feed-through acts on the previous command, as in
    :func:`_simulate`), input ``[r; noise; d]``.
    """

    def __init__(self, a: LoopPoint) -> None:
        self.a = a
        Ac, Bc, Cc, Dc = a.controller
        n, m, p, q = a.n, a.m, a.p, a.q
        nc = n + q
        By, Br, Dy, Dr = Bc[:, :p], Bc[:, p:], Dc[:, :p], Dc[:, p:]
        Z = np.zeros
        # du = Dy (Cd x + Dd e + noise) + Cc c + Dr r
        self.Vs = np.hstack([Dy @ a.Cd, Cc, Dy @ a.Dd])
        self.Vw = np.hstack([Dr, Dy, Z((m, m))])
        self.Ys = np.hstack([a.Cd, Z((p, nc)), a.Dd])
        self.Yw = np.hstack([Z((p, q)), np.eye(p), Z((p, m))])
        self.A = np.vstack(
            [
                np.hstack([a.Ad, Z((n, nc)), Z((n, m))]) + a.Bd @ self.Vs,
                np.hstack([By @ a.Cd, Ac, By @ a.Dd]),
                self.Vs,
            ]
        )
        self.B = np.vstack(
            [
                a.Bd @ self.Vw + np.hstack([Z((n, q + p)), a.Bd]),
                np.hstack([Br, By, Z((nc, m))]),
                self.Vw,
            ]
        )

    def run(
        self, *, steps: int, x0, r, r_step_at: int = 0, noise=None, d=None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """States, outputs (deviations) and commands (deviations ``v - u_op``) of ``steps`` samples."""
        a = self.a
        R = np.zeros((steps, a.q))
        R[r_step_at:] = r
        W = np.hstack(
            [R, np.zeros((steps, a.p)) if noise is None else noise, np.zeros((steps, a.m)) if d is None else d]
        )
        BW = W @ self.B.T
        S = np.empty((steps, self.A.shape[0]))
        s = np.concatenate([np.asarray(x0, dtype=float), np.zeros(self.A.shape[0] - a.n)])
        A = self.A
        with np.errstate(all="ignore"):
            for k in range(steps):
                S[k] = s
                s = A @ s + BW[k]
            return S[:, : a.n], S @ self.Ys.T + W @ self.Yw.T, S @ self.Vs.T + W @ self.Vw.T


def _scenario_and_reference_run(a: LoopPoint, *, seed: int) -> tuple[_Scenario, _Run]:
    """Size the run, the reference step, the noise and the pulse; return them with the float64 run."""
    u_op = a.u_op
    room = np.minimum(a.u_max - u_op, u_op - a.u_min)
    room = np.where(room > 0, room, (a.u_max - a.u_min) / 2)
    half = _half_run_steps(a)
    steps = 2 * half
    lin = _LinearLoop(a)
    # Reference step (or, without integral action, an initial output offset) whose command peaks at room / 2.
    unit_r = np.ones(a.q)
    unit_x0 = np.zeros(a.n) if a.q else np.linalg.pinv(a.Cd) @ np.ones(a.p)
    _, Y1, V1 = lin.run(steps=steps, x0=unit_x0, r=unit_r)
    scale = float(np.min(0.5 * room / np.maximum(np.max(np.abs(V1), axis=0), 1e-300)))
    scale = scale if np.isfinite(scale) and scale > 0 else 1.0
    noise = _noise(a, lin, steps=steps, room=room, y_excursion=scale * np.ptp(Y1, axis=0), seed=seed)
    sc = _Scenario(
        steps=steps,
        x0=scale * unit_x0,
        r=scale * unit_r,
        r_step_at=steps // 20,
        noise=noise,
        pulse=PULSE_FACTOR * room,
        pulse_at=half,
        pulse_steps=_saturating_pulse_length(a, lin, steps, half, room),
    )
    nominal, _, _ = lin.run(steps=steps, x0=sc.x0, r=sc.r, r_step_at=sc.r_step_at, noise=noise)
    excursion = max(float(np.max(np.abs(nominal))), 1e-300)
    tail = slice(-max(1, steps // 20), None)
    law = a.reference()
    first, resume = _simulate(a, law, sc, stop=half)
    for length, amplitude in _pulse_trials(sc.pulse_steps):
        sc = _Scenario(**{**sc.__dict__, "pulse_steps": length, "pulse": amplitude * PULSE_FACTOR * room})
        again = copy.deepcopy(law, {id(x): x for x in a.shared})  # the law as the first half left it
        second, _ = _simulate(a, again, sc, start=resume)
        gap = float(np.max(np.abs(second.x[tail] - nominal[tail]))) if np.all(np.isfinite(second.x)) else np.inf
        if length == 0 or gap <= 2.0 * _linear_pulse_tail(a, lin, sc, tail) + RECOVERY_TOL * excursion:
            break
    run = _Run(*(np.concatenate([getattr(first, f), getattr(second, f)]) for f in ("x", "y", "u", "saturated")))
    return sc, run


def _linear_pulse_tail(a: LoopPoint, lin: _LinearLoop, sc: _Scenario, tail: slice) -> float:
    """How far the unsaturated loop itself still is from its undisturbed run at the end, after this pulse."""
    window = sc.steps - sc.pulse_at
    d = np.zeros((window, a.m))
    d[: sc.pulse_steps] = sc.pulse
    X, _, _ = lin.run(steps=window, x0=np.zeros(a.n), r=np.zeros(a.q), d=d)
    return float(np.max(np.abs(X[tail])))


def _pulse_trials(longest: int):
    """Pulses to try, gentler each time: halve the length down to one sample, then halve the amplitude
    three times; the last resort is no pulse."""
    length = longest
    while length >= 1:
        yield length, 1.0
        length //= 2
    for amplitude in (0.5, 0.25, 0.125):
        yield 1, amplitude
    yield 0, 0.0


def _noise(
    a: LoopPoint, lin: _LinearLoop, *, steps: int, room: np.ndarray, y_excursion: np.ndarray, seed: int
) -> np.ndarray:
    """White measurement noise: ``sqrt(diag V)`` (or 1e-3 of the excursion), scaled down if it alone would
    move the command by more than a quarter of the room (3 standard deviations)."""
    sd = a.noise_sd if a.noise_sd is not None else 1e-3 * y_excursion
    white = np.random.default_rng(seed).standard_normal((steps, a.p))
    _, _, Vn = lin.run(steps=steps, x0=np.zeros(a.n), r=np.zeros(a.q), noise=white * sd)
    with np.errstate(all="ignore"):
        spread = 3.0 * np.std(Vn, axis=0)
    spread = np.where(np.isfinite(spread), spread, np.inf)
    factor = float(np.min(np.where(spread > 0.25 * room, 0.25 * room / np.maximum(spread, 1e-300), 1.0)))
    return white * sd * factor


def _half_run_steps(a: LoopPoint) -> int:
    """Half the run: enough closed-loop time constants to settle (from the slowest closed-loop pole)."""
    radius = a.radius if a.radius is not None else float(np.max(np.abs(np.linalg.eigvals(_LinearLoop(a).A))))
    tau = 1.0 / max(-np.log(min(radius, 1.0 - 1e-9)), 1e-9)
    return int(np.clip(SETTLE_TIME_CONSTANTS * tau, MIN_STEPS // 2, MAX_STEPS // 2))


def _saturating_pulse_length(a: LoopPoint, lin: _LinearLoop, steps: int, pulse_at: int, room: np.ndarray) -> int:
    """The shortest pulse whose linear command response reaches twice the room (capped at 2 % of the run)."""
    window = steps - pulse_at
    d = np.zeros((window, a.m))
    d[0] = PULSE_FACTOR * room
    _, _, V = lin.run(steps=window, x0=np.zeros(a.n), r=np.zeros(a.q), d=d)
    cumulative = np.cumsum(V, axis=0)  # the response to an l-sample pulse at step k is sum_{j<l} V[k - j]
    cap = max(1, steps // 50)
    for length in range(1, cap + 1):
        peak = np.max(np.abs(cumulative[length - 1 :] - np.vstack([np.zeros((1, a.m)), cumulative[:-length]])), axis=0)
        if np.any(peak >= 2.0 * room):
            return length
    return cap
