"""Replay engines that run the compiled firmware instead of the Python reference.

Each engine module exposes ``run(artifact, Y, R) -> gainlink.proof.reference.Trace``:

- ``native``: the host build of the C library through ctypes, one call per block of samples;
- ``qemu``: the Cortex-M4F image under ``qemu-system-arm``, samples through semihosting file I/O.

:mod:`gainlink.proof.replay_io` loads them by these names on first use (``--engine native|qemu``).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

ENGINE_MODULES = {"native": "gainlink.engines.native", "qemu": "gainlink.engines.qemu"}


def get(name: str) -> Callable:
    """Return the ``run`` function of engine ``name`` (``native`` or ``qemu``)."""
    from ..errors import GainlinkError

    if name not in ENGINE_MODULES:
        raise GainlinkError(f"unknown firmware engine {name!r} (choose from {', '.join(ENGINE_MODULES)})")
    return importlib.import_module(ENGINE_MODULES[name]).run
