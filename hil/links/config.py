"""A transport from a scenario's ``[transport]`` table: every transport module registers itself in
:data:`~gainlink.hil.links.base.TRANSPORTS` by being imported, so the base class never imports its subclasses.
The module of a kind is imported when a scenario names it (a CAN run does not load pymavlink's dialects)."""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from typing import Any

from gainlink.errors import TransportError

from .base import TRANSPORTS, Transport

#: The module that registers each transport kind.
MODULES = {"can": "gainlink.hil.links.can", "mavlink": "gainlink.hil.links.mavlink"}


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
    for name in [str(kind)] if str(kind) in MODULES else MODULES:  # an unknown kind: the error lists every one
        importlib.import_module(MODULES[name])
    return TRANSPORTS.create(str(kind), config, artifact=artifact)
