"""A small TOML writer for what gainlink writes (specs from ``linearize``, scenarios): tables,
strings, booleans, finite numbers and (nested) lists of them. Floats are written round-trip."""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from typing import Any

_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(k: str) -> str:
    return k if _BARE.match(k) else json.dumps(k)


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError("TOML output cannot hold a non-finite number")
        return repr(float(v)) if v != 0 else "0.0"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, Mapping):
        return "{" + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + "}"
    if hasattr(v, "tolist"):
        return _value(v.tolist())
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def dumps(data: Mapping[str, Any], *, header: str = "") -> str:
    """TOML text of ``data``: scalars first, then sub-tables, then arrays of tables (``list`` of dicts)."""
    lines = [f"# {h}" if h else "#" for h in header.splitlines()] if header else []

    def emit(table: Mapping[str, Any], prefix: str) -> None:
        scalars = {k: v for k, v in table.items() if not isinstance(v, Mapping) and not _is_aot(v)}
        for k, v in scalars.items():
            lines.append(f"{_key(k)} = {_value(v)}")
        for k, v in table.items():
            name = f"{prefix}{_key(k)}"
            if isinstance(v, Mapping):
                lines.append("")
                lines.append(f"[{name}]")
                emit(v, f"{name}.")
            elif _is_aot(v):
                for item in v:
                    lines.append("")
                    lines.append(f"[[{name}]]")
                    emit(item, f"{name}.")

    emit(data, "")
    return "\n".join(lines).lstrip("\n") + "\n"


def _is_aot(v: Any) -> bool:
    return isinstance(v, (list, tuple)) and len(v) > 0 and all(isinstance(x, Mapping) for x in v)
