"""``[schedule]`` and ``[[schedule.plant]]``: the points of a scheduled spec, each plant in the same coordinates.

``[plant]`` keeps what the points share (``kind`` and the signal names); each ``[[schedule.plant]]`` gives the
matrices and the operating point at one point, in the order of ``schedule.points``. Everything that would make
the points mean different things is refused here in one line: points not increasing or fewer than two, different
names or dimensions, a sigma that is neither an output nor a declared external signal, a trim outside the limits,
``rate_max <= 0``, ``rate_certified = false`` without a ``rate_max``, a ``certify_budget`` that is not a positive
number of seconds, a transfer-function plant, matrices in ``[plant]`` besides the points'.

The spec's parser reads them through ``gainlink.spec.parse.PLANTS["scheduled"]`` (:func:`scheduled_plants`) and
``OPERATING["scheduled"]`` (:func:`scheduled_operating`), which this family registers.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import SpecError
from ...spec.model import ImplementationSpec, LimitsSpec, PlantModel, ScheduleSpec
from ...spec.pairs import integer
from ...spec.plant import parse_plant
from ...spec.tables import parse_operating_point
from ...spec.values import SIGNAL_RE, as_vector, no_unknown, positive_number

SCHEDULE_KEYS = {"sigma", "external", "points", "rate_max", "rate_certified", "certify_budget", "filter_tau", "plant"}
# the fit keys: each point's fit to its FMU, written by ``linearize --schedule`` (kept as written, not used)
POINT_KEYS = {"A", "B", "C", "D", "states", "inputs", "outputs", "u_op", "y_op", "x_op"} | {
    "fit_steps", "fit_amplitude", "fit", "fit_warning",
}  # fmt: skip
SHARED_PLANT_KEYS = {"kind", "states", "inputs", "outputs"}
_NAMES = ("states", "inputs", "outputs")


def check_schedule_table(tbl: dict) -> np.ndarray:
    """The keys of ``[schedule]`` and its ``points`` (N >= 2, finite, strictly increasing)."""
    no_unknown(tbl, SCHEDULE_KEYS, "schedule")
    points = as_vector(tbl.get("points"), "schedule.points") if "points" in tbl else None
    if points is None or points.size < 2:
        raise SpecError("schedule.points must list at least two values of sigma (one point is an unscheduled spec)")
    if np.any(np.diff(points) <= 0):
        raise SpecError(f"schedule.points must be strictly increasing, got {points.tolist()}")
    entries = tbl.get("plant")
    if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
        raise SpecError("a [schedule] needs one [[schedule.plant]] table per point")
    if len(entries) != points.size:
        raise SpecError(f"schedule.points has {points.size} values but there are {len(entries)} [[schedule.plant]]")
    return points


def point_plants(shared: dict, entries: list[dict], points: np.ndarray, *, Ts: float) -> tuple[PlantModel, ...]:
    """Each point's :class:`PlantModel`: the shared ``[plant]`` (kind, names) with that point's matrices."""
    kind = shared.get("kind", "continuous")
    if kind == "transfer_function":
        raise SpecError("a [schedule] needs state-space plants (kind continuous or discrete): a transfer function's "
                        "realisation does not keep the same state coordinates from point to point")  # fmt: skip
    extra = sorted(set(shared) - SHARED_PLANT_KEYS)
    if extra:
        raise SpecError(f"with a [schedule], [plant] keeps only kind and the signal names; {extra[0]!r} goes in each "
                        "[[schedule.plant]]")  # fmt: skip
    plants = []
    for i, entry in enumerate(entries):
        where = f"schedule.plant[{i}] (sigma = {points[i]:g})"
        no_unknown(entry, POINT_KEYS, where)
        _same_names(shared, entry, where)
        table = {k: v for k, v in shared.items()} | {k: entry[k] for k in ("A", "B", "C", "D") if k in entry}
        try:
            plants.append(parse_plant(table, Ts=Ts))
        except SpecError as exc:
            raise SpecError(f"{where}: {exc}") from None
        _same_dimensions(plants[0], plants[-1], where)
    return tuple(plants)


def _same_names(shared: dict, entry: dict, where: str) -> None:
    for key in _NAMES:
        if key in entry and key in shared and list(entry[key]) != list(shared[key]):
            raise SpecError(f"{where} names its {key} {entry[key]}, [plant] names them {shared[key]}: every point "
                            "must be in the same coordinates")  # fmt: skip
        if key in entry and key not in shared:
            raise SpecError(f"{where} names its {key}: names are shared, give them once in [plant]")


def _same_dimensions(first: PlantModel, plant: PlantModel, where: str) -> None:
    for what, a, b in (("states", first.n, plant.n), ("inputs", first.m, plant.m), ("outputs", first.p, plant.p)):
        if a != b:
            raise SpecError(f"{where} has {b} {what}, the first point has {a}: every point must be in the same "
                            "coordinates")  # fmt: skip


def sigma_source(tbl: dict, plant: PlantModel) -> tuple[str, int, tuple[str, ...]]:
    """``(source, index, external)``: sigma as a measured output or one of the declared external signals."""
    external = tbl.get("external", [])
    if not isinstance(external, list) or not all(isinstance(s, str) and SIGNAL_RE.match(s) for s in external):
        raise SpecError("schedule.external must be a list of signal names (identifiers)")
    if len(set(external)) != len(external):
        raise SpecError("schedule.external repeats a name")
    clash = [s for s in external if s in plant.outputs]
    if clash:
        raise SpecError(f"schedule.external names {clash[0]!r}, which is also a plant output")
    sigma = tbl.get("sigma")
    if sigma in plant.outputs:
        return "output", plant.outputs.index(sigma), tuple(external)
    if sigma in external:
        return "external", external.index(sigma), tuple(external)
    raise SpecError(f"schedule.sigma {sigma!r} is neither a plant output ({', '.join(plant.outputs)}) nor one of "
                    f"schedule.external ({', '.join(external) or 'none declared'})")  # fmt: skip


def parse_schedule(
    tbl: dict, plants: tuple[PlantModel, ...], points: np.ndarray, *, limits: LimitsSpec, controllers: tuple
) -> ScheduleSpec:
    """The :class:`ScheduleSpec`: sigma's source, each point's operating point, ``rate_max`` (and whether it must
    be certified), ``filter_tau`` and the certificate searches' budget."""
    source, index, external = sigma_source(tbl, plants[0])
    rate_max = positive_number(tbl["rate_max"], "schedule.rate_max") if "rate_max" in tbl else None
    certified = tbl.get("rate_certified", True)
    if not isinstance(certified, bool):
        raise SpecError(f"schedule.rate_certified must be true or false, got {certified!r}")
    if not certified and rate_max is None:
        raise SpecError("schedule.rate_certified = false declares the spec's rate_max not certified: give rate_max")
    budget = positive_number(tbl["certify_budget"], "schedule.certify_budget") if "certify_budget" in tbl else None
    tau = tbl.get("filter_tau", 0.0)
    if isinstance(tau, bool) or not isinstance(tau, (int, float)) or not np.isfinite(tau) or tau < 0:
        raise SpecError(f"schedule.filter_tau must be a time constant >= 0 in seconds (0: no filter), got {tau!r}")
    ops = []
    for i, (entry, plant) in enumerate(zip(tbl["plant"], plants)):
        op_table = {k: entry[k] for k in ("u_op", "y_op", "x_op") if k in entry}
        try:
            ops.append(parse_operating_point(op_table, plant, limits))
        except SpecError as exc:
            raise SpecError(f"schedule.plant[{i}] (sigma = {points[i]:g}): {exc}") from None
    return ScheduleSpec(
        sigma=str(tbl["sigma"]),
        source=source,
        index=index,
        external=external,
        points=points,
        plants=plants,
        operating_points=tuple(ops),
        controllers=tuple(controllers),
        rate_max=rate_max,
        filter_tau=float(tau),
        rate_certified=certified,
        certify_budget=budget,
    )


def scheduled_plants(plant: dict, sched: dict, *, Ts: float) -> tuple:
    """The scheduled law's plants, one per point of its ``[schedule]``."""
    points = check_schedule_table(sched)
    return point_plants(plant, sched["plant"], points, Ts=Ts)


def scheduled_operating(parts: Any) -> tuple[Any, Any]:
    """The scheduled law's ``[schedule]`` (each point its own operating point): ``(schedule, its first point's)``."""
    q = 0 if parts.integral is None else parts.integral.q
    _check_schedulable(parts.data, q=q, m=parts.plants[0].m, implementation=parts.implementation)
    points = check_schedule_table(parts.sched)
    schedule = parse_schedule(parts.sched, parts.plants, points, limits=parts.limits, controllers=parts.controllers)
    return schedule, schedule.operating_points[0]


def _check_schedulable(data: dict, *, q: int, m: int, implementation: ImplementationSpec) -> None:
    """What the velocity form needs of the rest of a scheduled spec (docs/design.md, scheduled law)."""
    if "operating_point" in data:
        raise SpecError("with a [schedule], each [[schedule.plant]] gives its own u_op, y_op, x_op: "
                        "drop [operating_point]")  # fmt: skip
    if q < m:
        raise SpecError(f"a [schedule] needs integral action on every input ([integral] on {m} outputs, has {q}): "
                        "the velocity form integrates its command, and without it the trim drifts")  # fmt: skip
    realization = implementation.realization
    if realization != "as_designed":
        raise SpecError(f"implementation.realization {realization!r} cannot be scheduled: the points' estimates "
                        "must stay in the same coordinates (use as_designed)")  # fmt: skip
    if integer(implementation.numeric):
        raise SpecError(
            f"implementation.numeric {implementation.numeric!r} cannot be scheduled: a scheduled law is time-varying, "
            "where the fixed-point certificate (worst-case peak gain) does not apply"
        )
