"""The tables the layers below the laws read a law's parts from, filled by the law families (docs/design.md, §8).

A layer below ``gainlink.laws`` (the spec parser, the artifact loader, the C export, the parameter tables) cannot
import a law, yet has to read a scheduled artifact's points or render the MPC's C. It holds a :class:`LawTable`
keyed by what it knows without asking a law (the pair ``structure/numeric``, the structure, or the name of a block
of the artifact or a table of the spec), and each family's package registers its entries there when it is imported.
``gainlink/__init__.py`` imports ``gainlink.laws``, which imports every family, so any import of a gainlink module
has filled every table before the module's first use. A lookup of a key no family registered is one line naming it.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import TypeVar

from .errors import LawError

V = TypeVar("V")


class LawTable(Mapping[str, V]):
    """A low layer's table of a law's parts, keyed by pair, structure or block name, filled by :meth:`register`.

    Parameters
    ----------
    what : str
        What an entry is, for the one line a missing key raises ("C rendering", "artifact block reader").
    """

    def __init__(self, what: str) -> None:
        self.what = what
        self._entries: dict[str, V] = {}

    def register(self, key: str, entry: V) -> V:
        """Register ``entry`` under ``key`` and return it; a second, different entry for the same key is an error
        (two families cannot both own one key)."""
        held = self._entries.get(key)
        if held is not None and held is not entry:
            raise ValueError(f"{self.what} for {key!r} is registered twice")
        self._entries[key] = entry
        return entry

    def __getitem__(self, key: str) -> V:
        try:
            return self._entries[key]
        except KeyError:
            known = ", ".join(sorted(self._entries)) or "none"
            raise LawError(
                f"no {self.what} is registered for {key!r} (registered: {known}); a law family registers its own "
                "when gainlink.laws is imported"
            ) from None

    def get(self, key: str, default: V | None = None) -> V | None:  # type: ignore[override]
        """The entry under ``key``, ``default`` when none is registered."""
        return self._entries.get(key, default)

    def __contains__(self, key: object) -> bool:
        return key in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def __repr__(self) -> str:
        return f"LawTable({self.what!r}, {sorted(self._entries)})"
