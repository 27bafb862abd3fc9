"""Built-in plant models: nonlinear cart pendulum, quadrotor lateral channel, Wood-Berry column
(the linear plant of a spec or artifact is :mod:`gainlink.hil.plants.linear`).

Continuous models integrate with fixed-step RK4 (sub-steps no longer than ``step`` seconds).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping
from typing import Any, ClassVar

import numpy as np
from gainlink.errors import PlantError, did_you_mean

from ..registry import take_keys
from .base import PLANTS, Plant, select
from .kernel import Rows

_COMMON_KEYS = {"kind", "inputs", "outputs", "parameters", "step"}


def substeps(dt: float, h: float) -> tuple[int, float]:
    """The RK4 sub-steps of a sample ``dt``: how many (none longer than ``h``) and their length."""
    n = max(1, math.ceil(dt / h - 1e-9))
    return n, dt / n


def rk4(
    rates: Callable[[np.ndarray, np.ndarray, Mapping[str, np.ndarray]], np.ndarray],
    X: np.ndarray,
    U: np.ndarray,
    P: Mapping[str, np.ndarray],
    *,
    dt: float,
    h: float,
) -> np.ndarray:
    """Advance a batch of states ``X`` (B, n) under held full inputs ``U`` (B, inputs) by ``dt`` with fixed-step RK4
    (sub-steps no longer than ``h``); ``P`` holds each parameter as a (B,) column.

    The numpy kernel of a continuous plant (a user's :class:`OdePlant`, and the readable definition the compiled
    kernel of the built-in models follows operation for operation, but for sin and cos, SLEEF's there, within an ulp
    of numpy's: :mod:`.kernel`): a run alone steps it with a batch of one, a campaign block with its runs stacked.
    Every operation is elementwise in the batch (no product sums across it), so a run's row is the same bit for bit
    at any batch size. A row that overflows comes out non-finite (the caller refuses it).
    """
    n, hh = substeps(dt, h)
    half, sixth = 0.5 * hh, hh / 6.0
    T, acc = np.empty_like(X), np.empty_like(X)  # the stage's state and the weighted sum: this kernel's own buffers
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        for _ in range(n):  # X + (hh / 6) (k1 + 2 k2 + 2 k3 + k4), each product and sum in that order, in place
            k1 = rates(X, U, P)
            k2 = rates(np.add(X, np.multiply(k1, half, out=T), out=T), U, P)
            np.multiply(k2, 2.0, out=acc)
            np.add(k1, acc, out=acc)
            k3 = rates(np.add(X, np.multiply(k2, half, out=T), out=T), U, P)
            k4 = rates(np.add(X, np.multiply(k3, hh, out=T), out=T), U, P)
            acc += np.multiply(k3, 2.0, out=T)
            acc += k4
            X = X + np.multiply(acc, sixth, out=acc)
    return X


class OdePlant(Plant):
    """A continuous plant ``dx/dt = f(x, u)`` whose outputs are a selection of its states.

    Subclasses set ``name``, ``all_inputs``, ``state_names``, ``defaults`` (parameters) and implement :meth:`rates`
    over a batch axis (the kernel of :func:`rk4`); :meth:`clamp` is applied to the state after each sample. A run
    alone steps as a batch of one (:class:`OdeBatch`), so it steps as its row in a campaign block does.
    """

    all_inputs: tuple[str, ...]
    defaults: ClassVar[Mapping[str, float]]
    #: Steps in a campaign block (:class:`OdeBatch`): declared by each class in its own body, not inherited, because a
    #: block steps only :meth:`rates` and :meth:`clamp` (a subclass that overrides ``advance`` or ``outputs`` runs
    #: alone unless it declares itself vectorised again).
    vectorised: ClassVar[bool] = False
    #: The built-in models' compiled RK4 (``native/ode.c``, function ``gl_ode_<name>``): the parameter columns it
    #: takes, in its order (the parameters, then the :meth:`derived` ones); None: :func:`rk4` over :meth:`rates`.
    #: Declared in the class's own body, as ``vectorised``: a subclass that changes :meth:`rates` or :meth:`clamp`
    #: steps through numpy unless it declares a kernel of its own.
    native: ClassVar[tuple[str, ...] | None] = None

    def __init__(
        self,
        *,
        parameters: Mapping[str, float] | None = None,
        inputs: Any = None,
        outputs: Any = None,
        step: float = 1e-3,
    ) -> None:
        params = dict(self.defaults)
        for key, value in (parameters or {}).items():
            if key not in params:
                raise PlantError(
                    f"plant {self.name} has no parameter {key!r}{did_you_mean(key, params)} (has: {', '.join(params)})"
                )
            params[key] = float(value)
        self.params = params
        self._in_idx = select(self.all_inputs, inputs, what="inputs", plant=self.name)
        self._out_idx = select(
            self.state_names, outputs if outputs is not None else self.default_outputs, what="outputs", plant=self.name
        )
        self.input_names = tuple(self.all_inputs[i] for i in self._in_idx)
        self.output_names = tuple(self.state_names[i] for i in self._out_idx)
        if not step > 0:
            raise PlantError(f"plant {self.name}: step must be positive")
        self.h = float(step)
        self.x = np.zeros(len(self.state_names))
        self._one: OdeBatch | None = None  # the batch of one this plant steps as, made at its first advance

    default_outputs: tuple[str, ...] = ()

    def rates(self, X: np.ndarray, U: np.ndarray, P: Mapping[str, np.ndarray]) -> np.ndarray:  # pragma: no cover
        """dx/dt of each row of ``X`` (B, n) under full inputs ``U`` (B, inputs) and parameter columns ``P`` (with
        the :meth:`derived` ones), as a new array (:func:`rk4` reuses the ``X`` it passes)."""
        raise NotImplementedError

    @staticmethod
    def derived(P: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Columns :meth:`rates` uses computed once from the parameter columns ``P`` instead of at every call (a
        product ``m * l * w`` evaluates ``m * l`` first, so taking it from a column changes no bit); none here."""
        return {}

    @functools.cached_property
    def _P(self) -> dict[str, np.ndarray]:
        """The kernel's parameter columns of this plant alone (a batch of one), made when first asked: a campaign
        block builds a plant per run and never asks (its batch gathers the runs' ``params``)."""
        return columns(type(self), {k: np.array([v]) for k, v in self.params.items()})

    def derivatives(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """dx/dt at one state ``x`` and full input vector ``u`` (the kernel with a batch of one)."""
        return self.rates(np.asarray(x, float)[None, :], np.asarray(u, float)[None, :], self._P)[0]

    def clamp(self, X: np.ndarray) -> np.ndarray:
        """The state after a sample (a plant with a hard limit clamps it here); the default keeps it."""
        return X

    def reset(self, *, initial: Mapping[str, float]) -> None:
        self.x = np.zeros(len(self.state_names))
        for key, value in initial.items():
            if key not in self.state_names:
                raise PlantError(
                    f"plant {self.name} has no state {key!r}{did_you_mean(key, self.state_names)} "
                    f"(has: {', '.join(self.state_names)})"
                )
            self.x[self.state_names.index(key)] = float(value)

    def outputs(self) -> np.ndarray:
        return self.x[self._out_idx]

    def state(self) -> np.ndarray:
        return self.x.copy()

    def advance(self, *, u: np.ndarray, dt: float) -> None:
        one = self._one = self._one or OdeBatch([self])
        one.X[0] = self.x
        if one.advance(np.asarray(u)[None], dt=dt)[0]:
            raise PlantError(non_finite(self.name))
        self.x = one.X[0].copy()

    def save_state(self) -> Any:
        return self.x.copy()

    def restore_state(self, snapshot: Any) -> None:
        self.x = np.array(snapshot, dtype=float)


def columns(cls: type, P: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The parameter columns ``P`` of plants of ``cls`` with its :meth:`OdePlant.derived` ones."""
    return P | cls.derived(P)


def non_finite(name: str) -> str:
    """Why a plant's run ends when its state overflows (alone, or its row in a block)."""
    return f"plant {name}: state became non-finite"


class OdeBatch:
    """Plants of one kind stepped together: their states stacked (B, n), their parameters as columns. A campaign
    block steps its runs' plants so, a plant alone steps as a batch of one: the same kernel either way, the
    compiled RK4 of a built-in model (:mod:`.kernel`, its rows advanced in place) or :func:`rk4` over the class's
    :meth:`~OdePlant.rates`. ``plants`` are reset already; they must share the class, the selected inputs and
    outputs and the sub-step (:func:`batchable` says whether they do).

    A row whose state becomes non-finite is *failed*: it keeps its last finite state and :meth:`advance` reports
    it, as the plant alone raises (the run ends there).
    """

    def __init__(self, plants: list[OdePlant]) -> None:
        first = plants[0]
        self.kernel, self.name, self.h = first, first.name, first.h
        X = np.stack([p.x for p in plants])
        self.P = columns(type(first), {k: np.array([p.params[k] for p in plants]) for k in first.params})
        self._in_idx, self._out_idx = first._in_idx, first._out_idx
        lo = self._in_idx[0] if self._in_idx else 0  # inputs selected in order: a slice, cheaper than a list
        in_order = list(self._in_idx) == list(range(lo, lo + len(self._in_idx)))
        self._in_cols = slice(lo, lo + len(self._in_idx)) if in_order else self._in_idx
        native = vars(type(first)).get("native")
        self._rows = None if native is None else Rows(first.name, X, np.column_stack([self.P[k] for k in native]),
                                                      inputs=len(first.all_inputs))  # fmt: skip
        self.X = np.asfortranarray(X) if self._rows is None else self._rows.X  # numpy: each state a contiguous column
        self._U = np.zeros((len(plants), len(first.all_inputs))) if self._rows is None else self._rows.U

    def outputs(self) -> np.ndarray:
        """Every row's outputs (B, p)."""
        return self.X[:, self._out_idx]

    def c_plant(self, *, dt: float) -> dict | None:
        """How a loop written in C steps this batch as :meth:`advance` does for ``dt`` (``gainlink.hil.loop
        .lockstep``): the compiled RK4's function and rows (advanced in place), the sub-steps, the outputs' and the
        selected inputs' columns; None when the batch steps through numpy (:func:`rk4`)."""
        if self._rows is None:
            return None
        n, hh = substeps(dt, self.h)
        rows = self._rows
        return {"fn": rows.address, "X": rows.X, "U": rows.U, "P": rows.P, "failed": rows.failed,
                "nx": rows.X.shape[1], "nu": rows.U.shape[1], "npar": rows.P.shape[1], "substeps": n, "hh": hh,
                "out_idx": np.array(self._out_idx, dtype=np.int64),
                "in_idx": np.array(self._in_idx, dtype=np.int64)}  # fmt: skip

    def advance(self, U: np.ndarray, *, dt: float) -> np.ndarray:
        """Hold each row's command ``U`` (B, inputs selected) for ``dt``; returns the rows that failed now."""
        full = self._U
        full[:, self._in_cols] = U  # the inputs not selected stay zero
        if self._rows is not None:
            self._rows.advance(*substeps(dt, self.h))
            return self._rows.failed.copy()
        X = self.kernel.clamp(rk4(self.kernel.rates, self.X, full, self.P, dt=dt, h=self.h))
        failed = ~np.isfinite(X).all(axis=1)
        if failed.any():
            X[failed] = self.X[failed]
        self.X = X
        return failed


def batchable(plants: list[Plant]) -> bool:
    """Whether ``plants`` can step as one :class:`OdeBatch`: models of one class that declares itself vectorised
    (``vectorised = True`` in its own body: the built-in ones, or a user's), the same inputs, outputs and sub-step."""
    first = plants[0]
    if not isinstance(first, OdePlant) or vars(type(first)).get("vectorised") is not True:
        return False
    return all(
        type(p) is type(first) and p._in_idx == first._in_idx and p._out_idx == first._out_idx and p.h == first.h
        for p in plants
    )


class CartPendulum(OdePlant):
    """Cart with an inverted point-mass pendulum (theta from upright, positive force gives negative theta_ddot).

    With s = sin(theta), c = cos(theta), w = theta_dot and D = M + m s^2::

        x_ddot     = (F + m l w^2 s - m g s c) / D
        theta_ddot = ((M + m) g s - c (F + m l w^2 s)) / (l D)

    About upright: A = [[0,1,0,0],[0,0,-m g/M,0],[0,0,0,1],[0,0,(M+m) g/(M l),0]], B = [0,1/M,0,-1/(M l)].
    """

    name = "cart_pendulum"
    vectorised = True
    native = ("M", "m", "l", "g", "ml", "mg", "Mmg")
    all_inputs = ("F",)
    state_names = ("x", "x_dot", "theta", "theta_dot")
    default_outputs = ("x", "theta")
    defaults: ClassVar[Mapping[str, float]] = {"M": 1.0, "m": 0.1, "l": 0.5, "g": 9.81}

    @staticmethod
    def derived(P: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {"ml": P["m"] * P["l"], "mg": P["m"] * P["g"], "Mmg": (P["M"] + P["m"]) * P["g"]}

    def rates(self, X: np.ndarray, U: np.ndarray, P: Mapping[str, np.ndarray]) -> np.ndarray:
        # Each product and sum in the order of the docstring's equations. Plain expressions, not in-place ones:
        # numpy's in-place operators cost twice a new array at a batch of one (a run alone) and gain ~4 % at 1,000.
        th, w = X[:, 2], X[:, 3]
        s, c = np.sin(th), np.cos(th)
        D = P["M"] + P["m"] * s * s
        f = U[:, 0] + P["ml"] * w * w * s
        out = np.empty_like(X)  # columns assigned: np.stack costs 3x this at a batch of one
        out[:, 0], out[:, 1], out[:, 2], out[:, 3] = (
            X[:, 1],
            (f - P["mg"] * s * c) / D,
            w,
            (P["Mmg"] * s - c * f) / (P["l"] * D),
        )
        return out


class QuadrotorLateral(OdePlant):
    """Lateral channel of a quadrotor holding altitude (thrust m g / cos(phi)), as examples/quadrotor_lateral.toml.

    States phi (roll), p (roll rate), v (lateral speed), y (lateral position); input roll torque tau::

        phi_dot = p,  p_dot = tau / Ixx,  v_dot = g tan(phi) - (c_d / mass) v,  y_dot = v

    About hover (c_d = 0): A = [[0,1,0,0],[0,0,0,0],[g,0,0,0],[0,0,1,0]], B = [0, 1/Ixx, 0, 0].
    """

    name = "quadrotor_lateral"
    vectorised = True
    native = ("g", "Ixx", "mass", "c_d")
    all_inputs = ("tau",)
    state_names = ("phi", "p", "v", "y")
    default_outputs = ("phi", "y")
    defaults: ClassVar[Mapping[str, float]] = {"g": 9.81, "Ixx": 0.01, "mass": 1.0, "c_d": 0.0}

    def rates(self, X: np.ndarray, U: np.ndarray, P: Mapping[str, np.ndarray]) -> np.ndarray:
        v = X[:, 2]
        out = np.empty_like(X)
        out[:, 0], out[:, 1], out[:, 2], out[:, 3] = (
            X[:, 1],
            U[:, 0] / P["Ixx"],
            P["g"] * np.tan(X[:, 0]) - P["c_d"] / P["mass"] * v,
            v,
        )
        return out


class WoodBerry(Plant):
    """The Wood-Berry distillation column: four first-order lags with pure dead times (minutes).

    ``x_D = 12.8 e^{-s}/(16.7 s+1) reflux - 18.9 e^{-3 s}/(21 s+1) steam``,
    ``x_B = 6.6 e^{-7 s}/(10.9 s+1) reflux - 19.4 e^{-3 s}/(14.4 s+1) steam`` (names as examples/wood_berry.toml).
    Each lag is discretised exactly (zero-order hold) at the sub-step ``step``; each dead time is an
    input history of ``round(delay / step)`` sub-steps, so choose ``step`` dividing the delays and ``Ts``.
    """

    name = "wood_berry"
    GAIN = np.array([[12.8, -18.9], [6.6, -19.4]])
    TAU = np.array([[16.7, 21.0], [10.9, 14.4]])
    DELAY = np.array([[1.0, 3.0], [7.0, 3.0]])
    all_inputs = ("reflux", "steam")
    all_outputs = ("x_D", "x_B")

    def __init__(
        self,
        *,
        parameters: Mapping[str, float] | None = None,
        inputs: Any = None,
        outputs: Any = None,
        step: float = 0.1,
    ) -> None:
        if parameters:
            raise PlantError("plant wood_berry takes no parameters")
        if not step > 0:
            raise PlantError("plant wood_berry: step must be positive")
        self._in_idx = select(self.all_inputs, inputs, what="inputs", plant=self.name)
        self._out_idx = select(self.all_outputs, outputs, what="outputs", plant=self.name)
        self.input_names = tuple(self.all_inputs[i] for i in self._in_idx)
        self.output_names = tuple(self.all_outputs[i] for i in self._out_idx)
        self.state_names = ("y11", "y12", "y21", "y22")
        self.h = float(step)
        self.a = np.exp(-self.h / self.TAU)
        self.d = np.rint(self.DELAY / self.h).astype(int)
        self.hist_len = int(self.d.max()) + 1
        self.reset(initial={})

    def reset(self, *, initial: Mapping[str, float]) -> None:
        self.y = np.zeros((2, 2))
        self.hist = np.zeros((self.hist_len, 2))  # ring buffer of full input vectors, newest at self.k
        self.k = 0
        for key, value in initial.items():
            if key not in self.state_names:
                raise PlantError(
                    f"plant wood_berry has no state {key!r}{did_you_mean(key, self.state_names)} "
                    f"(has: {', '.join(self.state_names)})"
                )
            i = self.state_names.index(key)
            self.y[i // 2, i % 2] = float(value)

    def outputs(self) -> np.ndarray:
        return self.y.sum(axis=1)[self._out_idx]

    def state(self) -> np.ndarray:
        return self.y.ravel().copy()

    def advance(self, *, u: np.ndarray, dt: float) -> None:
        full = np.zeros(2)
        full[self._in_idx] = u
        n = max(1, int(round(dt / self.h)))
        for _ in range(n):
            self.k = (self.k + 1) % self.hist_len
            self.hist[self.k] = full
            for i in range(2):
                for j in range(2):
                    uj = self.hist[(self.k - self.d[i, j]) % self.hist_len, j]
                    self.y[i, j] = self.a[i, j] * self.y[i, j] + (1.0 - self.a[i, j]) * self.GAIN[i, j] * uj

    def save_state(self) -> Any:
        return (self.y.copy(), self.hist.copy(), self.k)

    def restore_state(self, snapshot: Any) -> None:
        y, hist, k = snapshot
        self.y, self.hist, self.k = y.copy(), hist.copy(), k


def _ode_factory(cls: type) -> Any:
    def factory(config: Mapping[str, Any], **_context: Any) -> Plant:
        cfg = take_keys(config, allowed=_COMMON_KEYS, where=f"plant {cls.name}", error=PlantError)
        kwargs = {k: cfg[k] for k in ("parameters", "inputs", "outputs", "step") if k in cfg}
        return cls(**kwargs)

    return factory


PLANTS.register("cart_pendulum")(_ode_factory(CartPendulum))
PLANTS.register("quadrotor_lateral")(_ode_factory(QuadrotorLateral))
PLANTS.register("wood_berry")(_ode_factory(WoodBerry))
