"""MAVSDK's parameter server playing a vehicle gainlink did not write (the bundled libcmavsdk, offline)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import mavsdk  # the test extra (make setup) installs it
from gainlink.mavlink.params import REAL32, ParamSpec
from mavsdk.plugins.param_server import ParamServer


@contextmanager
def mavsdk_vehicle(
    url: str, params: dict[str, tuple[int, float | int]], *, system_id: int = 1
) -> Iterator[ParamServer]:
    """MAVSDK as an autopilot on ``url`` (``udpin://...`` or ``udpout://...``) serving ``params``: name -> (type,
    value), REAL32 parameters as floats and every other type as MAVSDK's integers (which it stores as int32 and
    packs bytewise)."""
    cfg = mavsdk.Configuration.create_with_component_type(mavsdk.ComponentType.AUTOPILOT)
    cfg.system_id = system_id
    sdk = mavsdk.Mavsdk(cfg)
    try:
        assert sdk.add_any_connection(url) == mavsdk.ConnectionResult.SUCCESS
        server = ParamServer(sdk.server_component())
        for name, (ptype, value) in params.items():
            if ptype == REAL32:
                server.provide_param_float(name, float(value))
            else:
                server.provide_param_int(name, int(value))
        yield server
    finally:
        sdk.destroy()
        cfg.destroy()


def as_served(specs: tuple[ParamSpec, ...], **ptypes: int) -> dict[str, tuple[int, float | int]]:
    """The parameters of a plan as a vehicle serves them, with the types of some replaced (``GL_HASH=REAL32``)."""
    return {s.name: (ptypes.get(s.name, s.ptype), s.value) for s in specs}
