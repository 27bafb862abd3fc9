"""The closed-loop twin: what the implementation costs against the ideal design.

For a SIL, HIL or PIL run, a float64 twin of the whole loop (:func:`run_twin`): the law's float64 reference
closing the loop around a second instance of the same plant, fed the same measurement noise, references, input
disturbances and external scheduling signals from the same initial state, with every sample arriving at once and
no faults. It does not depend on the run, so it is computed from the run's plan after the run. Whatever
separates the real run from the twin is what the implementation costs the closed loop: float32 arithmetic, the
link's encoding (int16 quantisation), transport and timing (late or lost samples, a held command) and injected
faults. For a stable closed loop the difference stays bounded (unlike an open-loop replay through an
unstable compensator).

:func:`twin_comparison` is a pure function of the two traces, so campaigns can compute it from stored runs.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..shipping.artifact import Artifact


@dataclass(frozen=True)
class TwinTrace:
    """A twin's run, row k = sample k: sampled outputs (with the run's noise), commands, the law's state after each
    step (rows of the controller's ``state()``) and the sigma each step used (NaN for a law without one).

    A campaign block's twin records only what is read of the law's state, its integrators (``z``, the columns
    ``law.integrator_columns`` names; ``state`` None); :meth:`integrators` reads them from either."""

    y: np.ndarray  # (N, p)
    u: np.ndarray  # (N, m)
    state: np.ndarray | None  # (N, state size); None where only the integrators were recorded
    sigma: np.ndarray  # (N,)
    z: np.ndarray | None = None  # (N, q): the integrators alone, where the loop recorded only them

    def integrators(self, law: Any, artifact: Artifact) -> np.ndarray | None:
        """The twin's integrators (N, q), None for a law that keeps none (``law.integrators`` of its state)."""
        if self.state is None:
            return self.z
        return law.integrators(artifact, self.state)


def run_twin(
    controller: Any,
    *,
    outputs: Callable[[], np.ndarray],
    advance: Callable[[np.ndarray], None],
    noise: np.ndarray,
    R: np.ndarray,
    D: np.ndarray,
    S: np.ndarray,
    steps: int,
    on_signals: Callable[[np.ndarray], None] | None = None,
    on_sigma: Callable[[float], None] | None = None,
) -> TwinTrace:
    """Close ``controller`` (a law's ``step(y, r, s)``, e.g. its float64 reference) around a plant for ``steps``
    samples, with a run's measurement noise, references, input disturbances and external scheduling signals.

    The twin of a run does not depend on the run (every sample arrives, no faults), so it is computed from the
    run's plan after the run (or beside it), never on the run's per-sample path.

    Parameters
    ----------
    controller : Controller
        ``step(y, r, s) -> Step`` (``u``, ``sigma``) and ``state()``, at its start state.
    outputs, advance : callable
        The twin plant: ``outputs() -> y`` (absolute, noise-free) and ``advance(u)`` for one sample (absolute,
        disturbance included).
    noise, R, D, S : ndarray
        Per sample (rows): the noise added to the outputs, the references, the input disturbances and the external
        scheduling signals.
    steps : int
        Samples to run (the rows used).
    on_signals : callable, optional
        Hears each sample's external scheduling signals before the plant is sampled (a plant that follows them).
    on_sigma : callable, optional
        Hears the sigma of each step before the plant advances (a model that follows its law's sigma).
    """
    Y, U, SIG = np.zeros((steps, noise.shape[1])), np.zeros((steps, D.shape[1])), np.full(steps, np.nan)
    states = []
    for k in range(steps):
        if on_signals is not None:
            on_signals(S[k])
        y = np.asarray(outputs(), dtype=float) + noise[k]
        step = controller.step(y, R[k], S[k])
        Y[k], U[k], SIG[k] = y, step.u, step.sigma
        states.append(controller.state())
        if on_sigma is not None:
            on_sigma(step.sigma)
        advance(step.u + D[k])
    state = np.array(states) if states else np.zeros((0, 0))
    return TwinTrace(y=Y, u=U, state=state, sigma=SIG)


@dataclass(frozen=True)
class TwinComparison:
    """Real run against its twin (see :func:`twin_comparison`); ``to_dict`` is the report's form.

    Per input: ``max_du`` and ``max_du_rel`` (of the limit span). Per output: ``max_dy`` and ``max_dy_rel``
    (of the twin's excursion, ``max - min`` over the run). Per tracked output (per output without
    integral action): the real and the twin's IAE, their difference and that relative to the twin's IAE.
    """

    steps: int
    inputs: dict
    outputs: dict
    iae: dict

    @property
    def worst_du_rel(self) -> float:
        """The largest command deviation relative to its limit span."""
        return max((v["max_du_rel"] or 0.0 for v in self.inputs.values()), default=0.0)

    @property
    def worst_dy_rel(self) -> float:
        """The largest output deviation relative to its excursion."""
        return max((v["max_dy_rel"] or 0.0 for v in self.outputs.values()), default=0.0)

    def to_dict(self) -> dict:
        """JSON form (non-finite numbers become ``None``)."""
        # _clean builds every dict anew (dataclasses.asdict's deep copy first cost more than the comparison)
        fields = {"steps": self.steps, "inputs": self.inputs, "outputs": self.outputs, "iae": self.iae}
        return _clean(fields | {"worst_du_rel": self.worst_du_rel, "worst_dy_rel": self.worst_dy_rel})


def twin_comparison(
    *,
    t: np.ndarray,
    y: np.ndarray,
    u: np.ndarray,
    r: np.ndarray,
    twin_y: np.ndarray,
    twin_u: np.ndarray,
    artifact: Artifact,
) -> TwinComparison:
    """Compare a run's sampled outputs ``y`` and commands ``u`` with its twin's, sample by sample.

    Parameters
    ----------
    t : ndarray
        Sample times (N,).
    y, u : ndarray
        The real run's sampled outputs (N, p) and applied commands (N, m).
    r : ndarray
        The references (N, q), absolute.
    twin_y, twin_u : ndarray
        The twin's (same shapes).
    artifact : Artifact
        The design (signal names, limits, tracked outputs).

    Returns
    -------
    TwinComparison

    Examples
    --------
    >>> import control as ct, numpy as np, gainlink as gl
    >>> art = gl.design(ct.ss([[0.9]], [[0.1]], [[1.0]], [[0.0]], 0.01), Q=[[1.0]], R=[[1.0]],
    ...                 W=[[1e-3]], V=[[1e-4]], u_min=[-1.0], u_max=[1.0])
    >>> sim = gl.simulate(art, steps=100, x0=[1.0])
    >>> cmp = twin_comparison(t=sim.t, y=sim.y, u=sim.u, r=sim.r, twin_y=sim.y, twin_u=sim.u + 0.01, artifact=art)
    >>> round(cmp.worst_du_rel, 6), cmp.worst_dy_rel
    (0.005, 0.0)
    """
    N = int(t.size)
    dt = float(t[1] - t[0]) if N > 1 else 0.0
    return TwinComparison(
        steps=N,
        inputs=_input_differences(u, twin_u, artifact=artifact),
        outputs=_output_differences(y, twin_y, artifact=artifact, steps=N),
        iae=_iae(_tracking_errors(y=y, r=r, twin_y=twin_y, artifact=artifact), dt=dt),
    )


def _input_differences(u: np.ndarray, twin_u: np.ndarray, *, artifact: Artifact) -> dict:
    """Per input the largest command difference, absolute and relative to the input's range (``None`` when the
    range is not positive)."""
    span = artifact.u_max - artifact.u_min
    du = np.abs(u - twin_u)
    return {
        name: {
            "max_du": float(du[:, i].max(initial=0.0)),
            "max_du_rel": float(du[:, i].max(initial=0.0) / span[i]) if span[i] > 0 else None,
        }
        for i, name in enumerate(artifact.signals["inputs"])
    }


def _output_differences(y: np.ndarray, twin_y: np.ndarray, *, artifact: Artifact, steps: int) -> dict:
    """Per output the largest difference, absolute and relative to the twin's excursion (``None`` when the twin's
    output stays constant)."""
    dy = np.abs(y - twin_y)
    # column by column: np.ptp along axis 0 of a (1000, 2) array cost ~4x two one-column extents (the same numbers)
    excursion = [np.ptp(twin_y[:, i]) for i in range(twin_y.shape[1])] if steps else np.zeros(artifact.p)
    return {
        name: {
            "max_dy": float(dy[:, i].max(initial=0.0)),
            "max_dy_rel": float(dy[:, i].max(initial=0.0) / excursion[i]) if excursion[i] > 0 else None,
        }
        for i, name in enumerate(artifact.signals["outputs"])
    }


def _tracking_errors(
    *, y: np.ndarray, r: np.ndarray, twin_y: np.ndarray, artifact: Artifact
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per reference the tracking error of the run and of the twin; per output without references (regulation about
    the operating point), its distance from ``y_op``."""
    a = artifact
    sig = a.signals
    if a.q:
        return {name: (r[:, j] - y @ a.Ci[j], r[:, j] - twin_y @ a.Ci[j]) for j, name in enumerate(sig["references"])}
    return {name: (a.y_op[i] - y[:, i], a.y_op[i] - twin_y[:, i]) for i, name in enumerate(sig["outputs"])}


def _iae(errors: dict[str, tuple[np.ndarray, np.ndarray]], *, dt: float) -> dict:
    """Integral of the absolute error of the run and of the twin, and their difference (absolute and relative to
    the twin's)."""
    iae = {}
    for name, (e_real, e_twin) in errors.items():
        real, ideal = float(np.sum(np.abs(e_real)) * dt), float(np.sum(np.abs(e_twin)) * dt)
        iae[name] = {
            "real": real,
            "twin": ideal,
            "difference": real - ideal,
            "difference_rel": (real - ideal) / ideal if ideal > 0 else None,
        }
    return iae


def _clean(obj):
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj
