"""The closed-loop twin: what the implementation costs against the ideal design.

Beside a SIL, HIL or PIL run, a float64 twin of the whole loop runs in step: the reference law
(:class:`~gainlink.proof.reference.ReferenceLoop`) closing the loop around a second instance of the same
plant, fed the same measurement noise, references and input disturbances from the same initial
state, with every sample arriving at once and no faults. Whatever separates the real run from the
twin is what the implementation costs the closed loop: float32 arithmetic, the link's encoding
(int16 quantisation), transport and timing (late or lost samples, a held command) and injected
faults. For a stable closed loop the difference stays bounded (unlike an open-loop replay through an
unstable compensator).

:func:`twin_comparison` is a pure function of the two traces, so campaigns can compute it from stored runs.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np

from ..shipping.artifact import Artifact
from .reference import ReferenceLoop


@dataclass(frozen=True)
class TwinTrace:
    """The twin's run: sampled outputs (with the same noise), commands, integrator; row k = sample k."""

    y: np.ndarray  # (N, p)
    u: np.ndarray  # (N, m)
    z: np.ndarray  # (N, q)


class TwinLoop:
    """The float64 twin of a loop, advanced one sample at a time beside the real run.

    Parameters
    ----------
    artifact : Artifact
        The design the real controller runs.
    outputs : callable
        ``outputs() -> y``: the twin plant's current outputs (absolute, noise-free).
    advance : callable
        ``advance(u)``: apply ``u`` (absolute, disturbance included) to the twin plant for one sample.
    steps : int
        Samples planned (the trace is cut to those taken).
    """

    def __init__(
        self,
        artifact: Artifact,
        *,
        outputs: Callable[[], np.ndarray],
        advance: Callable[[np.ndarray], None],
        steps: int,
    ) -> None:
        self.law = ReferenceLoop(artifact)
        self._outputs, self._advance = outputs, advance
        a = artifact
        self.Y, self.U, self.Z = np.zeros((steps, a.p)), np.zeros((steps, a.m)), np.zeros((steps, a.q))

    def step(self, k: int, *, noise: np.ndarray, r: np.ndarray, d: np.ndarray) -> None:
        """Sample ``k``: sample the twin plant (plus ``noise``), run the law on it, apply ``u + d``."""
        y = np.asarray(self._outputs(), dtype=float) + noise
        u = self.law.step(y, r).u
        self.Y[k], self.U[k], self.Z[k] = y, u, self.law.z
        self._advance(u + d)

    def trace(self, steps: int) -> TwinTrace:
        """The twin's first ``steps`` samples."""
        return TwinTrace(y=self.Y[:steps].copy(), u=self.U[:steps].copy(), z=self.Z[:steps].copy())


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
        return _clean(asdict(self) | {"worst_du_rel": self.worst_du_rel, "worst_dy_rel": self.worst_dy_rel})


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
    excursion = np.ptp(twin_y, axis=0) if steps else np.zeros(artifact.p)
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
