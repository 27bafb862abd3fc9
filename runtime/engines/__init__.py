"""Replay engines that run the compiled firmware instead of the Python reference.

Each engine module exposes ``run(artifact, Y, R) -> gainlink.proof.reference.Trace``:

- ``native``: the host build of the C library through ctypes, one call per block of samples;
- ``qemu``: the Cortex-M4F image under ``qemu-system-arm``, samples through semihosting file I/O.

:mod:`gainlink.proof.replay_io` loads them by these names on first use (``--engine native|qemu``).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

from ..errors import GainlinkError

ENGINE_MODULES = {"native": "gainlink.engines.native", "qemu": "gainlink.engines.qemu"}


def get(name: str) -> Callable:
    """Return the ``run`` function of engine ``name`` (``native`` or ``qemu``)."""

    if name not in ENGINE_MODULES:
        raise GainlinkError(f"unknown firmware engine {name!r} (choose from {', '.join(ENGINE_MODULES)})")
    return importlib.import_module(ENGINE_MODULES[name]).run


def engine_with_image(engine: str, *, target: str | None = None, board: str | None = None) -> Callable[..., Any]:
    """The engine ``engine``; ``target`` and ``board`` choose the Cortex-M image of ``qemu`` (checked here,
    before anything runs).

    Raises
    ------
    GainlinkError
        An unknown engine, target or board, a board without that core, or a target for another engine.
    """
    from ..proof.replay_io import get_engine

    fn = get_engine(engine)
    if target is None and board is None:
        return fn
    if engine != "qemu":
        raise GainlinkError(f"--target and --board choose the image of --engine qemu, not of {engine}")
    from ..firmware.targets import resolve_cortex_m

    platform = resolve_cortex_m(target, board)
    return lambda artifact, Y, R: fn(artifact, Y, R, target=platform.target.name, board=platform.board.name)
