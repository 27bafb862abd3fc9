"""QGroundControl's ``.params`` files: a vehicle's parameters, or the ones an artifact would give it, written and read
as QGroundControl (and Mission Planner, MAVProxy) save and load them.

The format (QGroundControl's ``ParameterManager``): comment lines starting with ``#``, a header saying which vehicle,
stack and version, then one tab-separated line per parameter, ``vehicle-id component-id name value type``, the type a
``MAV_PARAM_TYPE`` number (9 REAL32, 6 INT32, ...)::

    # Onboard parameters for Vehicle 1
    #
    # Stack: gainlink firmware (law float32)
    # Vehicle: pendulum sha256:929bc854778e
    # Version: gainlink 0.x
    # Git Revision:
    #
    # Vehicle-Id Component-Id Name Value Type
    1	1	GL_DIM_N	4	6
    1	1	GL_K_0_0	-5.80262041	9

A REAL32 value is written as the shortest decimal that reads back as the same float32 (QGroundControl writes 18
decimals, which loses the digits of a gain below 1e-9); any decimal form reads. The stack line of a file gainlink
wrote names the law the gainlink firmware runs (its HEARTBEAT's ``custom_mode``), so that a diff against the file
checks it as an upload checks the vehicle; another tool's file says nothing of it, and that check is left out.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ParameterError
from ..fileio import read_user_file
from ..shipping.artifact import Artifact
from ..shipping.law_c import IDS, LABELS, law_label
from .params import (
    PARAM_ID_LEN,
    PARAM_TYPES,
    REAL32,
    Encoding,
    Mapping,
    ParamSpec,
    firmware_params,
    mapped_params,
)
from .session import ParamValue

HEADER = "# Vehicle-Id Component-Id Name Value Type"
_STACK = re.compile(r"^# Stack: gainlink firmware \(law (?P<law>[\w-]+)\)\s*$")
_INT_TYPES = {t for name, t in PARAM_TYPES.items() if name.startswith(("UINT", "INT"))}
#: What the HEARTBEAT's custom_mode says the gainlink firmware runs, by the law's label (GL_LAW_ID of gl_law.h).
LAW_IDS = {LABELS[law]: IDS[law] for law in IDS}


@dataclass(frozen=True)
class ParamsEntry:
    """One parameter line: which vehicle and component, the id, the value (decoded) and its MAV_PARAM_TYPE."""

    system: int
    component: int
    name: str
    value: float | int
    ptype: int


@dataclass(frozen=True)
class ParamsFile:
    """A ``.params`` file: its entries in file order and the law its stack line names (None: not a gainlink file)."""

    entries: tuple[ParamsEntry, ...]
    law: str | None = None

    def values(self) -> dict[str, ParamValue]:
        """The entries by name, as a vehicle would report them (index in file order)."""
        n = len(self.entries)
        return {
            e.name: ParamValue(name=e.name, ptype=e.ptype, value=e.value, index=k, count=n)
            for k, e in enumerate(self.entries)
        }

    @property
    def target(self) -> tuple[int, int]:
        """(vehicle id, component id) of the first entry ((1, 1) for an empty file)."""
        return (self.entries[0].system, self.entries[0].component) if self.entries else (1, 1)


def format_value(value: float | int, ptype: int) -> str:
    """A value as the file holds it: an integer type in decimal, REAL32 the shortest decimal of its float32."""
    if ptype == REAL32:
        return np.format_float_positional(np.float32(value), unique=True, trim="0")
    return str(int(value))


def render_params_file(
    entries: Iterable[ParamsEntry], *, law: str | None = None, vehicle: str = "", version: str = ""
) -> str:
    """The text of a ``.params`` file: QGroundControl's header, then one tab-separated line per entry."""
    rows = list(entries)
    system = rows[0].system if rows else 1
    stack = f"gainlink firmware (law {law})" if law else ""
    lines = [f"# Onboard parameters for Vehicle {system}", "#", f"# Stack: {stack}", f"# Vehicle: {vehicle}",
             f"# Version: {version}", "# Git Revision: ", "#", HEADER]  # fmt: skip
    lines += [
        "\t".join((str(e.system), str(e.component), e.name, format_value(e.value, e.ptype), str(e.ptype))) for e in rows
    ]
    return "\n".join(lines) + "\n"


def read_params_file(path: str | Path) -> ParamsFile:
    """Read a ``.params`` file (QGroundControl's, Mission Planner's or gainlink's).

    Raises
    ------
    ParameterError
        One line naming the file, the line and what is wrong with it: not five fields, a vehicle or component id
        that is not a number, an id longer than 16 characters, a type that is no MAV_PARAM_TYPE, a value that is
        not a number of its type, a name given twice.
    """
    path = Path(path)
    text = read_user_file(path, what="params file", error=ParameterError)
    entries: list[ParamsEntry] = []
    seen: dict[str, int] = {}
    law = None
    for k, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if line.startswith("#"):
            m = _STACK.match(line)
            law = m.group("law") if m and m.group("law") in LAW_IDS else law
            continue
        if not line:
            continue
        entry = _entry(line, where=f"params file {path} line {k}")
        if entry.name in seen:
            raise ParameterError(f"params file {path} line {k}: {entry.name} again (first on line {seen[entry.name]})")
        seen[entry.name] = k
        entries.append(entry)
    return ParamsFile(entries=tuple(entries), law=law)


def _entry(line: str, *, where: str) -> ParamsEntry:
    fields = line.split("\t") if "\t" in line else line.split()
    if len(fields) != 5:
        raise ParameterError(f"{where}: expected 5 fields (vehicle-id component-id name value type), got {len(fields)}")
    sys_id, comp_id, name, value, ptype = (f.strip() for f in fields)
    try:
        system, component, type_id = int(sys_id), int(comp_id), int(ptype)
    except ValueError:
        raise ParameterError(f"{where}: vehicle id, component id and type must be whole numbers") from None
    if not name or len(name) > PARAM_ID_LEN:
        raise ParameterError(f"{where}: parameter id {name!r} is not 1 to {PARAM_ID_LEN} characters")
    if type_id not in PARAM_TYPES.values():
        raise ParameterError(f"{where}: {name}: type {type_id} is not a MAV_PARAM_TYPE")
    try:
        number = float(value)
    except ValueError:
        raise ParameterError(f"{where}: {name}: value {value!r} is not a number") from None
    if type_id in _INT_TYPES:
        if not number.is_integer():
            raise ParameterError(f"{where}: {name}: value {value!r} is not a whole number (type {type_id})")
        return ParamsEntry(system=system, component=component, name=name, value=int(number), ptype=type_id)
    return ParamsEntry(system=system, component=component, name=name, value=float(np.float32(number)), ptype=type_id)


def artifact_parameters(artifact: Artifact, mapping: Mapping | None = None) -> tuple[ParamSpec, ...]:
    """Every parameter the gainlink firmware built from ``artifact`` holds, in its order (structure, ``GL_HASH``,
    gains), or with ``mapping`` the vehicle parameters the mapping names."""
    if mapping is not None:
        return mapped_params(artifact, mapping)
    return firmware_params(artifact)  # the table of the law it runs (gainlink.shipping.params.table)


def artifact_law(artifact: Artifact) -> str:
    """The law the gainlink firmware built from ``artifact`` runs (its HEARTBEAT's custom_mode names it)."""
    return law_label(artifact)


class ValuesSession:
    """A parameter session answered from values known without a link (a vehicle's saved ``.params`` file), for the
    dry run of an upload (:func:`.upload.dry_run_against`): ``read`` gives what the values hold, and names the rest
    missing; ``custom_mode`` is the law the file's stack line names (or the artifact's own, when it names none)."""

    def __init__(self, values: dict[str, ParamValue], *, custom_mode: int) -> None:
        self.values = values
        self.custom_mode = custom_mode
        self.encoding = Encoding.C_CAST  # the values are decoded already
        self.resent = 0

    def read(self, names: list[str]) -> tuple[dict[str, ParamValue], dict[str, str]]:
        """The values of ``names`` held, and the others as missing (``"not in the file"``)."""
        got = {n: self.values[n] for n in names if n in self.values}
        return got, {n: "not in the file" for n in names if n not in self.values}


def session_for(params: ParamsFile, artifact: Artifact) -> ValuesSession:
    """The :class:`ValuesSession` of a ``.params`` file, for a diff of ``artifact`` against it."""
    law = params.law or artifact_law(artifact)
    return ValuesSession(params.values(), custom_mode=LAW_IDS[law])
