"""Discrete controller + observer design from a :class:`~gainlink.spec.PlantSpec` to a gain artifact.

The pipeline is: discretise (ZOH or Tustin) -> augment with integrators of the tracked outputs
-> DLQR (Q/R given or from Bryson's rule) or pole placement -> Kalman (DARE) or Luenberger
observer in predictor or current form -> anti-windup gain -> checks of the combined closed loop
-> the artifact dict, sealed. Every Riccati solution comes from python-control (SLICOT through
slycot when present, SciPy otherwise).
"""

from __future__ import annotations

import logging
import platform
from dataclasses import dataclass, field
from importlib import metadata

import numpy as np

from . import __version__
from .analysis import complex_pairs, pole_frequency, uncontrollable_unstable, unobservable_unstable
from .artifact import SCHEMA_VERSION, matrix_to_json, seal, vector_to_json
from .errors import DesignError, SpecError
from .spec import PlantSpec, as_matrix, as_vector

log = logging.getLogger(__name__)

# Back-calculation sheds this fraction of the command excess from the integral term per saturated
# step: a tracking time of 10 samples. 0.5 wound the pendulum's integrator hard during the observer's
# start-up transient (cart ran to 3.7 m from a 1 m offset); 0.1 gives no overshoot and catches a 25 N kick.
DEFAULT_AW_GAIN = 0.1
POLE_MATCH_TOL = 1e-6
MARGIN_GRID_POINTS = 2000


@dataclass(frozen=True)
class Discretised:
    """The discrete plant the controller is designed for."""

    Ad: np.ndarray
    Bd: np.ndarray
    Cd: np.ndarray
    Dd: np.ndarray
    method: str


@dataclass(frozen=True)
class ChannelMargin:
    """Loop-at-a-time margins with the loop broken at one plant input (others closed).

    Gain margins are exact: the factors by which that loop's gain can rise or fall before an
    eigenvalue of the closed loop leaves the unit circle (``None``: beyond 60 dB either way).
    The phase margin and the gain crossover come from the loop's frequency response.
    """

    input: str
    gain_margin_up_db: float | None
    gain_margin_down_db: float | None
    phase_margin_deg: float | None
    gain_crossover_rad_s: float | None


@dataclass(frozen=True)
class DesignResult:
    """A finished design: the sealed artifact dict and the numbers behind its checks."""

    artifact: dict
    controller_poles: np.ndarray
    observer_poles: np.ndarray
    closed_loop_poles: np.ndarray
    margins: list[ChannelMargin]
    warnings: list[str] = field(default_factory=list)
    compensator: object = None  # gainlink.compensator.CompensatorStability
    float32: object = None  # gainlink.fidelity.Float32Fidelity, None when the check was switched off
    dead_time: object = None  # gainlink.deadtime.DeadTimeCheck, None unless the plant has sampled dead times


def discretise(spec: PlantSpec) -> Discretised:
    """ZOH or Tustin discretisation of a continuous spec; a discrete spec is returned as is."""
    import control

    if not spec.continuous:
        return Discretised(spec.A, spec.B, spec.C, spec.D, "none")
    sysc = control.ss(spec.A, spec.B, spec.C, spec.D)
    sysd = control.c2d(sysc, spec.Ts, method=spec.discretization)
    return Discretised(
        np.asarray(sysd.A, float),
        np.asarray(sysd.B, float),
        np.asarray(sysd.C, float),
        np.asarray(sysd.D, float),
        spec.discretization,
    )


def design(spec: PlantSpec) -> DesignResult:
    """Design the controller and observer a spec asks for and return the sealed artifact.

    Raises
    ------
    SpecError
        A design setting is missing, malformed or inconsistent with the plant.
    DesignError
        The plant is not stabilizable/detectable, weights are not (semi)definite, or the
        resulting closed loop is not stable.
    """
    warnings: list[str] = []
    d = discretise(spec)
    n, m = spec.n, spec.m
    u_min, u_max, anti_windup = _limits(spec)
    Ci = _integral_selector(spec)
    q = Ci.shape[0]
    if q == 0 and anti_windup != "none":
        anti_windup = "none"
    Aa, Ba = augment(d, Ci, spec.Ts)
    _check_feasible(d, Aa, Ba, q)
    Ka, controller_record = _controller(spec, Aa, Ba, warnings)
    K, Ki = Ka[:, :n], Ka[:, n:]
    L, M, observer_record = _observer(spec, d, warnings)
    form = spec.observer.get("form", "predictor")
    Kaw = _anti_windup_gain(spec, Ki, m=m, anti_windup=anti_windup, record=controller_record)
    gains = {"K": K, "Ki": Ki, "L": L, "M": M, "Ci": Ci, "Ts": spec.Ts, "form": form}
    cl_poles, radius = _closed_loop(d, Aa - Ba @ Ka, gains)
    ctrl_poles = np.linalg.eigvals(Aa - Ba @ Ka)
    obs_poles = np.linalg.eigvals(d.Ad - L @ d.Cd)
    margins = input_margins(d, inputs=spec.inputs, **gains)
    bandwidth = loop_bandwidth(margins, ctrl_poles, spec.Ts)
    if (2 * np.pi / spec.Ts) < 10 * bandwidth:
        warnings.append(
            f"sampling at {2 * np.pi / spec.Ts:.3g} rad/s is less than 10x the closed-loop "
            f"bandwidth {bandwidth:.3g} rad/s"
        )
    data = _artifact_data(
        spec,
        d,
        gains,
        Kaw=Kaw,
        u_min=u_min,
        u_max=u_max,
        anti_windup=anti_windup,
        design_record={"discretization": d.method, "controller": controller_record, "observer": observer_record},
        checks={
            "closed_loop_poles": complex_pairs(sorted(cl_poles, key=lambda z: (abs(z), z.imag))),
            "spectral_radius": radius,
            "margins": [dict(mg.__dict__) for mg in margins],
        },
    )
    data, compensator, fidelity = implement(data, spec.implementation or {}, warnings)
    dead_time = _dead_time(spec, data, warnings)
    for w in warnings:
        log.warning(w)
    return DesignResult(
        artifact=seal(data),
        controller_poles=ctrl_poles,
        observer_poles=obs_poles,
        closed_loop_poles=cl_poles,
        margins=margins,
        warnings=warnings,
        compensator=compensator,
        float32=fidelity,
        dead_time=dead_time,
    )


def _dead_time(spec: PlantSpec, data: dict, warnings: list[str]):
    """The law against the exact sampled dead times of a transfer-function spec (:mod:`gainlink.deadtime`),
    recorded in ``checks.dead_time``; None when the spec has none."""
    from .artifact import from_dict
    from .deadtime import dead_time_check

    check = dead_time_check(spec, from_dict(seal(data)))
    if check is not None:
        data["checks"]["dead_time"] = check.to_dict()
        if not check.stable:
            warnings.append(check.warning())
    return check


def _check_feasible(d: Discretised, Aa: np.ndarray, Ba: np.ndarray, q: int) -> None:
    """Stabilizable, detectable, and (with integral action) the augmented plant stabilizable: else DesignError."""
    bad = uncontrollable_unstable(d.Ad, d.Bd, discrete=True)
    if bad:
        raise DesignError(f"plant is not stabilizable: unstable mode(s) {_fmt_list(bad)} are uncontrollable")
    bad = unobservable_unstable(d.Ad, d.Cd, discrete=True)
    if bad:
        raise DesignError(f"plant is not detectable: unstable mode(s) {_fmt_list(bad)} are unobservable")
    if q:
        bad = uncontrollable_unstable(Aa, Ba, discrete=True)
        if bad:
            raise DesignError(
                "integral action is not feasible: the tracked outputs cannot be driven to a constant "
                f"reference (augmented modes {_fmt_list(bad)} uncontrollable; a plant zero at s=0 / z=1?)"
            )


def _anti_windup_gain(spec: PlantSpec, Ki: np.ndarray, *, m: int, anti_windup: str, record: dict) -> np.ndarray:
    """Kaw: -aw_gain pinv(Ki) for back-calculation (recorded in the controller record), zeros otherwise."""
    q = Ki.shape[1]
    aw_gain = float(spec.integral.get("aw_gain", DEFAULT_AW_GAIN)) if spec.integral else DEFAULT_AW_GAIN
    if not (q and anti_windup == "backcalc"):
        return np.zeros((q, m))
    if not 0 < aw_gain <= 1:
        raise SpecError(f"integral.aw_gain must be in (0, 1], got {aw_gain}")
    record["aw_gain"] = aw_gain
    return -aw_gain * np.linalg.pinv(Ki)


def _closed_loop(d: Discretised, A_ctrl: np.ndarray, gains: dict) -> tuple[np.ndarray, float]:
    """Closed-loop poles and spectral radius; DesignError when unstable or the separation principle fails."""
    Acl = closed_loop_matrix(d, **gains)
    cl_poles = np.linalg.eigvals(Acl)
    radius = float(np.max(np.abs(cl_poles)))
    if not radius < 1.0:
        raise DesignError(f"closed loop is unstable: spectral radius {radius:.6g} >= 1")
    check_separation(Acl, A_ctrl, d.Ad - gains["L"] @ d.Cd)
    return cl_poles, radius


def _artifact_data(
    spec: PlantSpec,
    d: Discretised,
    gains: dict,
    *,
    Kaw: np.ndarray,
    u_min: np.ndarray,
    u_max: np.ndarray,
    anti_windup: str,
    design_record: dict,
    checks: dict,
) -> dict:
    """The artifact's content (unsealed, before the implementation choices)."""
    Ci, M = gains["Ci"], gains["M"]
    q = Ci.shape[0]
    data = {
        "schema_version": SCHEMA_VERSION,
        "name": spec.name,
        "Ts": spec.Ts,
        "n": spec.n,
        "m": spec.m,
        "p": spec.p,
        "q": q,
        "Ad": matrix_to_json(d.Ad),
        "Bd": matrix_to_json(d.Bd),
        "Cd": matrix_to_json(d.Cd),
        "Dd": matrix_to_json(d.Dd),
        "K": matrix_to_json(gains["K"]),
        "L": matrix_to_json(gains["L"]),
        "u_min": vector_to_json(u_min),
        "u_max": vector_to_json(u_max),
        "anti_windup": anti_windup,
        "observer_form": gains["form"],
        "signals": {
            "states": list(spec.states),
            "inputs": list(spec.inputs),
            "outputs": list(spec.outputs),
            "references": [f"r_{spec.outputs[int(np.argmax(row))]}" for row in Ci],
        },
        "plant": {
            "kind": spec.kind,
            "A": matrix_to_json(spec.A),
            "B": matrix_to_json(spec.B),
            "C": matrix_to_json(spec.C),
            "D": matrix_to_json(spec.D),
        },
        "design": design_record,
        "checks": checks,
        "provenance": provenance(spec),
    }
    if spec.pade_order is not None:
        data["plant"]["pade_order"] = spec.pade_order
    if M is not None:
        data["M"] = matrix_to_json(M)
    if q:
        data["Ci"], data["Ki"], data["Kaw"] = matrix_to_json(Ci), matrix_to_json(gains["Ki"]), matrix_to_json(Kaw)
    data.update(operating_point_keys(spec, u_min=u_min, u_max=u_max))
    return data


def implement(data: dict, implementation: dict, warnings: list[str]):
    """Apply the spec's ``[implementation]`` choices to a designed artifact dict and record their checks.

    The estimate is put in the chosen realisation (:mod:`gainlink.realization`), then the compensator's
    stability (:mod:`gainlink.compensator`) and, unless ``float32_check = false``, the float32 closed-loop
    fidelity (:mod:`gainlink.fidelity`) are added to ``checks``, with their warnings.

    Returns
    -------
    tuple
        ``(data, CompensatorStability, Float32Fidelity or None)``; ``data`` is not sealed.
    """
    from .artifact import from_dict
    from .compensator import compensator_stability
    from .fidelity import float32_fidelity
    from .realization import REALIZATIONS, apply, transformation

    kind = implementation.get("realization", "as_designed")
    if kind not in REALIZATIONS:
        raise SpecError(f"implementation.realization must be one of {', '.join(REALIZATIONS)}, not {kind!r}")
    check = implementation.get("float32_check", True)
    if not isinstance(check, bool):
        raise SpecError(f"implementation.float32_check must be true or false, not {check!r}")
    if kind != "as_designed":
        a = from_dict(seal(data))
        T = transformation(kind, Ad=a.Ad, Bd=a.Bd, Cd=a.Cd, Dd=a.Dd, K=a.K, L=a.L, M=a.M, form=a.observer_form)
        data = apply(data, kind=kind, T=T)
    data = dict(data, checks=dict(data["checks"]))
    a = from_dict(seal(data))
    compensator = compensator_stability(a)
    data["checks"]["compensator"] = compensator.to_dict()
    if not compensator.stable:
        warnings.append(compensator.warning())
    fidelity = None
    if check:
        fidelity = float32_fidelity(a)
        data["checks"]["float32"] = fidelity.to_dict()
        if not fidelity.ok:
            better = None
            if kind == "as_designed":
                T = transformation(
                    "balanced", Ad=a.Ad, Bd=a.Bd, Cd=a.Cd, Dd=a.Dd, K=a.K, L=a.L, M=a.M, form=a.observer_form
                )
                better = float32_fidelity(from_dict(seal(apply(data, kind="balanced", T=T)))).max_rel_u
            warnings.append(fidelity.warning(kind, balanced=better))
    return data, compensator, fidelity


def augment(d: Discretised, Ci: np.ndarray, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """The plant augmented with ``z+ = z + Ts (r - Ci y)`` (taken at r = 0) for integral action."""
    n = d.Bd.shape[0]
    q = Ci.shape[0]
    Aa = np.block([[d.Ad, np.zeros((n, q))], [-Ts * Ci @ d.Cd, np.eye(q)]])
    Ba = np.vstack([d.Bd, -Ts * Ci @ d.Dd])
    return Aa, Ba


def closed_loop_matrix(
    d: Discretised, *, K, Ki, L, M, Ci, Ts: float, form: str, break_input: int | None = None
) -> np.ndarray | tuple:
    """State matrix of plant + observer + controller on the state ``[x; xh; z]`` (linear, r = 0).

    With ``break_input = i`` returns ``(A, B, C)`` of the loop broken at plant input i, where an
    actuator would change it: input ``w`` drives plant input i, output is the controller's command
    for input i, and the observer keeps being fed the controller's own command (as the C loop is:
    it never sees the actuator). Margins of that loop are margins against actuator gain and phase.
    """
    n, m = d.Bd.shape
    q = Ci.shape[0]
    Ad, Bd, Cd, Dd = d.Ad, d.Bd, d.Cd, d.Dd
    if form == "current":
        # xc = xh + M (Cd x - Cd xh); v = -K xc - Ki z; xh+ = Ad xc + Bd v
        V = np.hstack([-K @ M @ Cd, -K @ (np.eye(n) - M @ Cd), -Ki])
        Lx, Ah = Ad @ M @ Cd, Ad @ (np.eye(n) - M @ Cd)
        obs_sees_plant_input = np.zeros((n, m))  # Dd = 0 in the current form
        obs_own = Bd
    else:
        # v = -K xh - Ki z; xh+ = (Ad - L Cd) xh + L Cd x + (Bd - L Dd) v + L Dd u_plant
        V = np.hstack([np.zeros((m, n)), -K, -Ki])
        Lx, Ah = L @ Cd, Ad - L @ Cd
        obs_sees_plant_input = L @ Dd
        obs_own = Bd - L @ Dd
    A0 = np.block(
        [
            [Ad, np.zeros((n, n)), np.zeros((n, q))],
            [Lx, Ah, np.zeros((n, q))],
            [-Ts * Ci @ Cd, np.zeros((q, n)), np.eye(q)],
        ]
    )
    B_plant = np.vstack([Bd, obs_sees_plant_input, -Ts * Ci @ Dd])  # what the plant's input drives
    B_own = np.vstack([np.zeros((n, m)), obs_own, np.zeros((q, m))])  # the observer's copy of the command
    if break_input is None:
        return A0 + (B_plant + B_own) @ V
    S = np.eye(m)
    S[break_input, break_input] = 0.0
    e = np.zeros((m, 1))
    e[break_input] = 1.0
    return A0 + B_plant @ S @ V + B_own @ V, B_plant @ e, V[break_input : break_input + 1, :]


def check_separation(Acl: np.ndarray, A_ctrl: np.ndarray, A_obs: np.ndarray, rtol: float = 1e-9) -> None:
    """Verify that the combined loop is the controller and observer dynamics, and nothing else.

    In coordinates ``[x; z; e]`` with ``e = x - xh`` the matrix of :func:`closed_loop_matrix` must be
    block upper-triangular with diagonal blocks ``A_ctrl = Aa - Ba Ka`` and ``A_obs = Ad - L Cd``, so
    its eigenvalues are exactly their union. Comparing matrices is well conditioned where comparing
    clustered eigenvalues of a non-normal matrix is not.
    """
    n = A_obs.shape[0]
    q = A_ctrl.shape[0] - n
    N = 2 * n + q
    # [x; z; e] = T [x; xh; z]
    T = np.zeros((N, N))
    T[:n, :n] = np.eye(n)
    T[n : n + q, 2 * n :] = np.eye(q)
    T[n + q :, :n] = np.eye(n)
    T[n + q :, n : 2 * n] = -np.eye(n)
    At = T @ Acl @ np.linalg.inv(T)
    scale = max(1.0, float(np.linalg.norm(Acl)))
    errors = {
        "controller block": np.linalg.norm(At[: n + q, : n + q] - A_ctrl),
        "observer block": np.linalg.norm(At[n + q :, n + q :] - A_obs),
        "coupling of the estimation error into the plant": np.linalg.norm(At[n + q :, : n + q]),
    }
    for what, err in errors.items():
        if err > rtol * scale:
            raise DesignError(f"closed loop is not the union of controller and observer: {what} off by {err:.3g}")


def input_margins(d: Discretised, *, K, Ki, L, M, Ci, Ts, form, inputs) -> list[ChannelMargin]:
    """Loop-at-a-time gain and phase margins at each plant input (others closed)."""
    out = []
    for i, name in enumerate(inputs):
        A, B, C = closed_loop_matrix(d, K=K, Ki=Ki, L=L, M=M, Ci=Ci, Ts=Ts, form=form, break_input=i)
        pm, wgc = _phase_margin(A, B, C, Ts)
        up = _gain_limit(A, B @ C, direction=+1)
        down = _gain_limit(A, B @ C, direction=-1)
        out.append(
            ChannelMargin(
                input=name,
                gain_margin_up_db=None if up is None else float(20 * np.log10(up)),
                gain_margin_down_db=None if down is None else float(20 * np.log10(down)),
                phase_margin_deg=pm,
                gain_crossover_rad_s=wgc,
            )
        )
    return out


def _phase_margin(A: np.ndarray, B: np.ndarray, C: np.ndarray, Ts: float) -> tuple[float | None, float | None]:
    """Smallest phase margin over the 0 dB crossings of the loop gain ``-C (zI - A)^-1 B``, and where.

    The response is evaluated on a dense log grid up to Nyquist in one batched solve; each crossing
    is located by interpolating log|L| against log w and the phase taken there exactly. (python-control's
    default 'poly' method roots a high-order polynomial and misplaces crossovers for loops this size.)
    """
    n = A.shape[0]

    def response(w: np.ndarray) -> np.ndarray:
        z = np.exp(1j * w * Ts)
        return -(C @ np.linalg.solve(z[:, None, None] * np.eye(n) - A, B))[:, 0, 0]

    w_nyquist = np.pi / Ts
    grid = np.logspace(np.log10(w_nyquist) - 6, np.log10(w_nyquist), MARGIN_GRID_POINTS)
    with np.errstate(all="ignore"):
        log_mag = np.log(np.abs(response(grid)))
    crossings = np.flatnonzero(np.isfinite(log_mag[:-1]) & (log_mag[:-1] * log_mag[1:] < 0))
    if crossings.size == 0:
        return None, None
    i = crossings
    frac = log_mag[i] / (log_mag[i] - log_mag[i + 1])
    w_c = np.exp(np.log(grid[i]) + frac * (np.log(grid[i + 1]) - np.log(grid[i])))
    margins = 180.0 - np.abs(np.degrees(np.angle(response(w_c))))
    k = int(np.argmin(margins))
    return float(margins[k]), float(w_c[k])


def _gain_limit(A: np.ndarray, BC: np.ndarray, *, direction: int, max_db: float = 60.0) -> float | None:
    """The loop-gain factor k (above or below 1) at which ``A + k BC`` first loses stability."""

    def stable(k: float) -> bool:
        return float(np.max(np.abs(np.linalg.eigvals(A + k * BC)))) < 1.0

    step = 10 ** (direction * 0.25 / 20)  # quarter-dB grid, then bisection
    inside, k = 1.0, 1.0
    limit = 10 ** (direction * max_db / 20)
    while True:
        k *= step
        if (direction > 0 and k > limit) or (direction < 0 and k < limit):
            return None
        if not stable(k):
            break
        inside = k
    outside = k
    for _ in range(40):
        mid = np.sqrt(inside * outside)
        inside, outside = (mid, outside) if stable(mid) else (inside, mid)
    return float(outside)


def loop_bandwidth(margins: list[ChannelMargin], controller_poles: np.ndarray, Ts: float) -> float:
    """Closed-loop bandwidth proxy: the highest gain crossover at the plant inputs.

    Falls back to the fastest controller pole when no loop crosses 0 dB.
    """
    crossings = [mg.gain_crossover_rad_s for mg in margins if mg.gain_crossover_rad_s]
    if crossings:
        return float(max(crossings))
    return max(pole_frequency(z, discrete=True, Ts=Ts) for z in controller_poles)


def poles_match(a: np.ndarray, b: np.ndarray, tol: float = POLE_MATCH_TOL) -> bool:
    """True when the multisets a and b of complex numbers agree (greedy nearest matching)."""
    if len(a) != len(b):
        return False
    rest = list(b)
    for z in a:
        j = int(np.argmin([abs(z - w) for w in rest]))
        if abs(z - rest[j]) > tol * max(1.0, abs(z)):
            return False
        rest.pop(j)
    return True


def provenance(spec: PlantSpec) -> dict:
    """Versions of everything that computed the gains, and the spec's hash."""

    def version(dist: str) -> str:
        try:
            return metadata.version(dist)
        except metadata.PackageNotFoundError:
            return "absent"

    given = [
        part
        for part, table in (("controller", spec.controller), ("observer", spec.observer))
        if table.get("method") == "given"
    ]
    return {
        "gainlink": __version__,
        "numpy": version("numpy"),
        "scipy": version("scipy"),
        "control": version("control"),
        "slycot": version("slycot"),
        "python": platform.python_version(),
        "spec_sha256": spec.source_sha256,
        "gains": "given: " + ", ".join(given) if given else "designed",
    }


# --- pieces ---------------------------------------------------------------------------------------


def operating_point_keys(spec: PlantSpec, *, u_min: np.ndarray, u_max: np.ndarray) -> dict:
    """The artifact keys ``u_op``, ``y_op``, ``x_op`` for the spec's operating point.

    A key is written only when it holds a non-zero entry. An absent key means zeros, so a design about
    the origin has one form whether its spec writes a zero table or none, and every spec written before
    operating points existed designs to exactly the artifact (and sha256) it designed then.

    Raises
    ------
    SpecError
        ``u_op`` lies outside the limits: the loop could not hold the plant at that point.
    """
    op = spec.operating_point
    if op is None:
        return {}
    outside = [i for i in range(spec.m) if not u_min[i] <= op.u_op[i] <= u_max[i]]
    if outside:
        i = outside[0]
        raise SpecError(
            f"operating_point.u_op for input {spec.inputs[i]} is {op.u_op[i]:g}, outside the limits "
            f"[{u_min[i]:g}, {u_max[i]:g}]: the loop could not hold the plant there"
        )
    keys = {"u_op": op.u_op, "y_op": op.y_op, "x_op": op.x_op}
    return {k: vector_to_json(v) for k, v in keys.items() if v is not None and np.any(v != 0.0)}


def _limits(spec: PlantSpec) -> tuple[np.ndarray, np.ndarray, str]:
    lim = spec.limits
    for key in ("u_min", "u_max"):
        if key not in lim:
            raise SpecError(f"limits lacks {key}")
    u_min = as_vector(lim["u_min"], "limits.u_min", spec.m)
    u_max = as_vector(lim["u_max"], "limits.u_max", spec.m)
    if np.any(u_min >= u_max):
        raise SpecError("limits.u_min must be below limits.u_max for every input")
    aw = lim.get("anti_windup", "backcalc" if spec.integral else "none")
    if aw not in ("none", "clamp", "backcalc"):
        raise SpecError(f"limits.anti_windup must be none, clamp or backcalc, not {aw!r}")
    return u_min, u_max, aw


def _integral_selector(spec: PlantSpec) -> np.ndarray:
    if not spec.integral:
        return np.zeros((0, spec.p))
    outs = spec.integral.get("outputs")
    if not isinstance(outs, list) or not outs:
        raise SpecError("integral.outputs must list the tracked outputs (names or indices)")
    rows = []
    for o in outs:
        if isinstance(o, str):
            if o not in spec.outputs:
                raise SpecError(f"integral.outputs names {o!r}, which is not an output ({', '.join(spec.outputs)})")
            idx = spec.outputs.index(o)
        elif isinstance(o, int) and not isinstance(o, bool) and 0 <= o < spec.p:
            idx = o
        else:
            raise SpecError(f"integral.outputs entry {o!r} is not an output name or index")
        rows.append(np.eye(spec.p)[idx])
    Ci = np.array(rows)
    if np.linalg.matrix_rank(Ci) < len(rows):
        raise SpecError("integral.outputs repeats an output")
    if len(rows) > spec.m:
        raise SpecError(f"integral action on {len(rows)} outputs needs at least as many inputs (m = {spec.m})")
    return Ci


def _weight(table: dict, keys: tuple[str, str, str], size: int, where: str, *, required: bool) -> np.ndarray | None:
    """A weight matrix from a full matrix, a diagonal, or Bryson's maxima (1 / max^2)."""
    full, diag, bryson = keys
    given = [k for k in keys if k in table]
    if len(given) > 1:
        raise SpecError(f"{where}: give only one of {', '.join(given)}")
    if not given:
        if required:
            raise SpecError(f"{where} needs one of {full}, {diag} or {bryson}")
        return None
    key = given[0]
    if key == full:
        W = as_matrix(table[key], f"{where}.{key}")
        if W.shape != (size, size):
            raise SpecError(f"{where}.{key} is {W.shape[0]}x{W.shape[1]}, expected {size}x{size}")
        return W
    v = as_vector(table[key], f"{where}.{key}", size)
    if key == bryson:
        if np.any(v <= 0):
            raise SpecError(f"{where}.{key} must be > 0 (Bryson's rule uses 1/max^2)")
        return np.diag(1.0 / v**2)
    return np.diag(v)


def _check_psd(W: np.ndarray, what: str, *, definite: bool) -> None:
    if not np.allclose(W, W.T, rtol=1e-10, atol=1e-12):
        raise DesignError(f"{what} is not symmetric")
    eig = np.linalg.eigvalsh((W + W.T) / 2)
    scale = max(1.0, float(np.max(np.abs(eig))))
    if definite and eig[0] <= 1e-12 * scale:
        raise DesignError(f"{what} is not positive definite (smallest eigenvalue {eig[0]:.3g})")
    if not definite and eig[0] < -1e-10 * scale:
        raise DesignError(f"{what} is not positive semi-definite (smallest eigenvalue {eig[0]:.3g})")


def _poles(table: dict, count: int, Ts: float, where: str) -> np.ndarray:
    if ("poles" in table) == ("poles_z" in table):
        raise SpecError(f"{where} needs exactly one of poles (s-plane) or poles_z (z-plane)")
    key = "poles" if "poles" in table else "poles_z"
    raw = table[key]
    if not isinstance(raw, list):
        raise SpecError(f"{where}.{key} must be a list of numbers or [re, im] pairs")
    vals = []
    for item in raw:
        if isinstance(item, list) and len(item) == 2:
            re_im = as_vector(item, f"{where}.{key} entry")
            vals.append(complex(re_im[0], re_im[1]))
        elif isinstance(item, (int, float)) and not isinstance(item, bool) and np.isfinite(item):
            vals.append(complex(item))
        else:
            raise SpecError(f"{where}.{key} entry {item!r} is not a number or an [re, im] pair")
    if len(vals) != count:
        raise SpecError(f"{where}.{key} gives {len(vals)} poles, expected {count}")
    poles = np.array(vals)
    if not np.allclose(np.sort_complex(poles), np.sort_complex(poles.conj())):
        raise SpecError(f"{where}.{key}: complex poles must come in conjugate pairs")
    z = np.exp(poles * Ts) if key == "poles" else poles
    if np.any(np.abs(z) >= 1):
        raise SpecError(f"{where}.{key}: every pole must be stable (Re s < 0, |z| < 1)")
    return z


def _controller(spec: PlantSpec, Aa: np.ndarray, Ba: np.ndarray, warnings: list[str]) -> tuple[np.ndarray, dict]:
    import control

    ctl = spec.controller
    method = ctl.get("method", "lqr")
    na, m = Ba.shape
    q = na - spec.n
    if method == "lqr":
        if "bryson_y_max" in ctl:
            if any(k in ctl for k in ("Q", "Q_diag", "bryson_x_max")):
                raise SpecError("controller: give only one of Q, Q_diag, bryson_x_max, bryson_y_max")
            y_max = as_vector(ctl["bryson_y_max"], "controller.bryson_y_max", spec.p)
            if np.any(y_max <= 0):
                raise SpecError("controller.bryson_y_max must be > 0 (Bryson's rule uses 1/max^2)")
            Q = spec.C.T @ np.diag(1.0 / y_max**2) @ spec.C  # output weighting: y' Qy y
        else:
            Q = _weight(ctl, ("Q", "Q_diag", "bryson_x_max"), spec.n, "controller", required=True)
        R = _weight(ctl, ("R", "R_diag", "bryson_u_max"), m, "controller", required=True)
        if q:
            Qz = _weight(spec.integral, ("Q", "Q_diag", "bryson_max"), q, "integral", required=True)
            Q = np.block([[Q, np.zeros((spec.n, q))], [np.zeros((q, spec.n)), Qz]])
        _check_psd(Q, "controller Q", definite=False)
        _check_psd(R, "controller R", definite=True)
        try:
            K, _, _ = control.dlqr(Aa, Ba, Q, R)
        except Exception as exc:  # SLICOT/SciPy report failures with assorted exception types
            raise DesignError(f"DLQR failed: {str(exc).splitlines()[0]} (is (Q, A) detectable?)") from None
        return np.asarray(K, float), {
            "method": "lqr",
            "Q": matrix_to_json(Q),
            "R": matrix_to_json(R),
            "augmented": bool(q),
        }
    if method in ("place", "ackermann"):
        poles = _poles(ctl, na, spec.Ts, "controller")
        if method == "ackermann":
            if m != 1:
                raise SpecError("controller.method 'ackermann' is single-input only; use 'place'")
            warnings.append("Ackermann's formula is numerically fragile for more than a few states; prefer 'place'")
            K = np.atleast_2d(control.acker(Aa, Ba, poles))
        else:
            try:
                K = control.place(Aa, Ba, poles)
            except Exception as exc:
                raise DesignError(f"pole placement failed: {str(exc).splitlines()[0]}") from None
        return np.real(np.asarray(K, complex)).astype(float), {
            "method": method,
            "poles": complex_pairs(poles),
            "augmented": bool(q),
        }
    if method == "given":
        return _given_controller(ctl, n=spec.n, m=m, q=q), {"method": "given", "augmented": bool(q)}
    raise SpecError(f"controller.method must be lqr, place, ackermann or given, not {method!r}")


def _given_matrix(table: dict, key: str, shape: tuple[int, int], where: str) -> np.ndarray:
    """A user-given gain matrix of exactly ``shape`` (a 1-row or 1-column matrix may be given as a list)."""
    if key not in table:
        raise SpecError(f"{where}.method 'given' needs {key} ({shape[0]}x{shape[1]})")
    raw = table[key]
    if isinstance(raw, list) and raw and not any(isinstance(x, list) for x in raw) and 1 in shape:
        value = as_vector(raw, f"{where}.{key}", shape[0] * shape[1]).reshape(shape)
    else:
        value = as_matrix(raw, f"{where}.{key}")
    if value.shape != shape:
        raise SpecError(f"{where}.{key} is {value.shape[0]}x{value.shape[1]}, expected {shape[0]}x{shape[1]}")
    return value


def _given_controller(ctl: dict, *, n: int, m: int, q: int) -> np.ndarray:
    """``[K Ki]`` as the user gave them: discrete-time gains for the plant discretised at Ts."""
    for key in ("Q", "Q_diag", "bryson_x_max", "bryson_y_max", "R", "R_diag", "bryson_u_max", "poles", "poles_z"):
        if key in ctl:
            raise SpecError(f"controller.{key} is a design setting; method 'given' takes K (and Ki) only")
    K = _given_matrix(ctl, "K", (m, n), "controller")
    if q:
        Ki = _given_matrix(ctl, "Ki", (m, q), "controller")
    elif "Ki" in ctl:
        raise SpecError("controller.Ki is given but there is no [integral] table naming the tracked outputs")
    else:
        Ki = np.zeros((m, 0))
    return np.hstack([K, Ki])


def _observer(spec: PlantSpec, d: Discretised, warnings: list[str]):
    import control

    obs = spec.observer
    method = obs.get("method", "kalman")
    form = obs.get("form", "predictor")
    if form not in ("predictor", "current"):
        raise SpecError(f"observer.form must be predictor or current, not {form!r}")
    if form == "current" and np.any(d.Dd != 0):
        raise SpecError(
            "observer.form 'current' requires a plant without feedthrough (D = 0 after discretisation;"
            " Tustin adds feedthrough: use zoh)"
        )
    p, n = d.Cd.shape
    if method == "kalman":
        if obs.get("G") == "B":
            G = d.Bd  # process noise enters where the inputs do
        else:
            G = as_matrix(obs["G"], "observer.G") if "G" in obs else np.eye(n)
        if G.shape[0] != n:
            raise SpecError(f"observer.G has {G.shape[0]} rows, expected {n}")
        W = _weight(obs, ("W", "W_diag", "_none"), G.shape[1], "observer", required=True)
        V = _weight(obs, ("V", "V_diag", "_none"), p, "observer", required=True)
        _check_psd(W, "observer W (process noise covariance)", definite=False)
        _check_psd(V, "observer V (measurement noise covariance)", definite=True)
        try:
            P, _, _ = control.dare(d.Ad.T, d.Cd.T, G @ W @ G.T, V)
        except Exception as exc:
            raise DesignError(f"Kalman DARE failed: {str(exc).splitlines()[0]} (is (A, G) stabilizable?)") from None
        P = np.asarray(P, float)
        M = P @ d.Cd.T @ np.linalg.inv(d.Cd @ P @ d.Cd.T + V)
        L = d.Ad @ M
        record = {"method": "kalman", "W": matrix_to_json(W), "V": matrix_to_json(V)}
        if "G" in obs:
            record["G"] = matrix_to_json(G)
    elif method == "luenberger":
        poles = _poles(obs, n, spec.Ts, "observer")
        try:
            L = np.real(np.asarray(control.place(d.Ad.T, d.Cd.T, poles), complex)).T
        except Exception as exc:
            raise DesignError(f"observer pole placement failed: {str(exc).splitlines()[0]}") from None
        M = None
        if form == "current":
            if np.linalg.cond(d.Ad) > 1e12:
                raise DesignError("current-form Luenberger observer needs an invertible Ad")
            M = np.linalg.solve(d.Ad, L)
        record = {"method": "luenberger", "poles": complex_pairs(poles)}
    elif method == "given":
        L, M = _given_observer(obs, d, form=form)
        record = {"method": "given"}
    else:
        raise SpecError(f"observer.method must be kalman, luenberger or given, not {method!r}")
    return L, (M if form == "current" else None), record


def _given_observer(obs: dict, d: Discretised, *, form: str) -> tuple[np.ndarray, np.ndarray | None]:
    """The user's observer gain: ``L`` (predictor form) or ``M`` (current form, ``L = Ad M``)."""
    p, n = d.Cd.shape
    for key in ("W", "W_diag", "V", "V_diag", "G", "poles", "poles_z"):
        if key in obs:
            raise SpecError(f"observer.{key} is a design setting; method 'given' takes L (or M) only")
    if form == "current":
        if "L" in obs:
            raise SpecError("observer.form 'current' with method 'given' takes the filter gain M (L = Ad M follows)")
        M = _given_matrix(obs, "M", (n, p), "observer")
        return d.Ad @ M, M
    if "M" in obs:
        raise SpecError("observer.M is the current form's filter gain; the predictor form takes L")
    return _given_matrix(obs, "L", (n, p), "observer"), None


def _fmt_list(values) -> str:
    return ", ".join(
        f"{complex(v).real:.4g}{complex(v).imag:+.4g}j" if abs(complex(v).imag) > 1e-12 else f"{complex(v).real:.4g}"
        for v in values
    )
