"""The versioned gain artifact (``gains.json``): canonical form, hash, schema and invariants.

The artifact is what every later step reads (C code, firmware, replay, HIL, MAVLink upload);
nothing downstream looks at live Python design objects. Canonical JSON is ``sort_keys`` with
round-trip floats and no timestamps; ``sha256`` covers the canonical text of every other key.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import ArtifactError, IntegrityError
from ..fileio import atomic_write_text, read_user_file
from ..registry import LawTable
from .law_c import ONE_OPERATING_POINT, require_structure, sigma_name

if TYPE_CHECKING:
    from ..laws.mpc.block import Mpc
    from ..laws.scheduled.block import Schedule

SCHEMA_VERSION = 1
#: A scheduled artifact (``schedule`` holds the points; docs/design.md, scheduled law).
SCHEDULED_SCHEMA_VERSION = 2

#: The reader of each law's own block of the artifact, by the block's key (``schedule``: the scheduled law's points,
#: ``data, *, n, m, p, q, form -> Schedule``; ``mpc``: the MPC law's horizon, cache and boxes, ``data, *, Ad, ...,
#: y_op -> Mpc``), registered by the law families (:mod:`gainlink.registry`): the loader reads the shared keys and
#: hands the block to its law's reader.
BLOCKS: LawTable[Any] = LawTable("artifact block reader")


@lru_cache(maxsize=1)
def schema() -> dict:
    """Return the artifact's JSON Schema (``gainlink/schema/gains.schema.json``)."""
    text = resources.files("gainlink.shipping").joinpath("schema/gains.schema.json").read_text("utf-8")
    return json.loads(text)


def canonical_json(obj: Any) -> str:
    """Canonical compact JSON: sorted keys, no NaN/Inf, round-trip floats."""
    try:
        return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False, ensure_ascii=True)
    except ValueError as exc:
        raise ArtifactError(f"artifact holds a non-finite number ({exc})") from None


def content_sha256(data: dict) -> str:
    """sha256 of the canonical JSON of ``data`` without its ``sha256`` key."""
    body = {k: v for k, v in data.items() if k != "sha256"}
    return hashlib.sha256(canonical_json(body).encode("ascii")).hexdigest()


def seal(data: dict) -> dict:
    """Return a copy of ``data`` with its ``sha256`` set to the hash of its content."""
    sealed = {k: v for k, v in data.items() if k != "sha256"}
    sealed["sha256"] = content_sha256(sealed)
    return sealed


def render(data: dict) -> str:
    """The text of ``gains.json``: the sealed dict, sorted keys, two-space indent, trailing newline."""
    canonical_json(data)  # rejects NaN/Inf with a clear error
    return json.dumps(data, sort_keys=True, indent=2, allow_nan=False) + "\n"


def matrix_to_json(a: np.ndarray) -> list[list[float]]:
    """A 2-D array as a list of row lists of Python floats (``-0.0`` folded to ``0.0``)."""
    a = np.atleast_2d(np.asarray(a, dtype=float))
    return [[float(v) + 0.0 for v in row] for row in a]


def vector_to_json(v: np.ndarray) -> list[float]:
    """A 1-D array as a list of Python floats."""
    return [float(x) + 0.0 for x in np.asarray(v, dtype=float).ravel()]


@dataclass(frozen=True)
class Artifact:
    """A loaded, validated gain artifact with its matrices as float64 arrays.

    When there is no integral action (``q == 0``) ``Ci``, ``Ki`` and ``Kaw`` are empty arrays of
    shapes (0, p), (m, 0) and (0, m); ``M`` is ``None`` unless ``observer_form == "current"``.
    ``u_op`` (m) and ``y_op`` (p) are the operating point, zeros when the file has none (every
    artifact written before operating points existed keeps its meaning); ``x_op`` (n) is the state
    there, for the record only, ``None`` when not recorded.

    A scheduled artifact (schema 2, ``anti_windup == "velocity"``) has its per-point design in ``schedule``
    (:class:`~gainlink.laws.scheduled.block.Schedule`) and no single ``Ad Bd Cd Dd K L M Ki Kaw xh0 z0 u_op y_op``:
    those fields are ``None``, so that nothing runs one point's positional law by mistake (each part of the lq law
    refuses another law's artifact in one line: :func:`gainlink.shipping.law_c.require_structure`).
    """

    data: dict = field(repr=False)
    name: str
    Ts: float
    n: int
    m: int
    p: int
    q: int
    Ad: np.ndarray
    Bd: np.ndarray
    Cd: np.ndarray
    Dd: np.ndarray
    K: np.ndarray
    L: np.ndarray
    M: np.ndarray | None
    Ci: np.ndarray
    Ki: np.ndarray
    Kaw: np.ndarray
    u_min: np.ndarray
    u_max: np.ndarray
    xh0: np.ndarray
    z0: np.ndarray
    u_op: np.ndarray
    y_op: np.ndarray
    x_op: np.ndarray | None
    anti_windup: str
    observer_form: str
    sha256: str
    schedule: Schedule | None = None
    mpc: Mpc | None = None

    @property
    def signals(self) -> dict:
        """Names of states, inputs, outputs and references (and ``units``, when the spec gave them)."""
        return self.data["signals"]

    def unit(self, name: str) -> str:
        """What signal ``name`` is measured in (``""``: the spec gave no unit): a state, input or output its entry of
        the spec's ``[units]``, a reference ``r_<output>`` its output's, ``"time"`` the unit of ``Ts`` (``s`` unless
        the spec says otherwise)."""
        units = self.signals.get("units", {})
        if name == "time":
            return units.get("time", "s")
        if name not in units and name.startswith("r_") and name in self.signals["references"]:
            return units.get(name[2:], "")
        return units.get(name, "")

    def label(self, name: str) -> str:
        """``name [unit]`` for a plot's axis or a summary's figure, or ``name`` alone without a unit."""
        unit = self.unit(name)
        return f"{name} [{unit}]" if unit else name

    @property
    def safe_command(self) -> np.ndarray:
        """The command on a refused sample or an expired watchdog: ``u_op`` clamped into the limits."""
        require_structure(self, ONE_OPERATING_POINT, "safe_command")
        return np.minimum(np.maximum(self.u_op, self.u_min), self.u_max)

    @property
    def r_op(self) -> np.ndarray:
        """The reference that holds the plant at its operating point: the tracked outputs there, ``Ci y_op``."""
        require_structure(self, ONE_OPERATING_POINT, "r_op")
        return self.Ci @ self.y_op

    @property
    def has_operating_point(self) -> bool:
        """True when ``u_op`` or ``y_op`` has a non-zero entry."""
        require_structure(self, ONE_OPERATING_POINT, "has_operating_point")
        return bool(np.any(self.u_op != 0.0) or np.any(self.y_op != 0.0))

    def design_plant(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The discrete plant ``(Ad, Bd, Cd, Dd)`` in the design's coordinates (those of a plant state a user
        gives, e.g. ``simulate --x0``), whatever the realisation of the estimate (``realization.design``)."""
        require_structure(self, ONE_OPERATING_POINT, "design_plant")
        rec = self.data.get("realization")
        if rec is None:
            return self.Ad, self.Bd, self.Cd, self.Dd
        d = rec["design"]
        return tuple(np.array(d[k], dtype=float) for k in ("Ad", "Bd", "Cd")) + (self.Dd,)

    @property
    def provenance(self) -> dict:
        """Versions that computed the gains, the spec's sha256, and whether the gains were given."""
        return self.data["provenance"]

    @property
    def checks(self) -> dict:
        """What design checked: closed-loop poles, spectral radius, margins (and more, per version)."""
        return self.data["checks"]

    @classmethod
    def load(cls, path: str | Path, *, check_hash: bool = True) -> Artifact:
        """Read and check ``gains.json`` (schema, sha256, dimensions, invariants); see :func:`load`."""
        return load(path, check_hash=check_hash)

    def save(self, path: str | Path) -> None:
        """Write the artifact to ``path`` atomically (canonical JSON, readable by everyone).

        The example of :func:`gainlink.load` saves and loads one.
        """
        atomic_write_text(path, render(self.data))

    def controller(self, sigma: float | None = None) -> Any:
        """The unsaturated law as a discrete ``control.StateSpace`` from ``(y, r)`` to ``u``.

        Signals are named after the artifact's outputs, references and inputs and are deviations
        from the operating point; the sign is included (``u = C(z) [y; r]``), so the loop broken at
        a plant input is ``-controller()[u, y] * plant``. See :mod:`gainlink.shipping.systems`.

        A scheduled artifact needs ``sigma``: the frozen-point law there (the coefficients interpolated at sigma,
        in the positional form whose increments the velocity form runs); an unscheduled one takes none.
        """
        from .systems import controller_system

        on = sigma_name(self)
        if (sigma is None) != (on is None):
            on_what = f" (on {on})" if on else ""
            raise ArtifactError(f"controller(sigma=...) takes sigma exactly when the artifact is scheduled{on_what}")
        return controller_system(self, sigma=sigma)

    def closed_loop(self) -> Any:
        """Design plant + unsaturated law as a discrete ``control.StateSpace``: inputs the references
        and a disturbance ``d_<input>`` added at each plant input, outputs the plant outputs and commands."""
        from .systems import closed_loop_system

        return closed_loop_system(self)


def _matrix(data: dict, key: str, shape: tuple[int, int]) -> np.ndarray:
    rows = data[key]
    widths = {len(r) for r in rows}
    if len(widths) != 1:
        raise ArtifactError(f"artifact matrix {key} has rows of different lengths")
    a = np.array(rows, dtype=float)
    if a.shape != shape:
        raise ArtifactError(f"artifact matrix {key} is {a.shape[0]}x{a.shape[1]}, expected {shape[0]}x{shape[1]}")
    if not np.all(np.isfinite(a)):
        raise ArtifactError(f"artifact matrix {key} holds a non-finite entry")
    return a


def _vector(data: dict, key: str, length: int, default: float | None = None) -> np.ndarray:
    if key not in data:
        if default is None:
            raise ArtifactError(f"artifact lacks {key}")
        return np.full(length, default)
    v = np.array(data[key], dtype=float)
    if v.shape != (length,):
        raise ArtifactError(f"artifact vector {key} has length {v.size}, expected {length}")
    if not np.all(np.isfinite(v)):
        raise ArtifactError(f"artifact vector {key} holds a non-finite entry")
    return v


def from_dict(data: dict, *, check_hash: bool = True) -> Artifact:
    """Validate ``data`` (schema, hash, dimensions, invariants) and return an :class:`Artifact`."""
    _check_schema(data)
    if check_hash:
        _check_hash(data)
    return _READERS[data["schema_version"]](data)


def _check_hash(data: dict) -> None:
    actual = content_sha256(data)
    if actual != data["sha256"]:
        raise IntegrityError(
            f"artifact sha256 mismatch: recorded {data['sha256'][:12]}..., content hashes to {actual[:12]}... "
            "(the file was edited after design)"
        )


def _positional(data: dict) -> Artifact:
    """A schema-1 artifact: one positional law (matrices checked against their dimensions and invariants)."""
    n, m, p, q = (int(data[k]) for k in "nmpq")
    Ad = _matrix(data, "Ad", (n, n))
    Bd = _matrix(data, "Bd", (n, m))
    Cd = _matrix(data, "Cd", (p, n))
    Dd = _matrix(data, "Dd", (p, m))
    K = _matrix(data, "K", (m, n))
    L = _matrix(data, "L", (n, p))
    form = data["observer_form"]
    M = _filter_gain(data, form, Ad=Ad, Dd=Dd, L=L)
    Ci, Ki, Kaw = _integral_matrices(data, m=m, p=p, q=q)
    if "realization" in data:
        _check_realization(
            data["realization"],
            n=n,
            current=form == "current",
            now={"Ad": Ad, "Bd": Bd, "Cd": Cd, "K": K, "L": L, "M": M},
        )
    u_min = _vector(data, "u_min", m)
    u_max = _vector(data, "u_max", m)
    if np.any(u_min > u_max):
        raise ArtifactError("artifact has u_min > u_max for some input")
    _check_signals(data["signals"], n=n, m=m, p=p, q=q)
    u_op, y_op = _vector(data, "u_op", m, 0.0), _vector(data, "y_op", p, 0.0)
    x_op = _vector(data, "x_op", n) if "x_op" in data else None
    mpc = None
    if "mpc" in data:  # the MPC law: its block checked against the matrices above by its reader (BLOCKS)
        mpc = BLOCKS["mpc"](data, Ad=Ad, Bd=Bd, Cd=Cd, Dd=Dd, Ci=Ci, Ts=float(data["Ts"]), u_min=u_min, u_max=u_max,
                       u_op=u_op, x_op=x_op, y_op=y_op)  # fmt: skip
    return Artifact(
        data=data,
        name=data["name"],
        Ts=float(data["Ts"]),
        n=n,
        m=m,
        p=p,
        q=q,
        Ad=Ad,
        Bd=Bd,
        Cd=Cd,
        Dd=Dd,
        K=K,
        L=L,
        M=M,
        Ci=Ci,
        Ki=Ki,
        Kaw=Kaw,
        u_min=u_min,
        u_max=u_max,
        xh0=_vector(data, "xh0", n, 0.0),
        z0=_vector(data, "z0", q, 0.0),
        u_op=u_op,
        y_op=y_op,
        x_op=x_op,
        anti_windup=data["anti_windup"],
        observer_form=form,
        sha256=data["sha256"],
        mpc=mpc,
    )


def _scheduled(data: dict) -> Artifact:
    """A schema-2 artifact: shared keys here, the points by the ``schedule`` block's reader (:data:`BLOCKS`)."""
    n, m, p, q = (int(data[k]) for k in "nmpq")
    if q != m:
        raise ArtifactError(f"a scheduled artifact needs integral action on every input (q = m), has q={q}, m={m}")
    sched = BLOCKS["schedule"](data, n=n, m=m, p=p, q=q, form=data["observer_form"])
    u_min, u_max = _vector(data, "u_min", m), _vector(data, "u_max", m)
    if np.any(u_min > u_max):
        raise ArtifactError("artifact has u_min > u_max for some input")
    _check_signals(data["signals"], n=n, m=m, p=p, q=q)
    none = dict.fromkeys(("Ad", "Bd", "Cd", "Dd", "K", "L", "M", "Ki", "Kaw", "xh0", "z0", "u_op", "y_op", "x_op"))
    return Artifact(data=data, name=data["name"], Ts=float(data["Ts"]), n=n, m=m, p=p, q=q,
                    Ci=_matrix(data, "Ci", (q, p)), u_min=u_min, u_max=u_max, anti_windup=data["anti_windup"],
                    observer_form=data["observer_form"], sha256=data["sha256"], schedule=sched, **none)  # fmt: skip


def _check_signals(sig: dict, *, n: int, m: int, p: int, q: int) -> None:
    for key, size in (("states", n), ("inputs", m), ("outputs", p), ("references", q)):
        if len(sig[key]) != size:
            raise ArtifactError(f"signals.{key} names {len(sig[key])} signals, expected {size}")
    known = {*sig["states"], *sig["inputs"], *sig["outputs"], "time"}
    stray = sorted(set(sig.get("units", {})) - known)
    if stray:
        raise ArtifactError(f"signals.units names {stray[0]!r}, which is not a signal of the artifact")


#: sha256 of the canonical JSON of artifacts that passed the schema in this process (a design validates its
#: artifact three times, a campaign worker once per run of a batch: the schema walk was ~4 % of the test suite's
#: Python time); the same JSON value passes again, so only the walk is skipped
_SCHEMA_PASSED: set[str] = set()
_SCHEMA_PASSED_MAX = 1024


@lru_cache(maxsize=1)
def _validator() -> Any:
    """The schema's validator, made once (a third of a check's time was making it)."""
    import jsonschema

    return jsonschema.Draft202012Validator(schema())


#: The reader of each schema version (each checked against its JSON schema first): one positional law (1), the
#: scheduled law's points (2).
_READERS = {SCHEMA_VERSION: _positional, SCHEDULED_SCHEMA_VERSION: _scheduled}


def _check_schema(data: Any) -> None:
    """The artifact's JSON schema; the first violation (by path) is the error."""
    if not isinstance(data, dict):
        raise ArtifactError("artifact is not a JSON object")
    key = _json_key(data)
    if key in _SCHEMA_PASSED:
        return
    errors = sorted(_validator().iter_errors(data), key=lambda e: list(e.path))
    if errors:
        err = errors[0]
        where = "/".join(str(p) for p in err.path) or "top level"
        raise ArtifactError(f"artifact does not match the schema at {where}: {err.message}")
    if key is not None:
        if len(_SCHEMA_PASSED) >= _SCHEMA_PASSED_MAX:
            _SCHEMA_PASSED.clear()
        _SCHEMA_PASSED.add(key)


def _json_key(data: dict) -> str | None:
    """sha256 of ``data``'s :func:`canonical_json` (None when it has none, e.g. a NaN: then it is always checked)."""
    try:
        return hashlib.sha256(canonical_json(data).encode("ascii")).hexdigest()
    except (TypeError, ArtifactError):
        return None


def _filter_gain(data: dict, form: str, *, Ad: np.ndarray, Dd: np.ndarray, L: np.ndarray) -> np.ndarray | None:
    """M for the current-estimator form (with its invariants Dd = 0 and L = Ad M), None for the predictor."""
    if form != "current":
        if "M" in data:
            raise ArtifactError("M is only used with observer_form 'current'")
        return None
    if "M" not in data:
        raise ArtifactError("observer_form 'current' needs the filter gain M")
    M = _matrix(data, "M", L.shape)
    if np.any(Dd != 0.0):
        raise ArtifactError("observer_form 'current' requires Dd = 0")
    if not np.allclose(L, Ad @ M, rtol=1e-9, atol=1e-12):
        raise ArtifactError("observer_form 'current' requires L = Ad M")
    return M


def _integral_matrices(data: dict, *, m: int, p: int, q: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ci, Ki, Kaw: required with integral action (q > 0), absent (and empty) without."""
    if q == 0:
        present = [k for k in ("Ci", "Ki", "Kaw") if k in data]
        if present:
            raise ArtifactError(f"{', '.join(present)} given but q = 0")
        return np.zeros((0, p)), np.zeros((m, 0)), np.zeros((0, m))
    missing = [k for k in ("Ci", "Ki", "Kaw") if k not in data]
    if missing:
        raise ArtifactError(f"integral action (q={q}) needs {', '.join(missing)}")
    return _matrix(data, "Ci", (q, p)), _matrix(data, "Ki", (m, q)), _matrix(data, "Kaw", (q, m))


def _check_realization(rec: dict, *, n: int, current: bool, now: dict) -> None:
    """The top-level matrices must be the recorded design-coordinate ones in ``xh' = T xh``."""
    T = _matrix(rec, "T", (n, n))
    if np.linalg.cond(T) > 1e12:
        raise ArtifactError("realization.T is singular")
    Ti = np.linalg.inv(T)
    d = rec["design"]
    if current != ("M" in d):
        raise ArtifactError("realization.design must hold M exactly when observer_form is 'current'")
    expect = {k: np.array(d[k], dtype=float) for k in d if k != "xh0"}
    expect = {
        "Ad": T @ expect["Ad"] @ Ti,
        "Bd": T @ expect["Bd"],
        "Cd": expect["Cd"] @ Ti,
        "K": expect["K"] @ Ti,
        "L": T @ expect["L"],
        **({"M": T @ expect["M"]} if current else {}),
    }
    for key, want in expect.items():
        got = now[key]
        if got.shape != want.shape or np.linalg.norm(got - want) > 1e-9 * max(1.0, np.linalg.norm(want)):
            raise ArtifactError(f"artifact {key} is not realization.T applied to realization.design.{key}")


def load(path: str | Path, *, check_hash: bool = True) -> Artifact:
    """Read and validate ``gains.json`` at ``path``.

    Raises
    ------
    ArtifactError
        Not JSON, schema violation, inconsistent dimensions or invariants.
    IntegrityError
        The recorded sha256 does not match the content.
    """
    path = Path(path)
    text = read_user_file(path, what="artifact", error=ArtifactError)
    try:
        data = json.loads(text, parse_constant=_reject_constant)
    except json.JSONDecodeError as exc:
        raise ArtifactError(f"artifact {path} is not valid JSON (line {exc.lineno}: {exc.msg})") from None
    return from_dict(data, check_hash=check_hash)


def _reject_constant(name: str) -> float:
    raise ArtifactError(f"artifact holds the non-finite constant {name}")


def write(path: str | Path, data: dict) -> None:
    """Seal ``data`` and write it atomically to ``path``."""
    atomic_write_text(path, render(seal(data)))
