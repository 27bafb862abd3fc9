"""Plant specs: the TOML a user writes, parsed into a validated :class:`PlantSpec`.

A spec gives the plant as continuous or discrete matrices, or as a transfer-function matrix with
dead times (realised with Padé approximants), plus the design choices: controller, integral
action, observer and actuator limits. Every key is checked; an unknown key is an error, because a
misspelt weight that is silently ignored produces a controller nobody asked for.
"""

from __future__ import annotations

import hashlib
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .errors import SpecError
from .fileio import read_user_file

NAME_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,31}$")
SIGNAL_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")

TOP_KEYS = {
    "name",
    "Ts",
    "discretization",
    "description",
    "plant",
    "controller",
    "integral",
    "observer",
    "limits",
    "operating_point",
    "implementation",
}
PLANT_KEYS = {
    "continuous": {"kind", "A", "B", "C", "D", "states", "inputs", "outputs"},
    "discrete": {"kind", "A", "B", "C", "D", "states", "inputs", "outputs"},
    "transfer_function": {"kind", "num", "den", "delay", "pade_order", "inputs", "outputs"},
}
CONTROLLER_KEYS = {
    "method",
    "Q",
    "Q_diag",
    "bryson_x_max",
    "bryson_y_max",
    "R",
    "R_diag",
    "bryson_u_max",
    "poles",
    "poles_z",
    "K",
    "Ki",
}
INTEGRAL_KEYS = {"outputs", "Q_diag", "bryson_max", "aw_gain"}
OBSERVER_KEYS = {"method", "form", "W", "W_diag", "V", "V_diag", "G", "poles", "poles_z", "L", "M"}
LIMITS_KEYS = {"u_min", "u_max", "anti_windup"}
OPERATING_POINT_KEYS = {"u_op", "y_op", "x_op"}


@dataclass(frozen=True)
class OperatingPoint:
    """The point the plant model is a linearisation about (docs/design.md, "The control law").

    ``u_op`` (m) and ``y_op`` (p) are the absolute command and measurement there; the model, the
    estimate and the design are deviations from them. ``x_op`` (n) is the state there, kept for the
    record (``None`` when the spec does not give it): the law does not use it.
    """

    u_op: np.ndarray
    y_op: np.ndarray
    x_op: np.ndarray | None = None


IMPLEMENTATION_KEYS = {"realization", "float32_check"}


@dataclass(frozen=True)
class PlantSpec:
    """A validated plant spec.

    ``A, B, C, D`` are the plant as specified: continuous (``kind`` continuous, or a transfer
    function realised with Padé delays) or discrete (``kind`` discrete, sampled at ``Ts``).
    Section tables (``controller``, ``integral``, ``observer``, ``limits``) keep the user's
    keys; :mod:`gainlink.design` interprets them. ``operating_point`` is ``None`` when the spec has
    no ``[operating_point]`` table (the plant is about the origin).
    """

    name: str
    Ts: float
    kind: str
    discretization: str
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    states: tuple[str, ...]
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    controller: dict
    integral: dict | None
    observer: dict
    limits: dict
    pade_order: int | None = None
    transfer_function: dict | None = None
    operating_point: OperatingPoint | None = None
    implementation: dict | None = None
    source_sha256: str = ""
    source: str = "<dict>"
    description: str = ""

    @property
    def n(self) -> int:
        """Number of states."""
        return self.A.shape[0]

    @property
    def m(self) -> int:
        """Number of inputs."""
        return self.B.shape[1]

    @property
    def p(self) -> int:
        """Number of outputs."""
        return self.C.shape[0]

    @property
    def continuous(self) -> bool:
        """True when A, B, C, D are continuous-time."""
        return self.kind != "discrete"


def load_spec(path: str | Path) -> PlantSpec:
    """Read a TOML spec file and validate it.

    Raises
    ------
    SpecError
        The file is not TOML, or any key, value or dimension is wrong.
    """
    path = Path(path)
    raw = read_user_file(path, what="spec", error=SpecError, binary=True)
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise SpecError(f"spec {path} is not valid TOML: {exc}") from None
    return parse_spec(data, source=str(path), source_sha256=hashlib.sha256(raw).hexdigest())


def parse_spec(data: dict, *, source: str = "<dict>", source_sha256: str | None = None) -> PlantSpec:
    """Validate a spec given as a dict (the parsed TOML) and return a :class:`PlantSpec`."""
    if source_sha256 is None:
        import json

        source_sha256 = hashlib.sha256(json.dumps(data, sort_keys=True, default=str).encode()).hexdigest()
    _no_unknown(data, TOP_KEYS, "spec")
    name = data.get("name")
    if not isinstance(name, str) or not NAME_RE.match(name):
        raise SpecError("spec 'name' must be an identifier of at most 32 characters (letters, digits, _)")
    Ts = _positive_number(data.get("Ts"), "Ts")
    disc = data.get("discretization", "zoh")
    if disc not in ("zoh", "tustin"):
        raise SpecError(f"discretization must be 'zoh' or 'tustin', not {disc!r}")

    plant = _table(data, "plant", required=True)
    kind = plant.get("kind", "continuous")
    if kind not in PLANT_KEYS:
        raise SpecError(f"plant.kind must be one of {', '.join(PLANT_KEYS)}, not {kind!r}")
    _no_unknown(plant, PLANT_KEYS[kind], "plant")
    if kind == "transfer_function":
        A, B, C, D, pade_order = _realise_tf(plant)
        states = tuple(f"x{i}" for i in range(A.shape[0]))
        m = B.shape[1]
        tf = {
            "num": plant["num"],
            "den": plant["den"],
            "delay": plant.get("delay", [[0.0] * m for _ in range(C.shape[0])]),
        }
    else:
        (A, B, C, D), pade_order, tf = _state_space(plant), None, None
        states = _names(plant, "states", A.shape[0], "x")
    inputs = _names(plant, "inputs", B.shape[1], "u")
    outputs = _names(plant, "outputs", C.shape[0], "y")

    controller = _checked_table(data, "controller", CONTROLLER_KEYS, required=True)
    integral = _checked_table(data, "integral", INTEGRAL_KEYS, required=False)
    observer = _checked_table(data, "observer", OBSERVER_KEYS, required=True)
    limits = _checked_table(data, "limits", LIMITS_KEYS, required=True)
    op = _operating_point(data, states=states, inputs=inputs, outputs=outputs)
    implementation = _checked_table(data, "implementation", IMPLEMENTATION_KEYS, required=False)

    return PlantSpec(
        name=name,
        Ts=Ts,
        kind=kind,
        discretization=disc,
        A=A,
        B=B,
        C=C,
        D=D,
        states=states,
        inputs=inputs,
        outputs=outputs,
        controller=controller,
        integral=integral,
        observer=observer,
        limits=limits,
        pade_order=pade_order,
        transfer_function=tf,
        operating_point=op,
        implementation=implementation,
        source_sha256=source_sha256,
        source=source,
        description=str(data.get("description", "")),
    )


# --- helpers -------------------------------------------------------------------------------------


def _state_space(plant: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A, B, C and D (zeros when absent) of a continuous or discrete plant table, with consistent shapes."""
    A = _matrix(plant, "A", "plant")
    n = _square(A, "plant.A")
    B = _matrix(plant, "B", "plant")
    _rows(B, n, "plant.B", "rows as A")
    C = _matrix(plant, "C", "plant")
    if C.shape[1] != n:
        raise SpecError(f"plant.C has {C.shape[1]} columns, expected {n} (one per state)")
    if "D" not in plant:
        return A, B, C, np.zeros((C.shape[0], B.shape[1]))
    D = _matrix(plant, "D", "plant")
    if D.shape != (C.shape[0], B.shape[1]):
        raise SpecError(f"plant.D is {D.shape[0]}x{D.shape[1]}, expected {C.shape[0]}x{B.shape[1]}")
    return A, B, C, D


def _checked_table(data: dict, key: str, allowed: set[str], *, required: bool) -> dict | None:
    table = _table(data, key, required=required)
    if table is not None:
        _no_unknown(table, allowed, key)
    return table


def _no_unknown(table: dict, allowed: set[str], where: str) -> None:
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise SpecError(f"unknown key {unknown[0]!r} in {where} (allowed: {', '.join(sorted(allowed))})")


def _table(data: dict, key: str, *, required: bool) -> dict | None:
    value = data.get(key)
    if value is None:
        if required:
            raise SpecError(f"spec lacks the [{key}] table")
        return None
    if not isinstance(value, dict):
        raise SpecError(f"spec '{key}' must be a table")
    return value


def _positive_number(value: Any, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SpecError(f"{what} must be a number, got {value!r}")
    value = float(value)
    if not np.isfinite(value) or value <= 0:
        raise SpecError(f"{what} must be a finite number > 0, got {value}")
    return value


def as_matrix(value: Any, what: str) -> np.ndarray:
    """Turn a TOML list of row lists into a finite 2-D float array, or raise SpecError."""
    if not isinstance(value, list) or not value:
        raise SpecError(f"{what} must be a non-empty list of rows")
    if not all(isinstance(r, list) for r in value):
        raise SpecError(f"{what} must be a list of rows (a list of lists), e.g. [[1.0, 0.0]]")
    widths = {len(r) for r in value}
    if len(widths) != 1 or 0 in widths:
        raise SpecError(f"{what} has rows of different lengths")
    try:
        a = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise SpecError(f"{what} holds a non-numeric entry") from None
    if any(isinstance(x, bool) for r in value for x in r):
        raise SpecError(f"{what} holds a boolean entry")
    if not np.all(np.isfinite(a)):
        raise SpecError(f"{what} holds a NaN or infinite entry")
    return a


def as_vector(value: Any, what: str, length: int | None = None) -> np.ndarray:
    """Turn a TOML list of numbers into a finite 1-D float array of ``length``, or raise SpecError."""
    if isinstance(value, (int, float)) and not isinstance(value, bool) and length == 1:
        value = [value]
    if not isinstance(value, list) or not value or any(isinstance(x, (list, bool)) for x in value):
        raise SpecError(f"{what} must be a list of numbers")
    try:
        v = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise SpecError(f"{what} holds a non-numeric entry") from None
    if not np.all(np.isfinite(v)):
        raise SpecError(f"{what} holds a NaN or infinite entry")
    if length is not None and v.size != length:
        raise SpecError(f"{what} has {v.size} entries, expected {length}")
    return v


def _matrix(table: dict, key: str, where: str) -> np.ndarray:
    if key not in table:
        raise SpecError(f"{where} lacks {key}")
    return as_matrix(table[key], f"{where}.{key}")


def _square(a: np.ndarray, what: str) -> int:
    if a.shape[0] != a.shape[1]:
        raise SpecError(f"{what} is {a.shape[0]}x{a.shape[1]}, it must be square")
    return a.shape[0]


def _rows(a: np.ndarray, n: int, what: str, hint: str) -> None:
    if a.shape[0] != n:
        raise SpecError(f"{what} has {a.shape[0]} rows, expected {n} (as many {hint})")


def _names(table: dict, key: str, count: int, prefix: str) -> tuple[str, ...]:
    if key not in table:
        return tuple(f"{prefix}{i}" for i in range(count))
    names = table[key]
    if not isinstance(names, list) or not all(isinstance(s, str) and SIGNAL_RE.match(s) for s in names):
        raise SpecError(f"plant.{key} must be a list of identifiers")
    if len(names) != count:
        raise SpecError(f"plant.{key} names {len(names)} signals, expected {count}")
    if len(set(names)) != len(names):
        raise SpecError(f"plant.{key} repeats a name")
    return tuple(names)


def _operating_point(
    data: dict, *, states: tuple[str, ...], inputs: tuple[str, ...], outputs: tuple[str, ...]
) -> OperatingPoint | None:
    """Parse ``[operating_point]``: each of u_op, y_op, x_op a list (one value per signal, in order) or a
    table of signal name -> value (signals not named are 0)."""
    table = _table(data, "operating_point", required=False)
    if table is None:
        return None
    _no_unknown(table, OPERATING_POINT_KEYS, "operating_point")
    u_op = _signal_values(table, "u_op", inputs, "input")
    y_op = _signal_values(table, "y_op", outputs, "output")
    x_op = _signal_values(table, "x_op", states, "state") if "x_op" in table else None
    return OperatingPoint(u_op=u_op, y_op=y_op, x_op=x_op)


def _signal_values(table: dict, key: str, names: tuple[str, ...], kind: str) -> np.ndarray:
    what = f"operating_point.{key}"
    value = table.get(key)
    if value is None:
        return np.zeros(len(names))
    if not isinstance(value, dict):
        return as_vector(value, what, len(names))
    out = np.zeros(len(names))
    for name, v in value.items():
        if name not in names:
            raise SpecError(f"{what} names {name!r}, which is not a plant {kind} (the {kind}s are: {', '.join(names)})")
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
            raise SpecError(f"{what}.{name} must be a finite number, got {v!r}")
        out[names.index(name)] = float(v)
    return out


def _realise_tf(plant: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """Realise a transfer-function matrix with dead times as a minimal continuous state space."""
    import control

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
    nums, dens = [], []
    for i in range(p):
        nrow, drow = [], []
        for j in range(m):
            b = as_vector(num[i][j], f"plant.num[{i}][{j}]")
            a = as_vector(den[i][j], f"plant.den[{i}][{j}]")
            if a[0] == 0:
                raise SpecError(f"plant.den[{i}][{j}] has a zero leading coefficient")
            if len(np.trim_zeros(b, "f")) > len(a):
                raise SpecError(f"plant element ({i},{j}) is improper (numerator degree above denominator's)")
            tau = delay[i][j]
            if isinstance(tau, bool) or not isinstance(tau, (int, float)) or not np.isfinite(tau) or tau < 0:
                raise SpecError(f"plant.delay[{i}][{j}] must be a finite number >= 0")
            if tau > 0 and order > 0:
                pn, pd = control.pade(float(tau), order)
                b, a = np.polymul(b, pn), np.polymul(a, pd)
            elif tau > 0:
                raise SpecError("plant.pade_order = 0 cannot represent a non-zero delay")
            nrow.append(list(b))
            drow.append(list(a))
        nums.append(nrow)
        dens.append(drow)
    sys = control.ss(control.tf(nums, dens))
    sys = control.minreal(sys, verbose=False)
    return (
        np.asarray(sys.A, float),
        np.asarray(sys.B, float),
        np.asarray(sys.C, float),
        np.asarray(sys.D, float),
        order,
    )
