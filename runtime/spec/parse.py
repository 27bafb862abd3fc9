"""Plant specs: the TOML a user writes, parsed once into a validated, typed :class:`PlantSpec`.

A spec gives the plant as continuous or discrete matrices, or as a transfer-function matrix with
dead times (realised with Padé approximants), plus the design choices: controller, integral
action, observer and actuator limits. Every key is checked; an unknown key is an error, because a
misspelt weight that is silently ignored produces a controller nobody asked for.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import SpecError, did_you_mean
from ..fileio import read_toml
from ..registry import LawTable
from .model import ImplementationSpec, PlantSpec
from .pairs import structure_of
from .plant import parse_plant
from .ranges import check_ranges
from .tables import (
    CONTROLLER_KEYS,
    IMPLEMENTATION_KEYS,
    INTEGRAL_KEYS,
    LIMITS_KEYS,
    LINEARIZATION_KEYS,
    OBSERVER_KEYS,
    parse_controller,
    parse_implementation,
    parse_integral,
    parse_limits,
    parse_observer,
    parse_operating_point,
)
from .values import checked_table, no_unknown, positive_number, table

NAME_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,31}$")

TOP_KEYS = {
    "name", "Ts", "discretization", "description", "plant", "controller", "integral", "observer", "limits",
    "operating_point", "implementation", "linearization", "schedule", "units", "mpc",
}  # fmt: skip
TIME_UNIT_KEY = "time"  # in [units]: the unit of Ts and of every time (default s)
UNIT_MAX_LEN = 16


def load_spec(path: str | Path) -> PlantSpec:
    """Read a TOML spec file and validate it.

    Raises
    ------
    SpecError
        The file is not TOML, or any key, value or dimension is wrong.
    """
    data, raw = read_toml(path, what="spec", error=SpecError)
    return parse_spec(data, source=str(path), source_sha256=hashlib.sha256(raw).hexdigest())


def parse_spec(data: dict, *, source: str = "<dict>", source_sha256: str | None = None) -> PlantSpec:
    """Validate a spec given as a dict (the parsed TOML) and return a :class:`PlantSpec`."""
    if source_sha256 is None:
        source_sha256 = hashlib.sha256(json.dumps(data, sort_keys=True, default=str).encode()).hexdigest()
    no_unknown(data, TOP_KEYS, "spec")
    name = data.get("name")
    if not isinstance(name, str) or not NAME_RE.match(name):
        raise SpecError("spec 'name' must be an identifier of at most 32 characters (letters, digits, _)")
    Ts = positive_number(data.get("Ts"), "Ts")
    disc = data.get("discretization", "zoh")
    if disc not in ("zoh", "tustin"):
        raise SpecError(f"discretization must be 'zoh' or 'tustin', not {disc!r}")
    structure = structure_of(data)
    sched = table(data, "schedule", required=False)
    plants = PLANTS[structure](table(data, "plant", required=True), sched, Ts=Ts)
    plant = plants[0]
    ctl = checked_table(data, "controller", CONTROLLER_KEYS, required=True)
    integral = parse_integral(
        checked_table(data, "integral", INTEGRAL_KEYS, required=False),
        plant,
        lqr=ctl.get("method", "lqr") in ("lqr", "mpc"),
    )
    q = 0 if integral is None else integral.q
    limits_table = checked_table(data, "limits", LIMITS_KEYS, required=True)
    limits = parse_limits(limits_table, plant, q=q, structure=structure)
    controllers = tuple(parse_controller(ctl, p, q=q, Ts=Ts) for p in plants)
    implementation = parse_implementation(checked_table(data, "implementation", IMPLEMENTATION_KEYS, required=False))
    CHECKS.get(structure, _no_check)(implementation)
    parts = LawParts(data=data, sched=sched, plants=plants, integral=integral, limits=limits,
                      controllers=controllers, implementation=implementation)  # fmt: skip
    schedule, operating_point = OPERATING[structure](parts)
    return PlantSpec(
        name=name,
        Ts=Ts,
        discretization=disc,
        plant=plant,
        controller=controllers[0],
        integral=integral,
        observer=parse_observer(checked_table(data, "observer", OBSERVER_KEYS, required=True), plant, Ts=Ts),
        limits=limits,
        operating_point=operating_point,
        implementation=implementation,
        source_sha256=source_sha256,
        source=source,
        description=str(data.get("description", "")),
        linearization=checked_table(data, "linearization", LINEARIZATION_KEYS, required=False),
        schedule=schedule,
        units=parse_units(table(data, "units", required=False), plant),
        mpc=BLOCKS["mpc"](
            table(data, "mpc", required=False), method=str(ctl.get("method", "lqr")), plant=plant, op=operating_point
        ),
    )


def parse_units(units: dict | None, plant) -> dict[str, str]:
    """``[units]``: what each named signal is measured in (``x = "m"``, ``F = "N"``), and ``time`` the unit of ``Ts``
    and every time (default ``s``); for plots and summaries only, the law does not change. Names are the plant's
    states, inputs and outputs (a reference takes its tracked output's)."""
    if units is None:
        return {}
    known = {*plant.states, *plant.inputs, *plant.outputs, TIME_UNIT_KEY}
    out = {}
    for name, unit in units.items():
        if name not in known:
            raise SpecError(
                f"units names {name!r}, which is not a plant signal{did_you_mean(name, known)} "
                f"(states, inputs, outputs, or time)"
            )
        if not isinstance(unit, str) or not unit.strip() or len(unit) > UNIT_MAX_LEN or "\n" in unit:
            raise SpecError(f"units.{name} must be a unit of 1 to {UNIT_MAX_LEN} characters on one line, got {unit!r}")
        out[str(name)] = unit.strip()
    return dict(sorted(out.items()))


def lq_plants(plant: dict, sched: dict | None, *, Ts: float) -> tuple:
    """The lq law's plant (a 1-tuple)."""
    return (parse_plant(plant, Ts=Ts),)


@dataclass(frozen=True)
class LawParts:
    """What the spec's structure-specific step reads (:data:`OPERATING`)."""

    data: dict
    sched: dict | None
    plants: tuple
    integral: Any
    limits: Any
    controllers: tuple
    implementation: ImplementationSpec


def lq_operating(parts: LawParts) -> tuple[None, Any]:
    """The lq law's ``[operating_point]``, with the declared ranges checked around it: ``(None, operating point)``."""
    plant, limits, integral = parts.plants[0], parts.limits, parts.integral
    operating_point = parse_operating_point(table(parts.data, "operating_point", required=False), plant, limits)
    Ci = integral.Ci if integral else np.zeros((0, plant.p))
    check_ranges(limits, operating_point, Ci, plant, parts.implementation)
    return None, operating_point


def _no_check(implementation: ImplementationSpec) -> None:
    return None


# The tables parse_spec asks of a law, registered by the law families (gainlink.registry); .pairs says which
# structure a spec asks for.

#: A structure's plants ``(plant table, schedule table, *, Ts) -> tuple[PlantModel, ...]`` (the lq law's:
#: :func:`lq_plants`).
PLANTS: LawTable[Callable[..., tuple]] = LawTable("spec plant reader")
#: A structure's operating point(s) ``LawParts -> (schedule or None, operating point)`` (the lq law's:
#: :func:`lq_operating`).
OPERATING: LawTable[Callable[[LawParts], tuple[Any, Any]]] = LawTable("spec operating-point reader")
#: A structure's own check of ``[implementation]`` (none: nothing to check).
CHECKS: LawTable[Callable[[ImplementationSpec], None]] = LawTable("spec implementation check")
#: The reader of a law's own table of the spec, by its name, ``(table or None, *, method, plant, op) -> block or
#: None`` (``mpc``: the MPC law's horizon and boxes).
BLOCKS: LawTable[Callable[..., Any]] = LawTable("spec table reader")
