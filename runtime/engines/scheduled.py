"""The engines of a scheduled artifact: ``native`` (the host build of ``gl_sched.c``, :mod:`.sched_native`) and
``qemu`` (its Cortex-M image, :mod:`.sched_qemu`), each ``(artifact, Y, R, S) -> ScheduledTrace``."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ..errors import GainlinkError

SCHEDULED_ENGINES = ("native", "qemu")


def scheduled_engine(engine: str, *, target: str | None = None, board: str | None = None) -> Callable[..., Any]:
    """The C engine ``engine`` for a scheduled artifact; ``target`` and ``board`` choose the image of ``qemu``
    (checked here, before anything runs).

    Raises
    ------
    GainlinkError
        An engine that does not run the scheduled law, an unknown target or board, or a target for ``native``.
    """
    if engine not in SCHEDULED_ENGINES:
        raise GainlinkError(
            f"engine {engine!r} does not run the scheduled law (choose reference, {', '.join(SCHEDULED_ENGINES)})"
        )
    if engine == "native":
        if target is not None or board is not None:
            raise GainlinkError("--target and --board choose the image of --engine qemu, not of native")
        from .sched_native import run

        return run
    from ..firmware.targets import resolve_cortex_m
    from .sched_qemu import run as run_qemu

    platform = resolve_cortex_m(target, board)
    return lambda a, Y, R, S: run_qemu(a, Y, R, S, target=platform.target.name, board=platform.board.name)
