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

from ..errors import SpecError

#: The table whose presence asks for a structure other than ``lq``.
STRUCTURE_TABLES: dict[str, str] = {"scheduled": "schedule"}

#: The ``[controller] method`` that asks for a structure other than ``lq`` (its weights read as the lq law's).
STRUCTURE_METHODS: dict[str, str] = {"mpc": "mpc"}

#: Each structure's anti-windup modes (``[limits] anti_windup``); the first is its default (``lq``: ``backcalc`` with
#: integral action, else ``none``, which is the only one without).
ANTI_WINDUP: dict[str, tuple[str, ...]] = {
    "lq": ("backcalc", "clamp", "none"),
    "scheduled": ("velocity",),
    "mpc": ("backcalc", "clamp", "none"),  # the integrators of the MPC's model, updated as the lq law's
}

#: The numeric formats on integers (the fixed-point certificate's).
INTEGER_NUMERICS: tuple[str, ...] = ("q31", "q15")


def structure_of(data: dict[str, Any]) -> str:
    """The structure the spec ``data`` (its TOML tables) asks for: by a table (:data:`STRUCTURE_TABLES`) or by its
    controller's method (:data:`STRUCTURE_METHODS`); one line when it asks for two (not a pair in this version)."""
    ctl = data.get("controller")
    method = ctl.get("method") if isinstance(ctl, dict) else None
    by_table = [s for s, key in STRUCTURE_TABLES.items() if data.get(key) is not None]
    by_method = [s for s, m in STRUCTURE_METHODS.items() if method == m]
    if by_table and by_method:
        raise SpecError(
            f"a {by_method[0]} law cannot be {by_table[0]} in this version: drop [{STRUCTURE_TABLES[by_table[0]]}] "
            'or use method = "lqr"'
        )
    return (by_table + by_method + ["lq"])[0]


def integer(numeric: str) -> bool:
    """Whether ``numeric`` is a format on integers (a fixed-point law)."""
    return numeric in INTEGER_NUMERICS


def anti_windup_owner(mode: str) -> str | None:
    """The structure whose anti-windup mode ``mode`` is (None: no structure's)."""
    return next((s for s, modes in ANTI_WINDUP.items() if mode in modes), None)
