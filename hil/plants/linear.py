"""A linear plant from any spec or artifact, with optional parameter perturbation.

``[plant] kind = "linear"`` simulates ``A, B, C, D`` exactly (zero-order hold through the matrix
exponential for a continuous model; a discrete model advances only by its own ``Ts``) about the model's
operating point: its state is the deviation, its inputs and outputs are absolute
(``dx/dt = A x + B (u - u_op)``, ``y = y_op + C x + D (u - u_op)``). The model
comes from ``spec = "plant.toml"``, ``artifact = "gains.json"`` or, by default, the scenario's own
artifact. Perturbation (the Monte-Carlo hook of campaigns) is :func:`perturb_model`:

``perturb = { "A[1][0]" = 0.1, "B[3][0]" = -0.05 }``
    relative change of single entries, zero-based ``[row][column]`` as numpy indexes them:
    ``A[1][0] <- A[1][0] * (1 + 0.1)``. A zero entry stays zero (the model's structure is kept).
``scale = { "B" = 1.2 }``
    a factor for a whole matrix (applied before the entry perturbations).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from gainlink.errors import GainlinkError, PlantError, did_you_mean
from gainlink.lti import StateSpaceModel
from gainlink.proof.sampled_plant import SampledPlant

from ..registry import take_keys
from .base import PLANTS, Plant

_ENTRY = re.compile(r"^([ABCD])\[(\d+)\]\[(\d+)\]$")
MATRICES = ("A", "B", "C", "D")


@dataclass(frozen=True, kw_only=True)
class LinearModel(StateSpaceModel):
    """A linear plant model (``Ts`` is ``None`` for a continuous one) about its operating point ``u_op``, ``y_op``
    (``None``: the origin)."""

    name: str
    u_op: np.ndarray | None = None
    y_op: np.ndarray | None = None


def model_from_spec(path: str | Path) -> LinearModel:
    """The plant of a spec file (a transfer function as the spec realises it, Padé delays included)."""
    from gainlink.spec import load_spec

    try:
        spec = load_spec(path)
    except GainlinkError as exc:
        raise PlantError(f"plant linear: {exc}") from None
    op = spec.operating_point
    return LinearModel(
        name=spec.name,
        A=spec.plant.A,
        B=spec.plant.B,
        C=spec.plant.C,
        D=spec.plant.D,
        Ts=None if spec.plant.continuous else spec.Ts,
        states=spec.plant.states,
        inputs=spec.plant.inputs,
        outputs=spec.plant.outputs,
        u_op=None if op is None else op.u_op,
        y_op=None if op is None else op.y_op,
    )


def model_from_artifact(artifact: Any) -> LinearModel:
    """The plant model recorded in an artifact (``artifact.data["plant"]``)."""
    pl = artifact.data["plant"]
    A = np.array(pl["A"], float)
    sig = artifact.signals
    n = A.shape[0]
    states = tuple(sig["states"]) if len(sig["states"]) == n else tuple(f"x{i}" for i in range(n))
    return LinearModel(
        name=artifact.name,
        A=A,
        B=np.array(pl["B"], float),
        C=np.array(pl["C"], float),
        D=np.array(pl["D"], float),
        Ts=artifact.Ts if pl["kind"] == "discrete" else None,
        states=states,
        inputs=tuple(sig["inputs"]),
        outputs=tuple(sig["outputs"]),
        u_op=artifact.u_op,
        y_op=artifact.y_op,
    )


def _factors(table: Any, what: str) -> dict:
    if table is None:
        return {}
    if not isinstance(table, Mapping):
        raise PlantError(f"plant linear: {what} must be a table of numbers")
    out = {}
    for key, value in table.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
            raise PlantError(f"plant linear: {what} {key!r} must be a finite number, not {value!r}")
        out[str(key)] = float(value)
    return out


def perturb_model(
    model: LinearModel, *, perturb: Mapping[str, float] | None = None, scale: Mapping[str, float] | None = None
) -> LinearModel:
    """A copy of ``model`` with whole matrices scaled and single entries changed relatively.

    Parameters
    ----------
    model : LinearModel
        The nominal model (left unchanged).
    perturb : mapping, optional
        ``"A[i][j]" -> delta``: the entry becomes ``A[i][j] * (1 + delta)`` (zero-based indices).
    scale : mapping, optional
        ``"A" | "B" | "C" | "D" -> factor`` multiplying the whole matrix (applied first).

    Returns
    -------
    LinearModel

    Raises
    ------
    PlantError
        An unknown matrix, an entry outside the matrix, or a non-finite number (one line).

    Examples
    --------
    >>> import numpy as np
    >>> m = LinearModel(name="m", A=np.array([[0.0, 1.0], [-2.0, -3.0]]), B=np.array([[0.0], [1.0]]),
    ...                 C=np.eye(2), D=np.zeros((2, 1)), Ts=None, states=("x", "v"), inputs=("u",),
    ...                 outputs=("x", "v"))
    >>> perturb_model(m, perturb={"A[1][0]": 0.1}, scale={"B": 2.0}).A[1, 0]
    -2.2
    """
    mats = {k: np.array(getattr(model, k), float) for k in MATRICES}
    for key, factor in _factors(scale, "scale").items():
        if key not in mats:
            raise PlantError(f"plant linear: scale names matrix {key!r}; use one of A, B, C, D")
        mats[key] *= factor
    for key, delta in _factors(perturb, "perturb").items():
        match = _ENTRY.match(key.replace(" ", ""))
        if match is None:
            raise PlantError(
                f'plant linear: perturb key {key!r} is not of the form "A[i][j]" (B, C, D too; zero-based)'
            )
        name, i, j = match.group(1), int(match.group(2)), int(match.group(3))
        rows, cols = mats[name].shape
        if i >= rows or j >= cols:
            raise PlantError(f"plant linear: perturb {key} is outside {name} ({rows}x{cols}, zero-based indices)")
        mats[name][i, j] *= 1.0 + delta
    return replace(model, **mats)


class LinearPlant(Plant):
    """A :class:`LinearModel` simulated exactly under a held input.

    Parameters
    ----------
    model : LinearModel
        Continuous (advanced by the matrix exponential for any ``dt``) or discrete (only by ``Ts``).
    """

    def __init__(self, *, model: LinearModel) -> None:
        self.model = model
        self.name = f"linear({model.name})"
        self.A, self.B, self.C, self.D = model.A, model.B, model.C, model.D
        self.state_names, self.input_names, self.output_names = model.states, model.inputs, model.outputs
        self._disc: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        # Stepped with the transition of each step's length (a continuous model is sampled per dt).
        self._sampled = SampledPlant(self.A, self.B, self.C, self.D, u_op=model.u_op, y_op=model.y_op)

    def _discrete(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        if dt not in self._disc:
            Ts = self.model.Ts
            if Ts is not None:
                if abs(dt - Ts) > 1e-12 * Ts:
                    raise PlantError(f"discrete plant can only advance by Ts={Ts}, not {dt}")
                self._disc[dt] = (self.A, self.B)
            else:
                from scipy.linalg import expm  # only a continuous model needs it: imported here

                n, m = self.B.shape
                big = np.zeros((n + m, n + m))
                big[:n, :n], big[:n, n:] = self.A, self.B
                e = expm(big * dt)
                self._disc[dt] = (e[:n, :n], e[:n, n:])
        return self._disc[dt]

    def reset(self, *, initial: Mapping[str, float]) -> None:
        """Back to the operating point, then ``initial`` (state name -> deviation from it)."""
        x0 = np.zeros(self.A.shape[0])
        for key, value in initial.items():
            if key not in self.state_names:
                raise PlantError(
                    f"plant {self.name} has no state {key!r}{did_you_mean(key, self.state_names)} "
                    f"(has: {', '.join(self.state_names)})"
                )
            x0[self.state_names.index(key)] = float(value)
        self._sampled.reset(x0)

    def outputs(self) -> np.ndarray:
        return self._sampled.outputs()

    def state(self) -> np.ndarray:
        return self._sampled.state

    def advance(self, *, u: np.ndarray, dt: float) -> None:
        self._sampled.advance(u, transition=self._discrete(dt))

    def save_state(self) -> Any:
        return self._sampled.save()

    def restore_state(self, snapshot: Any) -> None:
        self._sampled.restore(snapshot)


def _source_path(value: Any, *, base_dir: Path | None, what: str) -> Path:
    if not isinstance(value, str) or not value:
        raise PlantError(f"plant linear: {what} must be a file name")
    p = Path(value)
    return base_dir / p if not p.is_absolute() and base_dir is not None else p


@PLANTS.register("linear")
def _linear_factory(
    config: Mapping[str, Any], *, artifact: Any = None, base_dir: Path | None = None, **_context: Any
) -> Plant:
    cfg = take_keys(
        config, allowed={"kind", "spec", "artifact", "perturb", "scale"}, where="plant linear", error=PlantError
    )
    if "spec" in cfg and "artifact" in cfg:
        raise PlantError("plant linear: give spec or artifact, not both")
    if "spec" in cfg:
        model = model_from_spec(_source_path(cfg["spec"], base_dir=base_dir, what="spec"))
    elif "artifact" in cfg:
        from gainlink.shipping.artifact import load

        try:
            model = model_from_artifact(load(_source_path(cfg["artifact"], base_dir=base_dir, what="artifact")))
        except GainlinkError as exc:
            raise PlantError(f"plant linear: {exc}") from None
    elif artifact is not None:
        model = model_from_artifact(artifact)
    else:
        raise PlantError(
            'plant linear needs a model: spec = "plant.toml", artifact = "gains.json", or the scenario\'s artifact'
        )
    if "perturb" in cfg or "scale" in cfg:
        model = perturb_model(model, perturb=cfg.get("perturb"), scale=cfg.get("scale"))
    return LinearPlant(model=model)
