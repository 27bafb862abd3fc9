"""Checked values from a spec's TOML: numbers, vectors, matrices, names, tables, weights and poles.

Each function turns one raw TOML value into what the design uses, or raises :class:`SpecError` naming the key.
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np

from ..errors import SpecError, did_you_mean

SIGNAL_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


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


def positive_number(value: Any, what: str) -> float:
    """A finite number > 0, or SpecError."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SpecError(f"{what} must be a number, got {value!r}")
    value = float(value)
    if not np.isfinite(value) or value <= 0:
        raise SpecError(f"{what} must be a finite number > 0, got {value}")
    return value


def no_unknown(table: dict, allowed: set[str], where: str) -> None:
    """Refuse a key that is not in ``allowed`` (a misspelt weight silently ignored designs the wrong controller)."""
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise SpecError(
            f"unknown key {unknown[0]!r}{did_you_mean(unknown[0], allowed)} in {where} "
            f"(allowed: {', '.join(sorted(allowed))})"
        )


def table(data: dict, key: str, *, required: bool) -> dict | None:
    """The sub-table ``key`` of ``data`` (None when absent and not required)."""
    value = data.get(key)
    if value is None:
        if required:
            raise SpecError(f"spec lacks the [{key}] table")
        return None
    if not isinstance(value, dict):
        raise SpecError(f"spec '{key}' must be a table")
    return value


def checked_table(data: dict, key: str, allowed: set[str], *, required: bool) -> dict | None:
    """:func:`table` with its keys checked against ``allowed``."""
    found = table(data, key, required=required)
    if found is not None:
        no_unknown(found, allowed, key)
    return found


def matrix_key(tbl: dict, key: str, where: str) -> np.ndarray:
    """The required matrix ``tbl[key]``."""
    if key not in tbl:
        raise SpecError(f"{where} lacks {key}")
    return as_matrix(tbl[key], f"{where}.{key}")


def signal_names(tbl: dict, key: str, count: int, prefix: str) -> tuple[str, ...]:
    """The names ``tbl[key]`` of ``count`` signals (default ``prefix0..``): identifiers, no repeats."""
    if key not in tbl:
        return tuple(f"{prefix}{i}" for i in range(count))
    names = tbl[key]
    if not isinstance(names, list) or not all(isinstance(s, str) and SIGNAL_RE.match(s) for s in names):
        raise SpecError(f"plant.{key} must be a list of identifiers")
    if len(names) != count:
        raise SpecError(f"plant.{key} names {len(names)} signals, expected {count}")
    if len(set(names)) != len(names):
        raise SpecError(f"plant.{key} repeats a name")
    return tuple(names)


def weight(tbl: dict, keys: tuple[str, str, str], size: int, where: str, *, required: bool) -> np.ndarray | None:
    """A weight matrix from a full matrix, a diagonal, or Bryson's maxima (1 / max^2)."""
    full, diag, bryson = keys
    given = [k for k in keys if k in tbl]
    if len(given) > 1:
        raise SpecError(f"{where}: give only one of {', '.join(given)}")
    if not given:
        if required:
            raise SpecError(f"{where} needs one of {full}, {diag} or {bryson}")
        return None
    key = given[0]
    if key == full:
        W = as_matrix(tbl[key], f"{where}.{key}")
        if W.shape != (size, size):
            raise SpecError(f"{where}.{key} is {W.shape[0]}x{W.shape[1]}, expected {size}x{size}")
        return W
    v = as_vector(tbl[key], f"{where}.{key}", size)
    if key == bryson:
        if np.any(v <= 0):
            raise SpecError(f"{where}.{key} must be > 0 (Bryson's rule uses 1/max^2)")
        return np.diag(1.0 / v**2)
    return np.diag(v)


def poles_z(tbl: dict, count: int, Ts: float, where: str) -> np.ndarray:
    """``count`` stable poles from ``poles`` (s-plane, mapped by exp(s Ts)) or ``poles_z``; complex as [re, im]."""
    if ("poles" in tbl) == ("poles_z" in tbl):
        raise SpecError(f"{where} needs exactly one of poles (s-plane) or poles_z (z-plane)")
    key = "poles" if "poles" in tbl else "poles_z"
    raw = tbl[key]
    if not isinstance(raw, list):
        raise SpecError(f"{where}.{key} must be a list of numbers or [re, im] pairs")
    vals = [_pole(item, f"{where}.{key}") for item in raw]
    if len(vals) != count:
        raise SpecError(f"{where}.{key} gives {len(vals)} poles, expected {count}")
    poles = np.array(vals)
    if not np.allclose(np.sort_complex(poles), np.sort_complex(poles.conj())):
        raise SpecError(f"{where}.{key}: complex poles must come in conjugate pairs")
    z = np.exp(poles * Ts) if key == "poles" else poles
    if np.any(np.abs(z) >= 1):
        raise SpecError(f"{where}.{key}: every pole must be stable (Re s < 0, |z| < 1)")
    return z


def _pole(item: Any, what: str) -> complex:
    if isinstance(item, list) and len(item) == 2:
        re_im = as_vector(item, f"{what} entry")
        return complex(re_im[0], re_im[1])
    if isinstance(item, (int, float)) and not isinstance(item, bool) and np.isfinite(item):
        return complex(item)
    raise SpecError(f"{what} entry {item!r} is not a number or an [re, im] pair")


def given_matrix(tbl: dict, key: str, shape: tuple[int, int], where: str) -> np.ndarray:
    """A user-given gain matrix of exactly ``shape`` (a 1-row or 1-column matrix may be given as a list)."""
    if key not in tbl:
        raise SpecError(f"{where}.method 'given' needs {key} ({shape[0]}x{shape[1]})")
    raw = tbl[key]
    if isinstance(raw, list) and raw and not any(isinstance(x, list) for x in raw) and 1 in shape:
        value = as_vector(raw, f"{where}.{key}", shape[0] * shape[1]).reshape(shape)
    else:
        value = as_matrix(raw, f"{where}.{key}")
    if value.shape != shape:
        raise SpecError(f"{where}.{key} is {value.shape[0]}x{value.shape[1]}, expected {shape[0]}x{shape[1]}")
    return value
