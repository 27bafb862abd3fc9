"""The Python API for a python-control user in a notebook: designs from a spec, a dict or a
``control.StateSpace``/``TransferFunction``, artifacts from one's own gains, replay and simulation.

Everything here returns a loaded :class:`~gainlink.shipping.artifact.Artifact` or a frozen dataclass of numpy
arrays; the command line calls the same functions. Names follow python-control where they exist.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from .errors import SpecError
from .fileio import read_toml
from .laws import design as design_spec
from .laws import law_for_spec, law_of
from .proof.reference import Trace
from .proof.simulation import Simulation
from .shipping.artifact import Artifact, from_dict
from .spec import PlantSpec, load_spec, parse_spec
from .synthesis import DesignResult
from .synthesis.plant_report import AnalysisReport
from .synthesis.plant_report import analyze as analyze_spec

_IDENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")

#: Keyword shortcuts of :func:`design` and the spec table each belongs to.
_SHORTCUTS = {
    "Q": "controller",
    "R": "controller",
    "W": "observer",
    "V": "observer",
    "u_min": "limits",
    "u_max": "limits",
}


def design(
    plant: Any,
    *,
    Ts: float | None = None,
    name: str | None = None,
    Q: Any = None,
    R: Any = None,
    W: Any = None,
    V: Any = None,
    u_min: Any = None,
    u_max: Any = None,
    controller: Mapping[str, Any] | None = None,
    integral: Mapping[str, Any] | None = None,
    observer: Mapping[str, Any] | None = None,
    limits: Mapping[str, Any] | None = None,
    operating_point: Mapping[str, Any] | None = None,
    discretization: str | None = None,
    schedule: Mapping[str, Any] | None = None,
    implementation: Mapping[str, Any] | None = None,
) -> Artifact:
    """Design a controller and observer and return the checked, sealed artifact.

    Parameters
    ----------
    plant : str, Path, dict, control.StateSpace or control.TransferFunction
        A spec file (TOML), a spec as a dict (the parsed TOML), or a python-control system:
        continuous (then ``Ts`` is required) or discrete (``Ts`` is the system's ``dt``).
    Ts : float, optional
        Sample time in seconds.
    name : str, optional
        Identifier used in C names (default: the spec's name, or ``"plant"``).
    Q, R, W, V : array_like, optional
        LQR state and input weights, Kalman process and measurement noise covariances (full
        matrices). They fill the ``controller`` and ``observer`` tables.
    u_min, u_max : array_like, optional
        Actuator limits (absolute), filling the ``limits`` table.
    controller, integral, observer, limits, operating_point : dict, optional
        Spec tables with the keys of a spec file (docs/guide/specs.md); given keys replace the
        spec's. With a python-control system, ``controller`` defaults to LQR and ``observer`` to
        a Kalman predictor.
    discretization : {"zoh", "tustin"}, optional
        How a continuous plant is sampled (default ``zoh``).
    schedule : dict, optional
        The ``[schedule]`` table (docs/guide/scheduled.md): ``sigma``, ``points``, optional ``external``,
        ``rate_max`` (with ``rate_certified = False`` to ship it where no certificate covers it),
        ``certify_budget`` (CPU seconds of the certificate searches), ``filter_tau``, and ``plant``: one entry per
        point, each a ``control.StateSpace`` (about the origin) or a dict of ``A B C D u_op y_op x_op``. ``plant``
        then gives only the shared kind and names (a python-control system's own matrices are dropped). The
        artifact is scheduled (schema 2).
    implementation : dict, optional
        The ``[implementation]`` table, e.g. ``{"numeric": "q31"}`` for the fixed-point law
        (docs/guide/fixed_point.md; needs the ranges ``y_min y_max r_min r_max`` in ``limits``); given keys
        replace the spec's.

    Returns
    -------
    Artifact

    Raises
    ------
    SpecError, DesignError
        A missing or malformed setting, or a design that fails its checks.

    Examples
    --------
    >>> import control as ct, numpy as np, gainlink as gl
    >>> sys = ct.ss([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], [[1.0, 0.0]], [[0.0]])
    >>> art = gl.design(sys, Ts=0.01, Q=np.diag([10.0, 1.0]), R=[[1.0]],
    ...                 W=np.diag([1e-4, 1e-4]), V=[[1e-6]], u_min=[-5.0], u_max=[5.0])
    >>> art.n, art.m, art.p, art.observer_form
    (2, 1, 1, 'predictor')

    A plant whose time constant changes tenfold, scheduled on an external signal ``load``:

    >>> family = [ct.ss([[-a]], [[a]], [[1.0]], [[0.0]]) for a in (1.0, 3.0, 10.0)]
    >>> sched = gl.design(family[0], Ts=0.01, Q=[[1.0]], R=[[1.0]], W=[[1e-3]], V=[[1e-4]],
    ...                   u_min=[-5.0], u_max=[5.0], integral={"outputs": [0], "Q_diag": [10.0]},
    ...                   schedule={"sigma": "load", "external": ["load"], "points": [0.0, 0.5, 1.0],
    ...                             "plant": family})
    >>> sched.anti_windup, sched.schedule.points.tolist(), sched.controller(sigma=0.25).nstates
    ('velocity', [0.0, 0.5, 1.0], 2)
    """
    report = design_report(
        plant,
        Ts=Ts,
        name=name,
        Q=Q,
        R=R,
        W=W,
        V=V,
        u_min=u_min,
        u_max=u_max,
        controller=controller,
        integral=integral,
        observer=observer,
        limits=limits,
        operating_point=operating_point,
        discretization=discretization,
        schedule=schedule,
        implementation=implementation,
    )
    return from_dict(report.artifact)


def design_report(
    plant: Any,
    *,
    Ts: float | None = None,
    name: str | None = None,
    Q: Any = None,
    R: Any = None,
    W: Any = None,
    V: Any = None,
    u_min: Any = None,
    u_max: Any = None,
    controller: Mapping[str, Any] | None = None,
    integral: Mapping[str, Any] | None = None,
    observer: Mapping[str, Any] | None = None,
    limits: Mapping[str, Any] | None = None,
    operating_point: Mapping[str, Any] | None = None,
    discretization: str | None = None,
    schedule: Mapping[str, Any] | None = None,
    implementation: Mapping[str, Any] | None = None,
) -> DesignResult:
    """:func:`design` with the numbers behind its checks: what ``gainlink design`` prints.

    Takes the parameters of :func:`design`. A spec file given alone is read as ``gainlink design`` reads it
    (its ``provenance.spec_sha256`` is the file's own sha256); with options, the hash is that of the merged spec.

    Returns
    -------
    DesignResult
        ``artifact`` (the sealed dict), controller, observer and closed-loop poles, margins, warnings, and the
        compensator, float32 and dead-time checks.

    Examples
    --------
    >>> import gainlink as gl
    >>> r = gl.design_report("examples/pendulum.toml")
    >>> r.artifact["sha256"] == gl.design("examples/pendulum.toml").sha256, bool(max(abs(r.closed_loop_poles)) < 1)
    (True, True)
    """
    tables = {
        "controller": controller,
        "integral": integral,
        "observer": observer,
        "limits": limits,
        "operating_point": operating_point,
        "schedule": schedule,
        "implementation": implementation,
    }
    shortcuts = {"Q": Q, "R": R, "W": W, "V": V, "u_min": u_min, "u_max": u_max}
    given = [v for v in (Ts, name, discretization, *tables.values(), *shortcuts.values()) if v is not None]
    if isinstance(plant, (str, Path)) and not given:
        return design_spec(load_spec(plant))
    data = _merge_tables(_spec_dict(plant, Ts=Ts, name=name, discretization=discretization), tables, shortcuts)
    return design_spec(_parse(data, source=_source_name(plant)))


def analyze(spec: str | Path | Mapping[str, Any]) -> AnalysisReport:
    """Structural analysis of a spec's plant, with the checks of the spec's own design: what ``gainlink analyze``
    prints (poles, PBH per mode, zeros, bandwidth against the sample rate, scaling, warnings).

    Examples
    --------
    >>> import gainlink as gl
    >>> rep = gl.analyze("examples/pendulum.toml")
    >>> rep.n, rep.stabilizable, rep.detectable
    (4, True, True)
    """
    parsed = load_spec(spec) if isinstance(spec, (str, Path)) else _parse(json.loads(json.dumps(spec)), source="<dict>")
    law = law_for_spec(parsed)
    report = analyze_spec(parsed, design=law.design)
    return replace(report, law_lines=law.analysis_lines(report))


def from_gains(
    plant: Any,
    *,
    K: Any,
    L: Any = None,
    M: Any = None,
    Ki: Any = None,
    Ci: Any = None,
    u_min: Any,
    u_max: Any,
    u_op: Any = None,
    y_op: Any = None,
    Ts: float | None = None,
    anti_windup: str | None = None,
    aw_gain: float | None = None,
    name: str | None = None,
) -> Artifact:
    """An artifact from gains the user computed (e.g. with ``control.dlqr``), with every design check.

    Parameters
    ----------
    plant : str, Path, dict, control.StateSpace or control.TransferFunction
        The plant the gains were computed for (as in :func:`design`); the gains are discrete-time
        gains for this plant sampled at ``Ts`` (``control.c2d(plant, Ts)`` for a continuous one).
    K : array_like (m, n)
        State feedback: ``u = u_op - K xh - Ki z``.
    L : array_like (n, p), optional
        Predictor-form observer gain. Give exactly one of ``L`` and ``M``.
    M : array_like (n, p), optional
        Current-form filter gain (``L = Ad M``); needs a plant without feedthrough.
    Ki : array_like (m, q), optional
        Integral gain, with ``Ci``.
    Ci : array_like (q, p), optional
        Rows of the identity selecting the tracked outputs (``e = r - Ci y``).
    u_min, u_max : array_like (m,)
        Actuator limits (absolute).
    u_op, y_op : array_like, optional
        Operating point: trim command (m) and the outputs there (p); zeros by default.
    Ts : float, optional
        Sample time (required for a continuous plant).
    anti_windup : {"none", "clamp", "backcalc"}, optional
        Anti-windup with integral action (default ``backcalc``).
    aw_gain : float, optional
        Back-calculation gain in (0, 1].
    name : str, optional
        Identifier used in C names.

    Returns
    -------
    Artifact
        Its ``provenance["gains"]`` says the gains were given.

    Examples
    --------
    >>> import control as ct, numpy as np, gainlink as gl
    >>> sysd = ct.c2d(ct.ss([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], [[1.0, 0.0]], [[0.0]]), 0.01)
    >>> K, _, _ = ct.dlqr(sysd, np.diag([10.0, 1.0]), [[1.0]])
    >>> Lt, _, _ = ct.dlqr(sysd.A.T, sysd.C.T, np.diag([1e-4, 1e-4]), [[1e-6]])
    >>> art = gl.from_gains(sysd, K=K, L=Lt.T, u_min=[-5.0], u_max=[5.0])
    >>> art.provenance["gains"]
    'given: controller, observer'
    """
    if (L is None) == (M is None):
        raise SpecError("from_gains: give exactly one of L (predictor form) and M (current form)")
    data = _spec_dict(plant, Ts=Ts, name=name, discretization=None)
    controller: dict[str, Any] = {"method": "given", "K": _rows(K)}
    tables: dict[str, Any] = {"controller": controller, "limits": {"u_min": _list(u_min), "u_max": _list(u_max)}}
    tables["observer"] = (
        {"method": "given", "form": "predictor", "L": _rows(L)}
        if L is not None
        else {"method": "given", "form": "current", "M": _rows(M)}
    )
    if (Ki is None) != (Ci is None):
        raise SpecError("from_gains: integral action needs both Ci (tracked outputs) and Ki")
    if Ki is not None:
        controller["Ki"] = _rows(Ki)
        tables["integral"] = {"outputs": _selected_outputs(Ci, p=_output_count(data))}
        if aw_gain is not None:
            tables["integral"]["aw_gain"] = float(aw_gain)
    if anti_windup is not None:
        tables["limits"]["anti_windup"] = anti_windup
    if u_op is not None or y_op is not None:
        tables["operating_point"] = {k: _list(v) for k, v in (("u_op", u_op), ("y_op", y_op)) if v is not None}
    for key in ("controller", "observer", "integral"):
        data.pop(key, None)
    data.update(tables)
    return from_dict(design_spec(_parse(data, source=_source_name(plant))).artifact)


def replay(
    artifact: Artifact,
    y: Any,
    r: Any = None,
    *,
    s: Any = None,
    engine: str = "reference",
    target: str | None = None,
    board: str | None = None,
) -> Trace:
    """Run recorded samples through an implementation of the control law, from its initial state.

    Parameters
    ----------
    artifact : Artifact
        The gains.
    y : array_like (N, p)
        Measurements (absolute), one row per sample; non-finite rows are refused by the law.
    r : array_like (N, q), optional
        References (absolute), zeros by default.
    s : array_like (N, e), optional
        A scheduled artifact's external scheduling signals (``schedule.external``, in order).
    engine : {"reference", "model", "native", "qemu"}
        The law's float64 reference, the bit-exact model of its C (float32 with explicit fused multiply-adds, or a
        fixed-point law's integers), the host C library (built on first use), or a Cortex-M image in QEMU.
    target : str, optional
        With ``engine="qemu"``: the core whose image runs, ``cortex-m0``, ``cortex-m3``, ``cortex-m4``
        (default), ``cortex-m7``, ``cortex-m33`` or ``cortex-m55``.
    board : str, optional
        With ``engine="qemu"``: its QEMU board (default: the target's; a board alone implies its core).

    Returns
    -------
    Trace
        Commands, saturation flags, faults and the state after each step (a scheduled artifact:
        :class:`~gainlink.laws.scheduled.reference.ScheduledTrace`, with the sigma each step used).

    Examples
    --------
    >>> import control as ct, numpy as np, gainlink as gl
    >>> art = gl.design(ct.ss([[0.9]], [[0.1]], [[1.0]], [[0.0]], 0.01), Q=[[1.0]], R=[[1.0]],
    ...                 W=[[1e-3]], V=[[1e-4]], u_min=[-1.0], u_max=[1.0])
    >>> tr = gl.replay(art, np.full((5, 1), 0.5))
    >>> tr.u.shape, bool(tr.u[0, 0] == 0.0), bool(tr.u[1, 0] < 0.0)
    ((5, 1), True, True)
    """
    Y = np.asarray(y, dtype=float).reshape(-1, artifact.p)
    R = np.zeros((Y.shape[0], artifact.q)) if r is None else np.asarray(r, dtype=float).reshape(Y.shape[0], artifact.q)
    trace: Trace = law_of(artifact).replay(artifact, engine, Y, R, s, target=target, board=board)
    return trace


def simulate(
    artifact: Artifact,
    *,
    steps: int,
    x0: Any = None,
    reference: Any = None,
    noise_std: float = 0.0,
    seed: int = 0,
    signals: Any = None,
) -> Simulation:
    """Closed-loop run of the law's float64 reference against the artifact's own discrete plant (a scheduled law:
    its points' model, following its scheduled output or the external signals).

    Parameters
    ----------
    artifact : Artifact
        The design.
    steps : int
        Number of samples.
    x0 : array_like (n,), optional
        Initial plant state (deviation from the operating point).
    reference : array_like (q,), optional
        Constant reference of the tracked outputs.
    noise_std : float
        Standard deviation of white measurement noise.
    seed : int
        Seed of the noise.
    signals : array_like (e,) or (steps, e), optional
        A scheduled law's external scheduling signals (``schedule.external``, in order).

    Returns
    -------
    Simulation
        ``t, x, y, r, u`` (and ``s``) arrays; ``y``, ``r`` and ``s`` replay to the same ``u`` through any engine.

    Examples
    --------
    >>> import control as ct, numpy as np, gainlink as gl
    >>> art = gl.design(ct.ss([[0.9]], [[0.1]], [[1.0]], [[0.0]], 0.01), Q=[[1.0]], R=[[1.0]],
    ...                 W=[[1e-3]], V=[[1e-4]], u_min=[-1.0], u_max=[1.0])
    >>> sim = gl.simulate(art, steps=200, x0=[1.0])
    >>> bool(abs(sim.y[-1, 0]) < 1e-3), bool(np.array_equal(gl.replay(art, sim.y).u, sim.u))
    (True, True)
    """
    sim: Simulation = law_of(artifact).simulate(artifact, steps=steps, x0=x0, reference=reference,
                                                 noise_std=noise_std, seed=seed, signals=signals)  # fmt: skip
    return sim


def load(path: str | Path) -> Artifact:
    """Read and check ``gains.json`` (schema, sha256, dimensions); same as :meth:`Artifact.load`.

    Examples
    --------
    >>> import tempfile, pathlib, control as ct, gainlink as gl
    >>> art = gl.design(ct.ss([[0.9]], [[0.1]], [[1.0]], [[0.0]], 0.01), Q=[[1.0]], R=[[1.0]],
    ...                 W=[[1e-3]], V=[[1e-4]], u_min=[-1.0], u_max=[1.0])
    >>> with tempfile.TemporaryDirectory() as d:
    ...     art.save(pathlib.Path(d) / "gains.json")
    ...     gl.load(pathlib.Path(d) / "gains.json").sha256 == art.sha256
    True
    """
    return Artifact.load(path)


# --- plants to spec dicts ---------------------------------------------------------------------------


def _spec_dict(plant: Any, *, Ts: float | None, name: str | None, discretization: str | None) -> dict[str, Any]:
    """A spec dict (the parsed-TOML shape) for ``plant``, with ``Ts``, ``name`` and ``discretization`` set."""
    data: dict[str, Any]
    if isinstance(plant, (str, Path)):
        data = _spec_file_dict(Path(plant))
    elif isinstance(plant, Mapping):
        data = json.loads(json.dumps(plant))  # a deep copy the caller's dict never sees changed
    else:
        data = _system_dict(plant, Ts=Ts)
    if Ts is not None:
        if "Ts" in data and data.get("plant", {}).get("kind") == "discrete" and float(data["Ts"]) != float(Ts):
            raise SpecError(f"Ts = {Ts} differs from the discrete plant's sample time {data['Ts']}")
        data["Ts"] = float(Ts)
    if name is not None:
        data["name"] = name
    data.setdefault("name", "plant")
    if discretization is not None:
        data["discretization"] = discretization
    return data


def _spec_file_dict(path: Path) -> dict[str, Any]:
    data, _ = read_toml(path, what="spec", error=SpecError)
    data.setdefault("name", load_spec(path).name)  # every key checked as gainlink design checks it
    return data


def _system_dict(sys: Any, *, Ts: float | None) -> dict[str, Any]:
    """The ``[plant]`` table and ``Ts`` of a python-control system, with its signal names where they are identifiers."""
    import control

    if isinstance(sys, control.TransferFunction):
        sys = control.ss(sys)
    if not isinstance(sys, control.StateSpace):
        raise SpecError(
            f"plant must be a spec file, a spec dict or a control.StateSpace/TransferFunction, not {type(sys).__name__}"
        )
    plant: dict[str, Any] = {"A": _rows(sys.A), "B": _rows(sys.B), "C": _rows(sys.C), "D": _rows(sys.D)}
    for key, labels, prefix in (
        ("states", sys.state_labels, "x"),
        ("inputs", sys.input_labels, "u"),
        ("outputs", sys.output_labels, "y"),
    ):
        plant[key] = _identifiers(labels, prefix)
    data: dict[str, Any] = {"plant": plant}
    if sys.isdtime(strict=True):
        plant["kind"] = "discrete"
        dt = 1.0 if sys.dt is True else float(sys.dt)
        if Ts is not None and float(Ts) != dt:
            raise SpecError(f"Ts = {Ts} differs from the discrete system's dt = {dt}")
        data["Ts"] = dt
    else:
        plant["kind"] = "continuous"
        if Ts is None:
            raise SpecError("a continuous plant needs Ts (the sample time of the controller)")
    data["controller"] = {"method": "lqr"}
    data["observer"] = {"method": "kalman"}
    return data


def _schedule_table(schedule: Mapping[str, Any]) -> dict[str, Any]:
    """The ``[schedule]`` table with each point's plant as a spec table (a ``control.StateSpace`` becomes its
    matrices)."""
    import control

    table = dict(schedule)
    points = table.get("plant")
    if isinstance(points, (list, tuple)):
        table["plant"] = [
            {"A": _rows(p.A), "B": _rows(p.B), "C": _rows(p.C), "D": _rows(p.D)}
            if isinstance(p, control.StateSpace)
            else {k: _jsonable(v) for k, v in dict(p).items()}
            for p in points
        ]
    return table


def _points_hold_the_plant(data: dict[str, Any]) -> dict[str, Any]:
    """A ``[schedule]`` given: its points hold the matrices and operating points; ``[plant]`` keeps the shared kind
    and names."""
    data["plant"] = {k: v for k, v in data["plant"].items() if k in ("kind", "states", "inputs", "outputs")}
    data.pop("operating_point", None)
    return data


def _unchanged(data: dict[str, Any]) -> dict[str, Any]:
    return data


#: A table given as an argument, in its spec form (a ``[schedule]``'s points may be ``control.StateSpace``s).
_TABLE_FORMS = {"schedule": _schedule_table}
#: What giving a table as an argument does to the rest of the spec.
_TABLE_EFFECTS = {"schedule": _points_hold_the_plant}


def _identifiers(labels: list[str], prefix: str) -> list[str]:
    """python-control's labels when they are all distinct identifiers (``u[0]`` is not), else prefix + index."""
    if all(_IDENT.match(s) for s in labels) and len(set(labels)) == len(labels):
        return list(labels)
    return [f"{prefix}{i}" for i in range(len(labels))]


#: Spec keys a weight given as a full matrix replaces (one way to give each weight).
_REPLACES = {
    "Q": ("Q_diag", "bryson_x_max", "bryson_y_max"),
    "R": ("R_diag", "bryson_u_max"),
    "W": ("W_diag",),
    "V": ("V_diag",),
    "u_min": (),
    "u_max": (),
}


def _merge_tables(data: dict[str, Any], tables: Mapping[str, Any], shortcuts: Mapping[str, Any]) -> dict[str, Any]:
    """``data`` with the given tables' keys replaced (each in its spec form, :data:`_TABLE_FORMS`, and with what
    giving it does to the rest, :data:`_TABLE_EFFECTS`), then the keyword shortcuts put in their tables."""
    for key, table in tables.items():
        if table is not None:
            merged = dict(data.get(key) or {})
            merged.update({k: _jsonable(v) for k, v in _TABLE_FORMS.get(key, dict)(table).items()})
            data[key] = merged
            data = _TABLE_EFFECTS.get(key, _unchanged)(data)
    for key, value in shortcuts.items():
        if value is None:
            continue
        table = data.setdefault(_SHORTCUTS[key], {})
        for other in _REPLACES[key]:
            table.pop(other, None)
        table[key] = _list(value) if key in ("u_min", "u_max") else _rows(value)
    return data


def _parse(data: dict[str, Any], *, source: str) -> PlantSpec:
    """The typed spec of a spec dict, hashed by its canonical JSON (there is no file to hash)."""
    digest = hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()
    return parse_spec(data, source=source, source_sha256=digest)


def _source_name(plant: Any) -> str:
    return str(plant) if isinstance(plant, (str, Path)) else f"<{type(plant).__name__}>"


def _output_count(data: Mapping[str, Any]) -> int:
    plant = data.get("plant", {})
    if "C" in plant:
        return len(plant["C"])
    return len(plant.get("num", []))


def _selected_outputs(Ci: Any, *, p: int) -> list[int]:
    """Output indices that ``Ci``'s rows select; refuses anything but rows of the identity."""
    C = np.atleast_2d(np.asarray(Ci, dtype=float))
    if C.shape[1] != p:
        raise SpecError(f"Ci has {C.shape[1]} columns, expected {p} (one per output)")
    picks = []
    for row in C:
        ones = np.flatnonzero(row)
        if len(ones) != 1 or row[ones[0]] != 1.0:
            raise SpecError("Ci rows must be rows of the identity (each selects one tracked output)")
        picks.append(int(ones[0]))
    return picks


def _rows(a: Any) -> list[list[float]]:
    return [[float(v) for v in row] for row in np.atleast_2d(np.asarray(a, dtype=float))]


def _list(v: Any) -> list[float]:
    return [float(x) for x in np.asarray(v, dtype=float).ravel()]


def _jsonable(v: Any) -> Any:
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.generic):
        return v.item()
    return v
