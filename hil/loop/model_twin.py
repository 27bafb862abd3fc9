"""The model twin: the float64 law closed around the design's own model (:mod:`.twins`), and what it tells.

The closed-loop twin (:mod:`gainlink.proof.twin`) runs the ideal law on a second instance of the *same* plant, so it
agrees with the run whatever the plant does: it prices the implementation, not the model. The model twin runs
the same law, with the same references, measurement noise and input disturbances, around the model the
controller believes in — the artifact's discrete ``Ad, Bd, Cd, Dd`` about its operating point, in deviations —
started where the plant starts. Where the plant and the model twin part, the design's model does not describe
the plant in this run (a wrong interface or step of an FMU, nonlinearity, a model off the point), and every
verdict computed on the model (margins, overshoot, settling) is in question.

:func:`model_mismatch` gives per output the largest ``|y_plant - y_model|`` against the output's range in the
run (the larger of the plant's and the model's), and per tracked output the IAE ratio plant / model. A
mismatch above :data:`MISMATCH_WARN` (5 % of the range) is flagged: the design predicts the closed loop only to
that order, and it is the level at which ``linearize`` calls a model's fit poor (:mod:`..plants.model_fit`). A
sound model sits far below it (1e-4 or less for an exactly linear plant through Model Exchange).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from gainlink.shipping.artifact import Artifact

MISMATCH_WARN = 0.05


@dataclass(frozen=True)
class ModelMismatch:
    """The run against its model twin (see the module docstring); ``to_dict`` is the report's form."""

    outputs: dict
    iae: dict
    worst: float | None
    start: str

    @property
    def warn(self) -> bool:
        return self.worst is None or self.worst > MISMATCH_WARN

    def to_dict(self) -> dict:
        return _clean(asdict(self) | {"threshold": MISMATCH_WARN, "warning": self.warn})


def model_mismatch(
    *, t: np.ndarray, y: np.ndarray, r: np.ndarray, model_y: np.ndarray, artifact: Artifact, start: str = ""
) -> ModelMismatch:
    """Compare a run's sampled outputs ``y`` with its model twin's ``model_y``, sample by sample.

    Parameters
    ----------
    t : ndarray
        Sample times (N,).
    y, model_y : ndarray
        The run's and the model twin's sampled outputs (N, p), absolute.
    r : ndarray
        The references (N, q), absolute.
    artifact : Artifact
        The design (signal names, tracked outputs, operating point).
    start : str
        Where the model twin started (for the record).

    Returns
    -------
    ModelMismatch
    """
    a = artifact
    outputs = {}
    for i, name in enumerate(a.signals["outputs"]):
        dy = float(np.max(np.abs(y[:, i] - model_y[:, i]), initial=0.0))
        span = float(max(np.ptp(y[:, i]), np.ptp(model_y[:, i]))) if t.size else 0.0
        rel = dy / span if span > 0 else (0.0 if dy == 0 else float("inf"))
        outputs[name] = {"max_dy": dy, "range": span, "max_dy_rel": rel}
    iae = _iae_ratios(t, y, r, model_y, a)
    rels = [v["max_dy_rel"] for v in outputs.values()]
    worst = max(rels, default=0.0)
    return ModelMismatch(outputs=outputs, iae=iae, worst=worst if np.isfinite(worst) else None, start=start)


def _iae_ratios(t: np.ndarray, y: np.ndarray, r: np.ndarray, model_y: np.ndarray, a: Artifact) -> dict:
    """Per tracked output (per output about the operating point without integral action): IAE of the plant, of
    the model twin, and their ratio."""
    dt = float(t[1] - t[0]) if t.size > 1 else 0.0
    if a.q:
        errors = {
            n: (r[:, j] - y @ a.Ci[j], r[:, j] - model_y @ a.Ci[j]) for j, n in enumerate(a.signals["references"])
        }
    else:
        errors = {n: (a.y_op[i] - y[:, i], a.y_op[i] - model_y[:, i]) for i, n in enumerate(a.signals["outputs"])}
    out = {}
    for name, (e_plant, e_model) in errors.items():
        plant, model = float(np.sum(np.abs(e_plant)) * dt), float(np.sum(np.abs(e_model)) * dt)
        out[name] = {"plant": plant, "model": model, "ratio": plant / model if model > 0 else None}
    return out


def _clean(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj
