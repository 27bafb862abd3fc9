"""Which law a spec asks for, read in one place below the laws (the spec's side of
:func:`gainlink.shipping.law_c.law_pair`), and what each structure and numeric format declares of a spec's tables.

A ``[schedule]`` table asks for the ``scheduled`` structure, else ``lq`` (:func:`structure_of`); ``[implementation]
numeric`` names the format, the integer ones certified by the fixed-point certificate (:data:`INTEGER_NUMERICS`).
The spec's parser asks these tables instead of testing what it holds: each structure's anti-windup modes and
default (:data:`ANTI_WINDUP`), and the table that asks for it (:data:`STRUCTURE_TABLES`). ``gainlink.laws
.law_for_spec`` reads the parsed spec the same way.
"""

from __future__ import annotations

from typing import Any

#: The table whose presence asks for a structure other than ``lq``.
STRUCTURE_TABLES: dict[str, str] = {"scheduled": "schedule"}

#: Each structure's anti-windup modes (``[limits] anti_windup``); the first is its default (``lq``: ``backcalc`` with
#: integral action, else ``none``, which is the only one without).
ANTI_WINDUP: dict[str, tuple[str, ...]] = {"lq": ("backcalc", "clamp", "none"), "scheduled": ("velocity",)}

#: The numeric formats on integers (the fixed-point certificate's).
INTEGER_NUMERICS: tuple[str, ...] = ("q31", "q15")


def structure_of(data: dict[str, Any]) -> str:
    """The structure the spec ``data`` (its TOML tables) asks for."""
    return next((s for s, key in STRUCTURE_TABLES.items() if data.get(key) is not None), "lq")


def integer(numeric: str) -> bool:
    """Whether ``numeric`` is a format on integers (a fixed-point law)."""
    return numeric in INTEGER_NUMERICS


def anti_windup_owner(mode: str) -> str | None:
    """The structure whose anti-windup mode ``mode`` is (None: no structure's)."""
    return next((s for s, modes in ANTI_WINDUP.items() if mode in modes), None)
