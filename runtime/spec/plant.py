"""The ``[plant]`` table: state-space matrices (continuous or discrete) or a transfer-function matrix with dead
times, realised with Padé approximants as a minimal continuous state space."""

from __future__ import annotations

import numpy as np

from ..errors import SpecError
from .model import PlantModel, TransferFunctionSource
from .values import as_vector, matrix_key, no_unknown, signal_names

PLANT_KEYS = {
    "continuous": {"kind", "A", "B", "C", "D", "states", "inputs", "outputs"},
    "discrete": {"kind", "A", "B", "C", "D", "states", "inputs", "outputs"},
    "transfer_function": {"kind", "num", "den", "delay", "pade_order", "inputs", "outputs"},
}


def parse_plant(plant: dict, *, Ts: float) -> PlantModel:
    """A checked :class:`PlantModel` from the ``[plant]`` table (a discrete plant is sampled at ``Ts``)."""
    kind = plant.get("kind", "continuous")
    if kind not in PLANT_KEYS:
        raise SpecError(f"plant.kind must be one of {', '.join(PLANT_KEYS)}, not {kind!r}")
    no_unknown(plant, PLANT_KEYS[kind], "plant")
    if kind == "transfer_function":
        A, B, C, D, pade_order = realise_tf(plant)
        states = tuple(f"x{i}" for i in range(A.shape[0]))
        m = B.shape[1]
        tf = TransferFunctionSource(
            num=plant["num"], den=plant["den"], delay=plant.get("delay", [[0.0] * m for _ in range(C.shape[0])])
        )
    else:
        (A, B, C, D), pade_order, tf = state_space(plant), None, None
        states = signal_names(plant, "states", A.shape[0], "x")
    return PlantModel(
        kind=kind,
        A=A,
        B=B,
        C=C,
        D=D,
        states=states,
        inputs=signal_names(plant, "inputs", B.shape[1], "u"),
        outputs=signal_names(plant, "outputs", C.shape[0], "y"),
        pade_order=pade_order,
        transfer_function=tf,
        Ts=Ts if kind == "discrete" else None,
    )


def state_space(plant: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A, B, C and D (zeros when absent) of a continuous or discrete plant table, with consistent shapes."""
    A = matrix_key(plant, "A", "plant")
    if A.shape[0] != A.shape[1]:
        raise SpecError(f"plant.A is {A.shape[0]}x{A.shape[1]}, it must be square")
    n = A.shape[0]
    B = matrix_key(plant, "B", "plant")
    if B.shape[0] != n:
        raise SpecError(f"plant.B has {B.shape[0]} rows, expected {n} (as many rows as A)")
    C = matrix_key(plant, "C", "plant")
    if C.shape[1] != n:
        raise SpecError(f"plant.C has {C.shape[1]} columns, expected {n} (one per state)")
    if "D" not in plant:
        return A, B, C, np.zeros((C.shape[0], B.shape[1]))
    D = matrix_key(plant, "D", "plant")
    if D.shape != (C.shape[0], B.shape[1]):
        raise SpecError(f"plant.D is {D.shape[0]}x{D.shape[1]}, expected {C.shape[0]}x{B.shape[1]}")
    return A, B, C, D


def realise_tf(plant: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """Realise a transfer-function matrix with dead times as a minimal continuous state space."""
    import control

    num, den, delay, order = _tf_tables(plant)
    p, m = len(num), len(num[0])
    nums = [[None] * m for _ in range(p)]
    dens = [[None] * m for _ in range(p)]
    for i in range(p):
        for j in range(m):
            b, a = _tf_element(num[i][j], den[i][j], delay[i][j], order, (i, j))
            nums[i][j], dens[i][j] = list(b), list(a)
    sys = control.minreal(control.ss(control.tf(nums, dens)), verbose=False)
    return (
        np.asarray(sys.A, float),
        np.asarray(sys.B, float),
        np.asarray(sys.C, float),
        np.asarray(sys.D, float),
        order,
    )


def _tf_tables(plant: dict) -> tuple[list, list, list, int]:
    """num, den, delay (p x m each) and the Padé order of a transfer-function plant table, shapes checked."""
    for key in ("num", "den"):
        if key not in plant:
            raise SpecError(f"plant of kind transfer_function lacks {key}")
    num, den = plant["num"], plant["den"]
    if not (isinstance(num, list) and num and all(isinstance(r, list) for r in num)):
        raise SpecError("plant.num must be a matrix (p rows x m columns) of coefficient lists")
    p, m = len(num), len(num[0])
    delay = plant.get("delay", [[0.0] * m for _ in range(p)])
    order = plant.get("pade_order", 1)
    if isinstance(order, bool) or not isinstance(order, int) or not 0 <= order <= 10:
        raise SpecError("plant.pade_order must be an integer from 0 to 10")
    for key, value in (("num", num), ("den", den), ("delay", delay)):
        if not (
            isinstance(value, list) and len(value) == p and all(isinstance(r, list) and len(r) == m for r in value)
        ):
            raise SpecError(f"plant.{key} must be a {p}x{m} matrix like plant.num")
    return num, den, delay, order


def _tf_element(num, den, tau, order: int, ij: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Numerator and denominator of element ``ij`` with its dead time ``tau`` as a Padé approximant of ``order``."""
    import control

    i, j = ij
    b = as_vector(num, f"plant.num[{i}][{j}]")
    a = as_vector(den, f"plant.den[{i}][{j}]")
    if a[0] == 0:
        raise SpecError(f"plant.den[{i}][{j}] has a zero leading coefficient")
    if len(np.trim_zeros(b, "f")) > len(a):
        raise SpecError(f"plant element ({i},{j}) is improper (numerator degree above denominator's)")
    if isinstance(tau, bool) or not isinstance(tau, (int, float)) or not np.isfinite(tau) or tau < 0:
        raise SpecError(f"plant.delay[{i}][{j}] must be a finite number >= 0")
    if tau > 0 and order == 0:
        raise SpecError("plant.pade_order = 0 cannot represent a non-zero delay")
    if tau > 0:
        pn, pd = control.pade(float(tau), order)
        b, a = np.polymul(b, pn), np.polymul(a, pd)
    return b, a
