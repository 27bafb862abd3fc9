"""Fixed-point designs for the C tests and the reference model's run in the same shape as the C's records."""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
from gainlink.fileio import read_toml
from gainlink.laws.fixed.model import FixedPointLoop
from gainlink.shipping.artifact import Artifact, from_dict
from gainlink.synthesis.random_plants import random_spec

from support.designs import designed
from support.paths import EXAMPLES

_CACHE: dict = {}


def example(name: str, numeric: str) -> Artifact:
    """The example ``name`` designed with ``[implementation] numeric`` (once per test run)."""
    key = (name, numeric)
    if key not in _CACHE:
        data, _ = read_toml(EXAMPLES / f"{name}.toml", what="spec", error=ValueError)
        data = copy.deepcopy(data)
        data["implementation"] = data.get("implementation", {}) | {"numeric": numeric}
        _CACHE[key] = from_dict(designed(data))
    return _CACHE[key]


def random_design(seed: int, numeric: str, y_range: float = 2.0, r_range: float = 1.0, **kw) -> Artifact:
    """A seeded random design (gainlink.synthesis.random_plants) certified in ``numeric`` with ranges +-y_range,
    +-r_range."""
    key = (seed, numeric, repr(sorted(kw.items())))
    if key not in _CACHE:
        spec = random_spec(seed, **kw)
        p, q = kw["p"], kw.get("q", 0)
        spec["limits"] = spec.get("limits", {}) | {"y_min": [-y_range] * p, "y_max": [y_range] * p}
        if q:
            spec["limits"] |= {"r_min": [-r_range] * q, "r_max": [r_range] * q}
        spec["implementation"] = {"numeric": numeric, "float32_check": False, "fixed_point_max_error": 0.5}
        _CACHE[key] = from_dict(designed(spec))
    return _CACHE[key]


@dataclass(frozen=True)
class ModelRun:
    """The integer model's steps: as gainlink.laws.fixed.firmware.FixedRun (masks as bit masks, overflow as names)."""

    U: np.ndarray
    V: np.ndarray
    XH: np.ndarray
    Z: np.ndarray
    sat: np.ndarray
    clip: np.ndarray
    fault: np.ndarray
    overflow: list


def model_run(a: Artifact, Y, R) -> ModelRun:
    """Run float32 samples through gainlink.laws.fixed.model (widened exactly to double, as the C does)."""
    loop = FixedPointLoop(a)
    Y = np.asarray(Y, dtype=np.float32).reshape(-1, a.p)
    R = np.asarray(R, dtype=np.float32).reshape(Y.shape[0], a.q)
    out: dict[str, list] = {k: [] for k in ("U", "V", "XH", "Z", "sat", "clip", "fault", "overflow")}
    for k in range(Y.shape[0]):
        s = loop.step_samples(Y[k].astype(np.float64), R[k].astype(np.float64))
        out["U"].append(s.U)
        out["V"].append(s.V)
        out["XH"].append(list(loop.XH))
        out["Z"].append(list(loop.Z))
        out["sat"].append(sum(1 << i for i, b in enumerate(s.saturated) if b))
        bits = list(s.clipped_y) + list(s.clipped_r)
        out["clip"].append(sum(1 << i for i, b in enumerate(bits) if b))
        out["fault"].append(s.fault)
        out["overflow"].append(set(s.overflow))
    arr = {k: np.array(v, dtype=np.int64) for k, v in out.items() if k not in ("overflow", "fault")}
    Z = arr["Z"].reshape(Y.shape[0], a.q)
    return ModelRun(arr["U"], arr["V"], arr["XH"], Z, arr["sat"], arr["clip"], np.array(out["fault"]), out["overflow"])


_PENDULUM_DESIGNS: dict = {}


def pendulum_design(numeric: str, q_diag=None, r_diag=None) -> Artifact:
    """The pendulum in ``numeric`` with other weights (``None``: the example's)."""
    key = (numeric, repr(q_diag), repr(r_diag))
    if key not in _PENDULUM_DESIGNS:
        data, _ = read_toml(EXAMPLES / "pendulum.toml", what="spec", error=ValueError)
        data = copy.deepcopy(data)
        data["implementation"] = {"numeric": numeric} | ({"fixed_point_max_error": 0.01} if numeric == "q15" else {})
        data["controller"]["Q_diag"] = q_diag or data["controller"]["Q_diag"]
        data["controller"]["R_diag"] = r_diag or data["controller"]["R_diag"]
        _PENDULUM_DESIGNS[key] = from_dict(designed(data))
    return _PENDULUM_DESIGNS[key]


class DesignLaw:
    """The design's float64 law written from the contract (docs/design.md, "The control law"), independently of
    gainlink's own law code: predictor or current observer, integrators with their anti-windup rule, the limits;
    state ``xh``, ``z`` (real values, settable)."""

    def __init__(self, a: Artifact) -> None:
        self.a = a
        self.xh, self.z = a.xh0.astype(float).copy(), a.z0.astype(float).copy()

    def step(self, y, r) -> tuple[np.ndarray, bool]:
        """One step on the absolute sample ``y`` and reference ``r``: the command and whether it saturated."""
        a = self.a
        y, r = np.asarray(y, dtype=float), np.asarray(r, dtype=float).reshape(a.q)
        dy = y - a.y_op
        xc = self.xh + a.M @ (dy - a.Cd @ self.xh) if a.observer_form == "current" else self.xh
        v = a.u_op - a.K @ xc - a.Ki @ self.z
        u = np.minimum(np.maximum(v, a.u_min), a.u_max)
        saturated = bool(np.any(u != v))
        if a.q:
            e = r - a.Ci @ y
            if a.anti_windup == "backcalc":
                self.z = self.z + a.Ts * e + a.Kaw @ (u - v)
            elif not (a.anti_windup == "clamp" and saturated):
                self.z = self.z + a.Ts * e
        du = u - a.u_op
        if a.observer_form == "current":
            self.xh = a.Ad @ xc + a.Bd @ du
        else:
            self.xh = a.Ad @ self.xh + a.Bd @ du + a.L @ (dy - a.Cd @ self.xh - a.Dd @ du)
        return u, saturated


def c_float(u: np.ndarray) -> np.ndarray:
    """The float the fixed-point C returns for commands ``u = U 2^-f_u``: ``(float)U`` times the power of two."""
    return np.asarray(u, dtype=np.float64).astype(np.float32).astype(np.float64)
