"""The campaign file: a base run, the axes that vary it, and the pass/fail criteria of every run.

Example (``examples/campaigns/`` has complete ones)::

    name = "pendulum_mass_uncertainty"
    kind = "sil"                      # sil (default: the C loop in-process, no bus) | hil (the bridge)
    seed = 2026                       # the campaign's draws and every run's noise follow from it
    runs = 500                        # Monte-Carlo draws per grid point (default 1)
    spec = "../pendulum.toml"         # designed once per grid point ... or: artifact = "gains.json"
    traces = "drawn"                  # drawn (default): store the traces of the runs the envelopes draw | all

    [scenario]                        # the base run: a HIL scenario's keys except artifact (SIL: no transport)
    duration = 8.0
    plant = { kind = "cart_pendulum", outputs = ["x", "theta"], parameters = { M = 1.0, m = 0.1, l = 0.5 } }
    initial_state = { theta = 0.15 }

    [[grid]]                          # every value of every grid axis (Cartesian product)
    target = "spec.limits.anti_windup"            # spec.* changes the design; any other path the run
    values = ["none", "clamp", "backcalc"]

    [[draw]]                          # a random value per run
    target = "plant.parameters.M"     # or targets = [...] with a name: one value applied to each
    distribution = "uniform"          # normal (mean, std) | uniform (low, high) | loguniform (low, high)
    low = 0.7                         # | truncnormal (mean, std, low, high) | choice (values)
    high = 1.3
    apply = "set"                     # set (default) | scale (times the base value) | add (to it)

    [fault_matrix]                    # HIL only: grid axes over link faults in a window
    drop = [0.0, 0.05]                # fraction of samples dropped at random
    delay_steps = [0, 2]              # every sample delayed this many samples
    encoding = ["float32", "int16"]   # the CAN transport's encoding
    start = 2.0                       # window [start, stop) in seconds (default: the whole run)

    [criteria]                        # every run passes or fails each; a run passes when it passes all
    stable = true                     # completed, finite, not growing at the end (see criteria.py)
    bounds = { theta = [-0.6, 0.6] }  # outputs stay within for the whole run
    settled_within = 6.0              # s after the last reference change (2 % band)
    overshoot_below = 25.0            # percent
    saturated_at_most = 1.0           # s: the longest stretch of a saturated command
    iae_below = 3.0                   # every tracked output
    twin_deviation_below = 0.01       # max |y - y_twin| / excursion of y_twin against the float64 twin

Paths are dotted keys into the base scenario (``plant.parameters.M``, ``initial_state.theta``,
``reference.r_x.value``, ``plant.parameters."spring.c"``, ``plant.perturb."A[3][2]"``: a key holding dots
or brackets is quoted) or into the spec (``spec.controller.Q_diag[2]``, ``spec.Ts``, ``spec.limits.u_max[0]``);
a value may be a whole table (e.g. an initial-condition set). Unknown keys
anywhere are refused with one line naming them.
"""

from __future__ import annotations

import functools
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gainlink.errors import ScenarioError, did_you_mean
from gainlink.fileio import read_toml

KINDS = ("sil", "hil")
TOP_KEYS = {
    "name",
    "description",
    "kind",
    "seed",
    "runs",
    "spec",
    "artifact",
    "scenario",
    "grid",
    "draw",
    "fault_matrix",
    "criteria",
    "traces",
}
#: Whose downsampled traces a campaign stores: ``drawn``, the runs its envelopes draw (every run of a campaign of at
#: most ``envelopes.ENVELOPE_RUNS``; any other run's trace is ``campaign show --run``'s replay), or ``all``.
TRACES = ("drawn", "all")
DISTRIBUTIONS = {
    "normal": {"mean", "std"},
    "uniform": {"low", "high"},
    "loguniform": {"low", "high"},
    "truncnormal": {"mean", "std", "low", "high"},
    "choice": {"values"},
}
APPLY = ("set", "scale", "add")
CRITERIA_KEYS = {
    "stable",
    "bounds",
    "settled_within",
    "overshoot_below",
    "saturated_at_most",
    "iae_below",
    "twin_deviation_below",
}
FAULT_MATRIX_KEYS = {"drop", "delay_steps", "encoding", "start", "stop"}
ENCODINGS = ("float32", "int16")
_SEGMENT = r'(?:[A-Za-z_][A-Za-z0-9_]*|"[^"]+")(?:\[\d+\])*'
_PATH = re.compile(rf"^{_SEGMENT}(?:\.{_SEGMENT})*$")
_STEP = re.compile(r'([A-Za-z_][A-Za-z0-9_]*|"[^"]+")((?:\[\d+\])*)(?:\.|$)')


@functools.cache  # a campaign sets the same few paths in every run
def path_steps(path: str) -> tuple[str | int, ...]:
    """The keys and indices of a checked path: ``plant.parameters."spring.c"`` -> plant, parameters, spring.c;
    ``spec.controller.Q_diag[2]`` -> spec, controller, Q_diag, 2 (a quoted key may hold dots and brackets)."""
    out: list[str | int] = []
    for m in _STEP.finditer(path):
        out.append(m.group(1).strip('"'))
        out += [int(i) for i in re.findall(r"\[(\d+)\]", m.group(2))]
    return tuple(out)


def value_at(tree: Any, path: str, missing: Any = None) -> Any:
    """The value at ``path`` (:func:`path_steps`) in ``tree``; ``missing`` where there is none."""
    node = tree
    for step in path_steps(path):
        if isinstance(step, int):
            if not isinstance(node, list) or step >= len(node):
                return missing
        elif not isinstance(node, dict) or step not in node:
            return missing
        node = node[step]
    return node


class CampaignError(ScenarioError):
    """A campaign file is malformed or asks for something a run cannot do."""


@dataclass(frozen=True)
class Axis:
    """One grid or draw axis: a name (its column in the report), the paths it sets and how.

    ``values`` for a grid axis; ``distribution`` and its ``params`` for a draw axis. ``targets``
    beginning with ``spec.`` change the design; the fault-matrix axes have the special targets
    ``faults.drop``, ``faults.delay_steps`` and ``transport.encoding``.
    """

    name: str
    targets: tuple[str, ...]
    apply: str = "set"
    values: tuple = ()
    distribution: str | None = None
    params: dict = field(default_factory=dict)

    @property
    def design(self) -> bool:
        """True when this axis changes the design (its targets are in the spec)."""
        return any(t.startswith("spec.") for t in self.targets)


@dataclass(frozen=True)
class Criteria:
    """Pass/fail limits of a run (``None``: not checked); see :mod:`.criteria`."""

    stable: bool = False
    bounds: dict = field(default_factory=dict)
    settled_within: float | None = None
    overshoot_below: float | None = None
    saturated_at_most: float | None = None
    iae_below: float | None = None
    twin_deviation_below: float | None = None


@dataclass(frozen=True)
class Campaign:
    """A parsed, checked campaign file (see the module docstring)."""

    name: str
    kind: str
    seed: int
    runs: int
    spec: dict | None
    spec_path: Path | None
    artifact_path: Path | None
    scenario: dict
    grid: tuple[Axis, ...]
    draws: tuple[Axis, ...]
    criteria: Criteria
    fault_window: tuple[float, float] = (0.0, 1e300)
    path: Path | None = None
    description: str = ""
    traces: str = "drawn"

    @property
    def base_dir(self) -> Path:
        """The folder relative paths of the file are read from."""
        return self.path.parent if self.path is not None else Path.cwd()

    @property
    def size(self) -> int:
        """How many runs the campaign has: the grid's points times the draws."""
        return math.prod(len(a.values) for a in self.grid) * self.runs


def _fail(msg: str) -> CampaignError:
    return CampaignError(f"campaign: {msg}")


def _keys(d: Any, allowed: set[str], where: str) -> dict:
    if not isinstance(d, Mapping):
        raise _fail(f"{where} must be a table")
    unknown = sorted(set(d) - allowed)
    if unknown:
        raise _fail(
            f"unknown key(s) {', '.join(unknown)}{did_you_mean(unknown[0], allowed)} in {where} "
            f"(allowed: {', '.join(sorted(allowed))})"
        )
    return dict(d)


def _number(v: Any, where: str, *, positive: bool = False) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise _fail(f"{where} must be a finite number, not {v!r}")
    if positive and v <= 0:
        raise _fail(f"{where} must be positive")
    return float(v)


def _path(p: Any, where: str) -> str:
    if not isinstance(p, str) or not _PATH.match(p):
        raise _fail(
            f"{where}: {p!r} is not a dotted path such as plant.parameters.M, spec.controller.Q_diag[2] "
            'or plant.perturb."A[3][2]" (quote a key holding dots or brackets)'
        )
    return p


def _targets(d: dict, where: str) -> tuple[str, tuple[str, ...]]:
    if ("target" in d) == ("targets" in d):
        raise _fail(f"{where} needs exactly one of target or targets")
    if "target" in d:
        target = _path(d["target"], f"{where}.target")
        return str(d.get("name", target)), (target,)
    ts = d["targets"]
    if not isinstance(ts, list) or not ts:
        raise _fail(f"{where}.targets must be a non-empty list of paths")
    if "name" not in d:
        raise _fail(f"{where}: an axis with several targets needs a name")
    return str(d["name"]), tuple(_path(t, f"{where}.targets") for t in ts)


def _apply(d: dict, where: str) -> str:
    apply = d.get("apply", "set")
    if apply not in APPLY:
        raise _fail(f"{where}.apply must be one of {', '.join(APPLY)}, not {apply!r}")
    return apply


def _grid_axis(d: Any, i: int) -> Axis:
    where = f"grid[{i}]"
    d = _keys(d, {"name", "target", "targets", "values", "apply"}, where)
    name, targets = _targets(d, where)
    values = d.get("values")
    if not isinstance(values, list) or not values:
        raise _fail(f"{where}.values must be a non-empty list")
    apply = _apply(d, where)
    if apply != "set":
        for v in values:
            _number(v, f"{where}.values (apply = {apply!r})")
    return Axis(name=name, targets=targets, apply=apply, values=tuple(values))


def _draw_axis(d: Any, i: int) -> Axis:
    where = f"draw[{i}]"
    d = _keys(d, {"name", "target", "targets", "distribution", "apply"} | set().union(*DISTRIBUTIONS.values()), where)
    name, targets = _targets(d, where)
    dist = d.get("distribution")
    if dist not in DISTRIBUTIONS:
        raise _fail(f"{where}.distribution must be one of {', '.join(DISTRIBUTIONS)}, not {dist!r}")
    allowed = DISTRIBUTIONS[dist]
    extra = sorted(set(d) - allowed - {"name", "target", "targets", "distribution", "apply"})
    missing = sorted(allowed - set(d))
    if extra or missing:
        raise _fail(
            f"{where}: distribution {dist} takes {', '.join(sorted(allowed))}"
            + (f" (missing {', '.join(missing)})" if missing else f" (not {', '.join(extra)})")
        )
    if dist == "choice":
        if not isinstance(d["values"], list) or not d["values"]:
            raise _fail(f"{where}.values must be a non-empty list")
        params = {"values": list(d["values"])}
    else:
        params = {k: _number(d[k], f"{where}.{k}") for k in sorted(allowed)}
        if "std" in params and params["std"] < 0:
            raise _fail(f"{where}.std must be >= 0")
        if "low" in params and not params["low"] < params["high"]:
            raise _fail(f"{where}: low must be below high")
        if dist == "loguniform" and params["low"] <= 0:
            raise _fail(f"{where}: loguniform needs 0 < low")
        if dist == "truncnormal" and params["std"] <= 0:
            raise _fail(f"{where}: truncnormal needs std > 0")
    return Axis(name=name, targets=targets, apply=_apply(d, where), distribution=dist, params=params)


def _fault_axes(d: Any) -> tuple[tuple[Axis, ...], tuple[float, float]]:
    d = _keys(d, FAULT_MATRIX_KEYS, "fault_matrix")
    axes = []
    for key, target in (
        ("drop", "faults.drop"),
        ("delay_steps", "faults.delay_steps"),
        ("encoding", "transport.encoding"),
    ):
        if key not in d:
            continue
        values = d[key]
        if not isinstance(values, list) or not values:
            raise _fail(f"fault_matrix.{key} must be a non-empty list")
        for v in values:
            if key == "drop" and not (0.0 <= _number(v, "fault_matrix.drop") <= 1.0):
                raise _fail("fault_matrix.drop values are fractions within [0, 1]")
            if key == "delay_steps" and (isinstance(v, bool) or not isinstance(v, int) or v < 0):
                raise _fail("fault_matrix.delay_steps values are whole numbers >= 0")
            if key == "encoding" and v not in ENCODINGS:
                raise _fail(f"fault_matrix.encoding values are {' or '.join(ENCODINGS)}, not {v!r}")
        axes.append(Axis(name=key, targets=(target,), values=tuple(values)))
    start = _number(d.get("start", 0.0), "fault_matrix.start")
    stop = _number(d.get("stop", 1e300), "fault_matrix.stop")
    if not 0 <= start < stop:
        raise _fail("fault_matrix: need 0 <= start < stop")
    return tuple(axes), (start, stop)


def _criteria(d: Any) -> Criteria:
    d = _keys(d, CRITERIA_KEYS, "criteria")
    out: dict[str, Any] = {}
    if "stable" in d:
        if not isinstance(d["stable"], bool):
            raise _fail("criteria.stable must be true or false")
        out["stable"] = d["stable"]
    bounds = _keys(d.get("bounds", {}), set(d.get("bounds", {}) or {}), "criteria.bounds")
    for name, b in bounds.items():
        if not (isinstance(b, list) and len(b) == 2):
            raise _fail(f"criteria.bounds.{name} must be [low, high]")
        lo, hi = (_number(x, f"criteria.bounds.{name}") for x in b)
        if not lo < hi:
            raise _fail(f"criteria.bounds.{name}: low must be below high")
        out.setdefault("bounds", {})[str(name)] = (lo, hi)
    for key in ("settled_within", "overshoot_below", "saturated_at_most", "iae_below", "twin_deviation_below"):
        if key in d:
            out[key] = _number(d[key], f"criteria.{key}", positive=key != "saturated_at_most")
            if out[key] < 0:
                raise _fail(f"criteria.{key} must be >= 0")
    return Criteria(**out)


def _file(data: dict, key: str, base: Path) -> Path | None:
    if key not in data:
        return None
    if not isinstance(data[key], str):
        raise _fail(f"{key} must be a path string")
    p = Path(data[key])
    return p if p.is_absolute() else base / p


def _load_spec(path: Path) -> dict:
    return read_toml(path, what="campaign: spec", error=CampaignError)[0]


def parse_campaign(data: Mapping[str, Any], *, path: Path | None = None) -> Campaign:
    """Check a campaign mapping (as read from TOML) and return a :class:`Campaign`."""
    data = _keys(data, TOP_KEYS, "the top level")
    base = path.parent if path is not None else Path.cwd()
    kind = data.get("kind", "sil")
    if kind not in KINDS:
        raise _fail(f"kind must be sil or hil, not {kind!r}")
    spec_path, artifact_path = _file(data, "spec", base), _file(data, "artifact", base)
    if (spec_path is None) == (artifact_path is None):
        raise _fail("give exactly one of spec (designed per grid point) or artifact (one gains.json)")
    scenario = _keys(data.get("scenario", {}), set(data.get("scenario", {}) or {}), "scenario")
    if "artifact" in scenario:
        raise _fail("scenario.artifact: the campaign's spec or artifact names it")
    for key in ("plant", "duration"):
        if key not in scenario:
            raise _fail(f"scenario needs {key}")
    if kind == "hil" and "transport" not in scenario:
        raise _fail("a hil campaign's scenario needs a transport")
    grid = [_grid_axis(a, i) for i, a in enumerate(_list(data.get("grid", []), "grid"))]
    draws = tuple(_draw_axis(a, i) for i, a in enumerate(_list(data.get("draw", []), "draw")))
    window = (0.0, 1e300)
    if "fault_matrix" in data:
        if kind != "hil":
            raise _fail('fault_matrix acts on a link: it needs kind = "hil"')
        faults, window = _fault_axes(data["fault_matrix"])
        grid += faults
    names = [a.name for a in (*grid, *draws)]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise _fail(f"axis name(s) {', '.join(dup)} used twice (give each a distinct name)")
    axes = (*grid, *draws)
    if artifact_path is not None and any(a.design for a in axes):
        raise _fail("spec.* axes need a spec to design from (the campaign names a fixed artifact)")
    runs = data.get("runs", 1)
    if isinstance(runs, bool) or not isinstance(runs, int) or runs < 1:
        raise _fail(f"runs must be a whole number >= 1, not {runs!r}")
    seed = data.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise _fail(f"seed must be a whole number >= 0, not {seed!r}")
    traces = data.get("traces", "drawn")
    if traces not in TRACES:
        raise _fail(f"traces must be drawn or all, not {traces!r}")
    return Campaign(
        name=str(data.get("name", path.stem if path is not None else "campaign")),
        kind=kind,
        seed=seed,
        runs=runs,
        spec=_load_spec(spec_path) if spec_path is not None else None,
        spec_path=spec_path,
        artifact_path=artifact_path,
        scenario=scenario,
        grid=tuple(grid),
        draws=draws,
        criteria=_criteria(data.get("criteria", {})),
        fault_window=window,
        path=path,
        description=str(data.get("description", "")),
        traces=traces,
    )


def _list(v: Any, where: str) -> list:
    if not isinstance(v, list):
        raise _fail(f"{where} must be an array of tables ([[{where}]])")
    return v


def load_campaign(path: str | Path) -> Campaign:
    """Read and check a campaign TOML file."""
    path = Path(path)
    data, _ = read_toml(path, what="campaign", error=CampaignError)
    return parse_campaign(data, path=path)
