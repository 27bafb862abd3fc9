"""Name -> factory registries for the bridge's plugins (plants, transports).

Plugins are small classes behind an abstract base, built from a configuration mapping; a
registry maps the configuration's ``kind`` to the factory. Unknown names fail with one line
that lists what is available.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, Generic, TypeVar

from gainlink.errors import GainlinkError, did_you_mean

T = TypeVar("T")


class Registry(Generic[T]):
    """A registry of factories ``factory(config, **context) -> T`` keyed by name.

    Parameters
    ----------
    what : str
        What the registry holds, for error messages ("plant", "transport").
    error : type[GainlinkError]
        The error raised for an unknown name.
    """

    def __init__(self, *, what: str, error: type[GainlinkError]) -> None:
        self.what = what
        self.error = error
        self._factories: dict[str, Callable[..., T]] = {}

    def register(self, name: str) -> Callable[[Callable[..., T]], Callable[..., T]]:
        """Decorator registering ``factory`` under ``name`` (later registrations replace earlier ones)."""

        def deco(factory: Callable[..., T]) -> Callable[..., T]:
            self._factories[name] = factory
            return factory

        return deco

    def names(self) -> list[str]:
        """The registered names, sorted."""
        return sorted(self._factories)

    def create(self, name: str, config: Mapping[str, Any], **context: Any) -> T:
        """Build the plugin registered as ``name`` from ``config``."""
        try:
            factory = self._factories[name]
        except KeyError:
            known = self.names()
            raise self.error(
                f"unknown {self.what} kind {name!r}{did_you_mean(name, known)} (known: {', '.join(known)})"
            ) from None
        return factory(config, **context)


def take_keys(config: Mapping[str, Any], *, allowed: set[str], where: str, error: type[GainlinkError]) -> dict:
    """Return ``config`` as a dict after checking it only uses ``allowed`` keys."""
    unknown = sorted(set(config) - allowed)
    if unknown:
        raise error(
            f"{where}: unknown key(s) {', '.join(unknown)}{did_you_mean(unknown[0], allowed)} "
            f"(allowed: {', '.join(sorted(allowed))})"
        )
    return dict(config)
