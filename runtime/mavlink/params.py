"""MAVLink parameters of a gain set: naming scheme, value encoding, gain-set hash, mapping files.

Naming scheme of the gainlink firmware (``firmware/apps/mavlink``; both read the field table
:mod:`gainlink.shipping.gains_layout`), in index order:

=============================================  ======  ==============================================
id                                             type    meaning
=============================================  ======  ==============================================
``GL_DIM_N GL_DIM_M GL_DIM_P GL_DIM_Q``        INT32   compiled dimensions n, m, p, q (read-only)
``GL_FORM GL_AW``                              INT32   observer form, anti-windup mode (read-only)
``GL_HASH``                                    INT32   CRC-32 of the gain set the loop runs on
                                                       (``gl_gains_crc32``); setting it commits
``GL_TS``                                      REAL32  sample time Ts
``GL_AD_i_j GL_BD_i_j GL_CD_i_j GL_DD_i_j``    REAL32  plant model, row ``i``, column ``j``
``GL_K_i_j GL_L_i_j``                          REAL32  feedback and observer gains
``GL_M_i_j``                                   REAL32  current-estimator gain (current form only)
``GL_CI_i_j GL_KI_i_j GL_KAW_i_j``             REAL32  integral action (q > 0 only)
``GL_UMIN_i GL_UMAX_i GL_XH0_i GL_Z0_i``       REAL32  limits, initial estimate and integrator
``GL_UOP_i GL_YOP_i``                          REAL32  operating point: command and measurement there
=============================================  ======  ==============================================

Every number of the C ``gl_gains_t`` is a parameter, so ``GL_HASH`` is fully determined by the
parameters: it is :func:`gainlink.shipping.codegen.gain_set`'s ``crc32`` for the artifact they came from.
``PARAM_SET`` of a REAL32 parameter only *stages* the value (it reads back as staged; non-finite
values are refused). Setting ``GL_HASH`` to the CRC-32 of the staged set commits it: the firmware
runs the library's whole check (dimensions, CRC, finiteness, ``u_min <= u_max``, ``Ts > 0``,
derivable coefficients) and swaps the set in between two steps; otherwise the commit is refused
(the echo carries the hash of the set still running) and the loop keeps its set.

Integer values travel in ``PARAM_VALUE.param_value`` either *bytewise* (the integer's bytes in
the float's four bytes; what the gainlink firmware and PX4 advertise with
``MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE``) or *C-cast* (``(float)value``, ArduPilot).

A mapping file (TOML) maps artifact gains to an autopilot's own parameters (each set is live on
such vehicles; there is no commit)::

    [[param]]
    gain = "K[0,1]"          # artifact matrix element (Ad Bd Cd Dd K L M Ci Ki Kaw), u_min[i], u_max[i],
                             # u_op[i], y_op[i] (e.g. a hover thrust) or Ts
    name = "MC_ROLLRATE_P"   # the vehicle's parameter id (at most 16 characters)
    type = "REAL32"          # REAL32 INT32 UINT32 INT16 UINT16 INT8 UINT8
    scale = -1.0             # optional: value sent = scale * gain (integers are rounded)
"""

from __future__ import annotations

import enum
import math
import re
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ParameterError
from ..fileio import read_toml
from ..shipping import gains_layout as layout
from ..shipping import params as law_params
from ..shipping.artifact import Artifact
from ..shipping.codegen import gain_set
from ..shipping.params import as_int32

#: MAV_PARAM_TYPE values (MAVLink common.xml).
PARAM_TYPES: dict[str, int] = {
    "UINT8": 1,
    "INT8": 2,
    "UINT16": 3,
    "INT16": 4,
    "UINT32": 5,
    "INT32": 6,
    "REAL32": 9,
}
_TYPE_NAMES = {v: k for k, v in PARAM_TYPES.items()}
_INT_FORMATS = {1: "<B", 2: "<b", 3: "<H", 4: "<h", 5: "<I", 6: "<i"}
_INT_RANGES = {
    1: (0, 255),
    2: (-128, 127),
    3: (0, 65535),
    4: (-32768, 32767),
    5: (0, 2**32 - 1),
    6: (-(2**31), 2**31 - 1),
}
REAL32 = PARAM_TYPES["REAL32"]
INT32 = PARAM_TYPES["INT32"]

#: Maximum length of a MAVLink parameter id.
PARAM_ID_LEN = 16

#: Matrices a mapping file may name; the firmware's ids come from the field table
#: (:mod:`gainlink.shipping.gains_layout`).
MATRICES: tuple[str, ...] = tuple(f.name for f in layout.NUMBERS if len(f.dims) == 2)
DIMENSION_IDS: tuple[str, ...] = tuple(f.param for f in layout.STRUCTURE)
HASH_ID = law_params.HASH_ID


class Encoding(enum.Enum):
    """How integer parameter values are carried in ``param_value``."""

    BYTEWISE = "bytewise"
    C_CAST = "c_cast"


@dataclass(frozen=True)
class ParamSpec:
    """One parameter to upload.

    Attributes
    ----------
    name : str
        The vehicle's parameter id.
    ptype : int
        MAV_PARAM_TYPE of the parameter.
    value : float or int
        The value to set, already scaled and rounded to the parameter's type.
    source : str
        Where the value comes from in the artifact, e.g. ``"K[0,3]"``.
    """

    name: str
    ptype: int
    value: float | int
    source: str


def type_name(ptype: int) -> str:
    """Name of a MAV_PARAM_TYPE (``"REAL32"``...), or ``"TYPE<n>"`` when unknown."""
    return _TYPE_NAMES.get(ptype, f"TYPE{ptype}")


def check_param_id(name: str) -> None:
    """Raise :class:`ParameterError` unless ``name`` is a valid MAVLink parameter id."""
    if not name or len(name) > PARAM_ID_LEN or not name.isascii() or not name.isprintable():
        raise ParameterError(f"invalid parameter id {name!r}: 1 to {PARAM_ID_LEN} printable ASCII characters")


def encode_value(*, value: float | int, ptype: int, encoding: Encoding) -> bytes:
    """The four ``param_value`` bytes (little-endian) that carry ``value`` of type ``ptype``."""
    if ptype == REAL32:
        return struct.pack("<f", float(value))
    if ptype not in _INT_FORMATS:
        raise ParameterError(f"unsupported parameter type {ptype}")
    lo, hi = _INT_RANGES[ptype]
    iv = int(value)
    if not lo <= iv <= hi:
        raise ParameterError(f"value {iv} does not fit parameter type {type_name(ptype)}")
    if encoding is Encoding.BYTEWISE:
        return struct.pack(_INT_FORMATS[ptype], iv).ljust(4, b"\0")
    return struct.pack("<f", float(iv))


def decode_value(*, raw: bytes, ptype: int, encoding: Encoding) -> float | int:
    """Decode four ``param_value`` bytes of type ``ptype``; floats come back as float32 values."""
    raw = bytes(raw[:4]).ljust(4, b"\0")
    if ptype == REAL32 or ptype not in _INT_FORMATS:
        return struct.unpack("<f", raw)[0]
    if encoding is Encoding.BYTEWISE:
        size = struct.calcsize(_INT_FORMATS[ptype])
        return struct.unpack(_INT_FORMATS[ptype], raw[:size])[0]
    f = struct.unpack("<f", raw)[0]
    return int(f) if math.isfinite(f) else 0


def same_value(*, a: float | int, b: float | int, ptype: int) -> bool:
    """Whether two decoded values are the same parameter value (float32 bit equality for REAL32)."""
    if ptype == REAL32:
        return struct.pack("<f", float(a)) == struct.pack("<f", float(b))
    return int(a) == int(b)


def firmware_params(artifact: Artifact) -> tuple[ParamSpec, ...]:
    """Every parameter of the gainlink firmware built for ``artifact``, in index order: the table of the law it runs
    (:func:`gainlink.shipping.params.table`, the one description the firmware's table is generated from; for the
    float32 law the module docstring's).

    REAL32 values are the float32 numbers the C ``gl_gains_t`` holds; ``GL_HASH`` is its CRC-32.
    """
    out = tuple(
        ParamSpec(name=p.name, ptype=p.ptype, value=p.value, source=p.source) for p in law_params.table(artifact)
    )
    for spec in out:
        check_param_id(spec.name)
    return out


def table_hash(artifact: Artifact) -> int:
    """``GL_HASH`` (int32) of the gainlink firmware built for ``artifact``: the CRC its law's table commits with."""
    (h,) = (int(s.value) for s in firmware_params(artifact) if s.name == HASH_ID)
    return h


def gain_set_hash(artifact: Artifact) -> int:
    """``GL_HASH`` (int32) of ``artifact``'s gain set."""
    return as_int32(gain_set(artifact).crc32)


def _f32(v: float) -> float:
    return float(np.float32(v))


def _matrix_of(artifact: Artifact, attr: str) -> np.ndarray | None:
    a = getattr(artifact, attr)
    if a is None:
        return None
    a = np.asarray(a, dtype=float)
    return a if a.size else None


_GAIN_RE = re.compile(r"^\s*([A-Za-z_]+)\s*(?:\[\s*(\d+)\s*(?:,\s*(\d+)\s*)?\])?\s*$")
_MATRIX_ATTRS = {attr.lower(): attr for attr in MATRICES}


def artifact_value(artifact: Artifact, gain: str) -> float:
    """The artifact value named by ``gain``: ``"K[0,1]"``, ``"u_max[0]"``, ``"Ts"``."""
    m = _GAIN_RE.match(gain)
    if not m:
        raise ParameterError(f"mapping: cannot parse gain {gain!r} (expected e.g. 'K[0,1]', 'u_max[0]', 'Ts')")
    key, i, j = m.group(1), m.group(2), m.group(3)
    if key == "Ts" and i is None:
        return float(artifact.Ts)
    if key in ("u_min", "u_max", "u_op", "y_op") and i is not None and j is None:
        v = np.asarray(getattr(artifact, key), dtype=float)
        if int(i) >= v.size:
            raise ParameterError(f"mapping: {gain} is out of range ({key} has {v.size} entries)")
        return float(v[int(i)])
    attr = _MATRIX_ATTRS.get(key.lower())
    if attr is None or i is None or j is None:
        raise ParameterError(f"mapping: unknown gain {gain!r}")
    a = _matrix_of(artifact, attr)
    if a is None or int(i) >= a.shape[0] or int(j) >= a.shape[1]:
        shape = "absent" if a is None else f"{a.shape[0]}x{a.shape[1]}"
        raise ParameterError(f"mapping: {gain} is out of range ({attr} is {shape} in this artifact)")
    return float(a[int(i), int(j)])


@dataclass(frozen=True)
class Mapping:
    """A mapping file: which vehicle parameter each artifact gain goes to.

    Attributes
    ----------
    entries : tuple of (gain, name, ptype, scale)
        One per ``[[param]]`` table.
    """

    entries: tuple[tuple[str, str, int, float], ...]


def load_mapping(path: str | Path) -> Mapping:
    """Read and check a mapping file (TOML, see module doc).

    Raises
    ------
    ParameterError
        When the file is malformed: unknown keys, bad ids or types, duplicate names.
    """
    path = Path(path)
    doc, _ = read_toml(path, what="mapping", error=ParameterError)
    unknown = set(doc) - {"param"}
    if unknown:
        raise ParameterError(f"mapping {path}: unknown table(s) {sorted(unknown)} (only [[param]])")
    rows = doc.get("param")
    if not isinstance(rows, list) or not rows:
        raise ParameterError(f"mapping {path}: no [[param]] entries")
    entries = []
    seen: set[str] = set()
    for k, row in enumerate(rows):
        unknown = set(row) - {"gain", "name", "type", "scale"}
        if unknown:
            raise ParameterError(f"mapping {path}: param #{k + 1} has unknown key(s) {sorted(unknown)}")
        try:
            gain, name = str(row["gain"]), str(row["name"])
        except KeyError as exc:
            raise ParameterError(f"mapping {path}: param #{k + 1} lacks '{exc.args[0]}'") from None
        check_param_id(name)
        tname = str(row.get("type", "REAL32")).upper()
        if tname not in PARAM_TYPES:
            raise ParameterError(
                f"mapping {path}: param {name}: unknown type {tname!r} (one of {', '.join(PARAM_TYPES)})"
            )
        scale = row.get("scale", 1.0)
        if not isinstance(scale, (int, float)) or not math.isfinite(scale):
            raise ParameterError(f"mapping {path}: param {name}: scale must be a finite number")
        if name in seen:
            raise ParameterError(f"mapping {path}: parameter {name} is mapped twice")
        seen.add(name)
        entries.append((gain, name, PARAM_TYPES[tname], float(scale)))
    return Mapping(entries=tuple(entries))


def mapped_params(artifact: Artifact, mapping: Mapping) -> tuple[ParamSpec, ...]:
    """The parameters a mapping asks for, with values taken from ``artifact``."""
    out = []
    for gain, name, ptype, scale in mapping.entries:
        v = scale * artifact_value(artifact, gain)
        if ptype == REAL32:
            value: float | int = _f32(v)
        else:
            value = int(round(v))
            lo, hi = _INT_RANGES[ptype]
            if not lo <= value <= hi:
                raise ParameterError(f"mapping: {gain} -> {name}: value {value} does not fit {type_name(ptype)}")
        out.append(ParamSpec(name=name, ptype=ptype, value=value, source=gain))
    return tuple(out)
