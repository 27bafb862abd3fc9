"""The scheduled block of a schema-2 artifact (``schedule``, read by the artifact loader through
``gainlink.shipping.artifact.BLOCKS["schedule"]``, which this family registers): the points, sigma's source and shaping,
and per point the coefficients the velocity-form law runs (docs/design.md, scheduled law).

Per point ``i`` the design gives the positional law in deviations (predictor or current form, one shape)::

    du  = -Kx xh - Ky dy - Ki z          xh+ = F xh + G du + Ly dy          z+ = z + Ts (r - Ci y)

with, predictor: ``F = Ad - L Cd``, ``G = Bd - L Dd``, ``Ly = L``, ``Kx = K``, ``Ky = 0``; current:
``F = Ad (I - M Cd)``, ``G = Bd``, ``Ly = Ad M``, ``Kx = K (I - M Cd)``, ``Ky = K M``. The scheduled law runs
``F G Ly Kx Ky`` and ``Kz = Ts Ki``, each interpolated linearly in sigma between the two points around it (the
coefficients, never ``Ad``, ``Cd``, ``L`` separately). :func:`coefficients_at` is that interpolation, the one
definition every check, the reference law and ``Artifact.controller(sigma=...)`` use.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import ArtifactError
from ...shipping.systems import coefficient_law, law_coefficients

#: The per-point coefficient arrays the C step runs, in its order of operations.
COEFFICIENTS = ("Kx", "Ky", "Kz", "F", "G", "Ly")
#: Per-point design matrices kept for the record (and the frozen-point checks).
DESIGN_MATRICES = ("Ad", "Bd", "Cd", "Dd", "K", "L", "Ki")


def interval(points: np.ndarray, sigma: float) -> tuple[int, float]:
    """``(i, lam)`` with ``points[i] <= sigma <= points[i + 1]`` and ``lam = (sigma - points[i]) / (points[i + 1] -
    points[i])``; sigma must already be clipped into the envelope."""
    i = int(np.clip(np.searchsorted(points, sigma, side="right") - 1, 0, len(points) - 2))
    return i, float((sigma - points[i]) / (points[i + 1] - points[i]))


def lerp(stack: np.ndarray, i: int, lam: float) -> np.ndarray:
    """``stack[i] + lam (stack[i + 1] - stack[i])``: the interpolation the law runs (one multiply-add each)."""
    return stack[i] + lam * (stack[i + 1] - stack[i])


@dataclass(frozen=True)
class Schedule:
    """A loaded schedule: ``points`` (N), sigma's ``source``/``index``/``name``, ``external`` names, the shaping
    (``rate_max`` or None, ``rate_certified``: whether a Lyapunov certificate covers that rate, None included,
    ``filter_tau``, ``filter_alpha``), and per point stacked arrays: ``coef[name]`` of shape
    ``(N, rows, cols)`` for each of :data:`COEFFICIENTS`, ``design[name]`` for each of :data:`DESIGN_MATRICES`
    (``M`` too in the current form), ``u_op`` (N, m) and ``y_op`` (N, p)."""

    points: np.ndarray
    sigma: str
    source: str
    index: int
    external: tuple[str, ...]
    rate_max: float | None
    rate_certified: bool
    filter_tau: float
    filter_alpha: float
    coef: dict
    design: dict
    u_op: np.ndarray
    y_op: np.ndarray

    def clip(self, sigma: float) -> float:
        """sigma clipped into ``[points[0], points[-1]]``."""
        return float(min(max(sigma, self.points[0]), self.points[-1]))

    def coefficients_at(self, sigma: float) -> dict[str, np.ndarray]:
        """The law's coefficients at sigma (clipped into the envelope first), interpolated linearly."""
        i, lam = interval(self.points, self.clip(sigma))
        return {k: lerp(v, i, lam) for k, v in self.coef.items()}

    def trim_at(self, sigma: float) -> tuple[np.ndarray, np.ndarray]:
        """``(u_op, y_op)`` interpolated at sigma: they only initialise the law and give its safe command."""
        i, lam = interval(self.points, self.clip(sigma))
        return lerp(self.u_op, i, lam), lerp(self.y_op, i, lam)

    def plant_at(self, sigma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The design plant ``(Ad, Bd, Cd, Dd)`` at sigma: the points' sampled plants interpolated linearly (what
        every check between points takes as the plant there)."""
        i, lam = interval(self.points, self.clip(sigma))
        return tuple(lerp(self.design[k], i, lam) for k in ("Ad", "Bd", "Cd", "Dd"))


def filter_alpha(tau: float, Ts: float) -> float:
    """The sigma filter's gain per step, ``1 - exp(-Ts / tau)`` (the first-order lag sampled exactly; 1: none)."""
    return 1.0 if tau == 0 else float(-np.expm1(-Ts / tau))


def load_schedule(data: dict, *, n: int, m: int, p: int, q: int, form: str) -> Schedule:
    """The :class:`Schedule` of a schema-2 artifact dict, dimensions and invariants checked."""
    s = data["schedule"]
    points = np.array(s["points"], dtype=float)
    if points.size < 2 or np.any(np.diff(points) <= 0) or not np.all(np.isfinite(points)):
        raise ArtifactError("schedule.points must be at least two finite, strictly increasing values")
    entries = s["point"]
    if len(entries) != points.size:
        raise ArtifactError(f"schedule has {points.size} points but {len(entries)} entries in schedule.point")
    shapes = _shapes(n=n, m=m, p=p, q=q)
    names = COEFFICIENTS + DESIGN_MATRICES + (("M",) if form == "current" else ())
    stacked = {k: np.array([_matrix(e, k, shapes[k], i) for i, e in enumerate(entries)]) for k in names}
    u_op = np.array([_vector(e, "u_op", m, i) for i, e in enumerate(entries)])
    y_op = np.array([_vector(e, "y_op", p, i) for i, e in enumerate(entries)])
    _check_coefficients(stacked, entries, Ts=float(data["Ts"]), form=form)
    sig = s["sigma"]
    tau = float(s["filter_tau"])
    return Schedule(
        points=points,
        sigma=sig["name"],
        source=sig["source"],
        index=int(sig["index"]),
        external=tuple(s["external"]),
        rate_max=None if s.get("rate_max") is None else float(s["rate_max"]),
        # an artifact from before rate_certified proved nothing its rate_max can be trusted for: not certified
        rate_certified=bool(s.get("rate_certified", False)),
        filter_tau=tau,
        filter_alpha=float(s["filter_alpha"]),
        coef={k: stacked[k] for k in COEFFICIENTS},
        design={k: stacked[k] for k in names if k not in COEFFICIENTS},
        u_op=u_op,
        y_op=y_op,
    )


def _shapes(*, n: int, m: int, p: int, q: int) -> dict:
    return {"Kx": (m, n), "Ky": (m, p), "Kz": (m, q), "F": (n, n), "G": (n, m), "Ly": (n, p), "Ad": (n, n),
            "Bd": (n, m), "Cd": (p, n), "Dd": (p, m), "K": (m, n), "L": (n, p), "Ki": (m, q), "M": (n, p)}  # fmt: skip


def _matrix(entry: dict, key: str, shape: tuple[int, int], i: int) -> np.ndarray:
    if key not in entry:
        raise ArtifactError(f"schedule.point[{i}] lacks {key}")
    a = np.array(entry[key], dtype=float)
    if a.shape != shape:
        raise ArtifactError(f"schedule.point[{i}].{key} is {a.shape}, expected {shape}")
    if not np.all(np.isfinite(a)):
        raise ArtifactError(f"schedule.point[{i}].{key} holds a non-finite entry")
    return a


def _vector(entry: dict, key: str, length: int, i: int) -> np.ndarray:
    v = np.array(entry.get(key, [0.0] * length), dtype=float)
    if v.shape != (length,) or not np.all(np.isfinite(v)):
        raise ArtifactError(f"schedule.point[{i}].{key} must be {length} finite numbers")
    return v


def _check_coefficients(stacked: dict, entries: list, *, Ts: float, form: str) -> None:
    """Each point's coefficients must be the ones its design matrices give (an edited gain is caught here)."""
    for i in range(len(entries)):
        d = {k: stacked[k][i] for k in DESIGN_MATRICES}
        want = law_coefficients(**d, M=stacked["M"][i] if form == "current" else None, Ts=Ts, form=form)
        for k, w in want.items():
            got = stacked[k][i]
            if np.linalg.norm(got - w) > 1e-9 * max(1.0, float(np.linalg.norm(w))):
                raise ArtifactError(f"schedule.point[{i}].{k} is not the coefficient its design matrices give")


def frozen_coefficients(a, sigma: float | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The scheduled law's frozen-point ``(A, B, C, D)`` (:func:`gainlink.shipping.systems.controller_matrices`): its
    points' coefficients interpolated at ``sigma``."""
    c = a.schedule.coefficients_at(sigma)
    return coefficient_law(c["F"], c["G"], c["Ly"], c["Kx"], c["Ky"], c["Kz"] / a.Ts, Ci=a.Ci, Ts=a.Ts)
