"""The design tables of a spec (``[controller]``, ``[integral]``, ``[observer]``, ``[limits]``,
``[operating_point]``, ``[implementation]``), each parsed into its typed class against the plant."""

from __future__ import annotations

import numpy as np

from ..errors import SpecError, did_you_mean
from .model import (
    ControllerSpec,
    ImplementationSpec,
    IntegralSpec,
    LimitsSpec,
    ObserverSpec,
    OperatingPoint,
    PlantModel,
)
from .pairs import ANTI_WINDUP, STRUCTURE_TABLES, anti_windup_owner
from .ranges import parse_numeric, parse_ranges
from .values import as_matrix, as_vector, given_matrix, no_unknown, poles_z, weight

CONTROLLER_KEYS = {
    "method", "Q", "Q_diag", "bryson_x_max", "bryson_y_max", "R", "R_diag", "bryson_u_max", "poles", "poles_z",
    "K", "Ki",
}  # fmt: skip
INTEGRAL_KEYS = {"outputs", "Q_diag", "bryson_max", "aw_gain"}
OBSERVER_KEYS = {"method", "form", "W", "W_diag", "V", "V_diag", "G", "poles", "poles_z", "L", "M"}
LIMITS_KEYS = {"u_min", "u_max", "anti_windup", "y_min", "y_max", "r_min", "r_max"}
OPERATING_POINT_KEYS = {"u_op", "y_op", "x_op"}
IMPLEMENTATION_KEYS = {"realization", "float32_check", "numeric", "fixed_point_max_error"}
# [linearization]: the record ``gainlink linearize`` writes (which interface runs use and why, the model's fit to
# the FMU); kept as written, for the artifact's provenance.
LINEARIZATION_KEYS = {
    "fmu", "fmu_sha256", "method", "Ts", "interface", "interface_reason", "interface_check", "fit_steps",
    "fit_amplitude", "fit", "fit_warning",
}  # fmt: skip
REALIZATIONS = ("as_designed", "balanced", "schur")

# Back-calculation sheds this fraction of the command excess from the integral term per saturated
# step: a tracking time of 10 samples. 0.5 wound the pendulum's integrator hard during the observer's
# start-up transient (cart ran to 3.7 m from a 1 m offset); 0.1 gives no overshoot and catches a 25 N kick.
DEFAULT_AW_GAIN = 0.1

_DESIGN_KEYS = ("Q", "Q_diag", "bryson_x_max", "bryson_y_max", "R", "R_diag", "bryson_u_max", "poles", "poles_z")


def parse_integral(tbl: dict | None, plant: PlantModel, *, lqr: bool) -> IntegralSpec | None:
    """``[integral]``: the tracked outputs as a selector ``Ci``, the integrators' weight (LQR) and ``aw_gain``."""
    if tbl is None:
        return None
    outs = tbl.get("outputs")
    if not isinstance(outs, list) or not outs:
        raise SpecError("integral.outputs must list the tracked outputs (names or indices)")
    index = tuple(_output_index(o, plant) for o in outs)
    Ci = np.array([np.eye(plant.p)[i] for i in index])
    if np.linalg.matrix_rank(Ci) < len(index):
        raise SpecError("integral.outputs repeats an output")
    if len(index) > plant.m:
        raise SpecError(f"integral action on {len(index)} outputs needs at least as many inputs (m = {plant.m})")
    Qz = weight(tbl, ("Q", "Q_diag", "bryson_max"), len(index), "integral", required=lqr)
    aw_gain = tbl.get("aw_gain", DEFAULT_AW_GAIN)
    if isinstance(aw_gain, bool) or not isinstance(aw_gain, (int, float)) or not 0 < aw_gain <= 1:
        raise SpecError(f"integral.aw_gain must be in (0, 1], got {aw_gain}")
    return IntegralSpec(outputs=index, Ci=Ci, Qz=Qz, aw_gain=float(aw_gain))


def _output_index(o, plant: PlantModel) -> int:
    if isinstance(o, str):
        if o not in plant.outputs:
            raise SpecError(
                f"integral.outputs names {o!r}, which is not an output{did_you_mean(o, plant.outputs)} "
                f"({', '.join(plant.outputs)})"
            )
        return plant.outputs.index(o)
    if isinstance(o, int) and not isinstance(o, bool) and 0 <= o < plant.p:
        return o
    raise SpecError(f"integral.outputs entry {o!r} is not an output name or index")


def parse_controller(tbl: dict, plant: PlantModel, *, q: int, Ts: float) -> ControllerSpec:
    """``[controller]``: LQR weights, closed-loop poles (n + q, z-plane) or the user's own gains."""
    method = tbl.get("method", "lqr")
    if method in ("lqr", "mpc"):  # MPC: the same weights, its terminal cost their DARE solution ([mpc])
        return ControllerSpec(method=method, Q=_state_weight(tbl, plant), R=_input_weight(tbl, plant.m))
    if method in ("place", "ackermann"):
        if method == "ackermann" and plant.m != 1:
            raise SpecError("controller.method 'ackermann' is single-input only; use 'place'")
        return ControllerSpec(method=method, poles_z=poles_z(tbl, plant.n + q, Ts, "controller"))
    if method == "given":
        return _given_controller(tbl, plant, q=q)
    raise SpecError(f"controller.method must be lqr, mpc, place, ackermann or given, not {method!r}")


def _state_weight(tbl: dict, plant: PlantModel) -> np.ndarray:
    """Q on the plant state: Q, Q_diag, Bryson's state maxima, or output weighting ``C' diag(1/y_max^2) C``."""
    if "bryson_y_max" not in tbl:
        return weight(tbl, ("Q", "Q_diag", "bryson_x_max"), plant.n, "controller", required=True)
    if any(k in tbl for k in ("Q", "Q_diag", "bryson_x_max")):
        raise SpecError("controller: give only one of Q, Q_diag, bryson_x_max, bryson_y_max")
    y_max = as_vector(tbl["bryson_y_max"], "controller.bryson_y_max", plant.p)
    if np.any(y_max <= 0):
        raise SpecError("controller.bryson_y_max must be > 0 (Bryson's rule uses 1/max^2)")
    return plant.C.T @ np.diag(1.0 / y_max**2) @ plant.C


def _input_weight(tbl: dict, m: int) -> np.ndarray:
    return weight(tbl, ("R", "R_diag", "bryson_u_max"), m, "controller", required=True)


def _given_controller(tbl: dict, plant: PlantModel, *, q: int) -> ControllerSpec:
    """``K`` and ``Ki`` as the user gave them: discrete-time gains for the plant discretised at Ts."""
    for key in _DESIGN_KEYS:
        if key in tbl:
            raise SpecError(f"controller.{key} is a design setting; method 'given' takes K (and Ki) only")
    K = given_matrix(tbl, "K", (plant.m, plant.n), "controller")
    if q:
        Ki = given_matrix(tbl, "Ki", (plant.m, q), "controller")
    elif "Ki" in tbl:
        raise SpecError("controller.Ki is given but there is no [integral] table naming the tracked outputs")
    else:
        Ki = np.zeros((plant.m, 0))
    return ControllerSpec(method="given", K=K, Ki=Ki)


def parse_observer(tbl: dict, plant: PlantModel, *, Ts: float) -> ObserverSpec:
    """``[observer]``: a Kalman filter (W, V, G), Luenberger poles, or the user's own L (or M)."""
    method = tbl.get("method", "kalman")
    form = tbl.get("form", "predictor")
    if form not in ("predictor", "current"):
        raise SpecError(f"observer.form must be predictor or current, not {form!r}")
    if method == "kalman":
        return _kalman(tbl, plant, form=form)
    if method == "luenberger":
        return ObserverSpec(method="luenberger", form=form, poles_z=poles_z(tbl, plant.n, Ts, "observer"))
    if method == "given":
        return _given_observer(tbl, plant, form=form)
    raise SpecError(f"observer.method must be kalman, luenberger or given, not {method!r}")


def _kalman(tbl: dict, plant: PlantModel, *, form: str) -> ObserverSpec:
    G_is_B = tbl.get("G") == "B"  # process noise enters where the inputs do (G = Bd)
    G = None
    if "G" in tbl and not G_is_B:
        G = as_matrix(tbl["G"], "observer.G")
        if G.shape[0] != plant.n:
            raise SpecError(f"observer.G has {G.shape[0]} rows, expected {plant.n}")
    width = plant.m if G_is_B else (plant.n if G is None else G.shape[1])
    W = weight(tbl, ("W", "W_diag", "_none"), width, "observer", required=True)
    V = weight(tbl, ("V", "V_diag", "_none"), plant.p, "observer", required=True)
    return ObserverSpec(method="kalman", form=form, W=W, V=V, G=G, G_is_B=G_is_B, G_given="G" in tbl)


def _given_observer(tbl: dict, plant: PlantModel, *, form: str) -> ObserverSpec:
    """The user's observer gain: ``L`` (predictor form) or ``M`` (current form, ``L = Ad M`` follows)."""
    for key in ("W", "W_diag", "V", "V_diag", "G", "poles", "poles_z"):
        if key in tbl:
            raise SpecError(f"observer.{key} is a design setting; method 'given' takes L (or M) only")
    shape = (plant.n, plant.p)
    if form == "current":
        if "L" in tbl:
            raise SpecError("observer.form 'current' with method 'given' takes the filter gain M (L = Ad M follows)")
        return ObserverSpec(method="given", form=form, M=given_matrix(tbl, "M", shape, "observer"))
    if "M" in tbl:
        raise SpecError("observer.M is the current form's filter gain; the predictor form takes L")
    return ObserverSpec(method="given", form=form, L=given_matrix(tbl, "L", shape, "observer"))


def parse_limits(tbl: dict, plant: PlantModel, *, q: int, structure: str = "lq") -> LimitsSpec:
    """``[limits]``: absolute limits below one another, the anti-windup mode of the law's ``structure``
    (:data:`.pairs.ANTI_WINDUP`: the lq law's, none without integral action; ``velocity``, the scheduled law's own,
    exactly when the spec has a ``[schedule]``) and, for the lq law, the declared ranges of samples and
    references."""
    for key in ("u_min", "u_max"):
        if key not in tbl:
            raise SpecError(f"limits lacks {key}")
    u_min = as_vector(tbl["u_min"], "limits.u_min", plant.m)
    u_max = as_vector(tbl["u_max"], "limits.u_max", plant.m)
    if np.any(u_min >= u_max):
        raise SpecError("limits.u_min must be below limits.u_max for every input")
    return _LIMITS[structure](tbl, plant, q=q, u_min=u_min, u_max=u_max)


def _lq_limits(tbl: dict, plant: PlantModel, *, q: int, u_min: np.ndarray, u_max: np.ndarray) -> LimitsSpec:
    """The lq law's anti-windup (none without integral action) and declared ranges."""
    aw = tbl.get("anti_windup", ANTI_WINDUP["lq"][0] if q else "none")
    _check_anti_windup(aw, "lq")
    ranges = parse_ranges(tbl, plant, q=q)
    return LimitsSpec(u_min=u_min, u_max=u_max, anti_windup=aw if q else "none", **ranges)


def _scheduled_limits(tbl: dict, plant: PlantModel, *, q: int, u_min: np.ndarray, u_max: np.ndarray) -> LimitsSpec:
    """The scheduled law's own anti-windup: the velocity form integrates its own saturated command."""
    aw = tbl.get("anti_windup", ANTI_WINDUP["scheduled"][0])
    _check_anti_windup(aw, "scheduled")
    return LimitsSpec(u_min=u_min, u_max=u_max, anti_windup=aw)


def _check_anti_windup(aw: object, structure: str) -> None:
    """Refuse an anti-windup mode the ``structure`` does not run: one line naming the structure whose mode it is
    (:data:`.pairs.ANTI_WINDUP`), or what this structure's must be."""
    if aw in ANTI_WINDUP[structure]:
        return
    owner = anti_windup_owner(aw) if isinstance(aw, str) else None
    if owner in STRUCTURE_TABLES:
        raise SpecError(f"limits.anti_windup {aw!r} is the {owner} law's: it needs a [{STRUCTURE_TABLES[owner]}]")
    raise SpecError(f"limits.anti_windup {_ANTI_WINDUP_MUST[structure]}, not {aw!r}{_ANTI_WINDUP_WHY[structure]}")


#: What each structure's anti-windup mode must be, and why, as its refusal says.
_ANTI_WINDUP_MUST = {
    "lq": "must be none, clamp or backcalc",
    "scheduled": "must be 'velocity' with a [schedule]",
    "mpc": "must be none, clamp or backcalc",
}
_ANTI_WINDUP_WHY = {
    "lq": "",
    "mpc": "",
    "scheduled": ": the velocity form integrates its own saturated command, which is its anti-windup",
}
#: Each structure's ``[limits]`` (the registry :func:`parse_limits` asks).
_LIMITS = {"lq": _lq_limits, "scheduled": _scheduled_limits, "mpc": _lq_limits}


def parse_operating_point(tbl: dict | None, plant: PlantModel, limits: LimitsSpec) -> OperatingPoint | None:
    """``[operating_point]``: each of u_op, y_op, x_op a list (one value per signal, in order) or a table of
    signal name -> value (signals not named are 0); ``u_op`` must lie within the limits."""
    if tbl is None:
        return None
    no_unknown(tbl, OPERATING_POINT_KEYS, "operating_point")
    u_op = _signal_values(tbl, "u_op", plant.inputs, "input")
    y_op = _signal_values(tbl, "y_op", plant.outputs, "output")
    x_op = _signal_values(tbl, "x_op", plant.states, "state") if "x_op" in tbl else None
    outside = [i for i in range(plant.m) if not limits.u_min[i] <= u_op[i] <= limits.u_max[i]]
    if outside:
        i = outside[0]
        raise SpecError(
            f"operating_point.u_op for input {plant.inputs[i]} is {u_op[i]:g}, outside the limits "
            f"[{limits.u_min[i]:g}, {limits.u_max[i]:g}]: the loop could not hold the plant there"
        )
    return OperatingPoint(u_op=u_op, y_op=y_op, x_op=x_op)


def _signal_values(tbl: dict, key: str, names: tuple[str, ...], kind: str) -> np.ndarray:
    what = f"operating_point.{key}"
    value = tbl.get(key)
    if value is None:
        return np.zeros(len(names))
    if not isinstance(value, dict):
        return as_vector(value, what, len(names))
    out = np.zeros(len(names))
    for name, v in value.items():
        if name not in names:
            raise SpecError(
                f"{what} names {name!r}, which is not a plant {kind}{did_you_mean(name, names)} "
                f"(the {kind}s are: {', '.join(names)})"
            )
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
            raise SpecError(f"{what}.{name} must be a finite number, got {v!r}")
        out[names.index(name)] = float(v)
    return out


def parse_implementation(tbl: dict | None) -> ImplementationSpec:
    """``[implementation]``: the realisation of the estimate and whether to run the float32 check."""
    if tbl is None:
        return ImplementationSpec()
    kind = tbl.get("realization", "as_designed")
    if kind not in REALIZATIONS:
        raise SpecError(f"implementation.realization must be one of {', '.join(REALIZATIONS)}, not {kind!r}")
    check = tbl.get("float32_check", True)
    if not isinstance(check, bool):
        raise SpecError(f"implementation.float32_check must be true or false, not {check!r}")
    return ImplementationSpec(realization=kind, float32_check=check, **parse_numeric(tbl))
