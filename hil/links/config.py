"""A transport from a scenario's ``[transport]`` table: every transport module registers itself here by being
imported, so the base class never imports its subclasses."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from gainlink.errors import TransportError

from . import can as _can  # noqa: F401 - registers "can"
from . import mavlink as _mavlink  # noqa: F401 - registers "mavlink"
from .base import TRANSPORTS, Transport


def transport_from_config(config: Mapping[str, Any], *, artifact: Any) -> Transport:
    """Build the transport described by a scenario's ``[transport]`` table.

    A table with ``kind`` names a registered transport; a table without ``kind`` but with
    ``interface`` is a python-can configuration (kind ``can``).
    """
    if not isinstance(config, Mapping):
        raise TransportError("transport: expected a table")
    kind = config.get("kind", "can" if "interface" in config else None)
    if kind is None:
        raise TransportError("transport: give interface (a python-can configuration) or kind")
    return TRANSPORTS.create(str(kind), config, artifact=artifact)
