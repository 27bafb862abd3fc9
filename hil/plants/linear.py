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


def rowsum(M: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``M @ v`` for each row of a batch (``M`` (B, r, c) or (1, r, c), ``v`` (B, c)) as a fixed chain of elementwise
    multiply-adds, summed left to right over the columns: a run's sums are the same at any batch size (a BLAS
    product picks its own order, per machine and size)."""
    B, rows = v.shape[0], M.shape[1]
    if M.shape[2] == 0:
        return np.zeros((B, rows))
    acc = M[:, :, 0] * v[:, None, 0]
    for j in range(1, M.shape[2]):
        acc = acc + M[:, :, j] * v[:, None, j]
    return acc


class LinearPlant(Plant):
    """A :class:`LinearModel` simulated exactly under a held input.

    ``x+ = Ad x + Bd (u - u_op)``, ``y = y_op + C x + D (u_prev - u_op)`` (the feed-through acts on the command
    held over the last sample), stepped by :func:`rowsum`, the kernel a campaign block steps its linear plants with
    (:class:`LinearBatch`): a plant alone is a batch of one.

    Parameters
    ----------
    model : LinearModel
        Continuous (advanced by the matrix exponential for any ``dt``) or discrete (only by ``Ts``).
    """

    def __init__(self, *, model: LinearModel) -> None:
        self.model = model
        self.name = f"linear({model.name})"
        self.A, self.B, self.C, self.D = (np.asarray(getattr(model, k), float) for k in MATRICES)
        self.state_names, self.input_names, self.output_names = model.states, model.inputs, model.outputs
        self._disc: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        n, m = self.B.shape
        self.u_op = np.zeros(m) if model.u_op is None else np.asarray(model.u_op, float)
        self.y_op = np.zeros(self.C.shape[0]) if model.y_op is None else np.asarray(model.y_op, float)
        self.X, self.dU = np.zeros((1, n)), np.zeros((1, m))

    def discrete(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """``(Ad, Bd)`` of one step of ``dt`` (the model's own for a discrete one, which advances only by ``Ts``)."""
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
        self.X, self.dU = x0[None, :], np.zeros_like(self.dU)

    def outputs(self) -> np.ndarray:
        return (self.y_op + rowsum(self.C[None], self.X) + rowsum(self.D[None], self.dU))[0]

    def state(self) -> np.ndarray:
        return self.X[0].copy()

    def advance(self, *, u: np.ndarray, dt: float) -> None:
        Ad, Bd = self.discrete(dt)
        self.dU = (np.asarray(u, dtype=float) - self.u_op).reshape(1, -1)
        self.X = rowsum(Ad[None], self.X) + rowsum(Bd[None], self.dU)

    def save_state(self) -> Any:
        return self.X.copy(), self.dU.copy()

    def restore_state(self, snapshot: Any) -> None:
        self.X, self.dU = snapshot[0].copy(), snapshot[1].copy()


class LinearBatch:
    """Linear plants of one shape stepped together (a campaign block): each its own (perturbed) matrices, stacked
    (B, ., .), the :func:`rowsum` kernel a plant alone steps. ``plants`` are reset already."""

    def __init__(self, plants: list[LinearPlant]) -> None:
        self.name = plants[0].name
        self._plants = plants
        self.X = np.concatenate([p.X for p in plants])
        self.dU = np.concatenate([p.dU for p in plants])
        self.C, self.D = np.stack([p.C for p in plants]), np.stack([p.D for p in plants])
        self.y_op, self.u_op = np.stack([p.y_op for p in plants]), np.stack([p.u_op for p in plants])
        self._disc: dict[float, tuple[np.ndarray, np.ndarray]] = {}

    def outputs(self) -> np.ndarray:
        """Every row's outputs (B, p)."""
        return self.y_op + rowsum(self.C, self.X) + rowsum(self.D, self.dU)

    def advance(self, U: np.ndarray, *, dt: float) -> np.ndarray:
        """Hold each row's command ``U`` (B, m) for ``dt``; returns the rows that failed (none: a linear plant
        does not fail, as a plant alone does not)."""
        if dt not in self._disc:
            pairs = [p.discrete(dt) for p in self._plants]
            self._disc[dt] = (np.stack([a for a, _ in pairs]), np.stack([b for _, b in pairs]))
        Ad, Bd = self._disc[dt]
        self.dU = np.asarray(U, dtype=float) - self.u_op
        self.X = rowsum(Ad, self.X) + rowsum(Bd, self.dU)
        return np.zeros(self.X.shape[0], dtype=bool)


def linear_batchable(plants: list) -> bool:
    """Whether ``plants`` can step as one :class:`LinearBatch`: linear plants of one shape and kind of time."""
    first = plants[0]
    if not isinstance(first, LinearPlant):
        return False
    return all(
        isinstance(p, LinearPlant) and p.A.shape == first.A.shape and p.B.shape == first.B.shape
        and p.C.shape == first.C.shape and p.model.Ts == first.model.Ts
        for p in plants
    )  # fmt: skip


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
