"""The ``fmu`` plant kind: which interface of an FMU a run simulates, and the plant built on it.

``interface = "cs"`` or ``"me"`` forces one. ``"auto"`` (the default) takes the Model Exchange derivatives as
the model: an FMU with only one interface runs through it; with both, Co-Simulation runs only where it
reproduces Model Exchange at the run's step (:mod:`.fmu_check`), else Model Exchange.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from gainlink.errors import PlantError

from ..registry import take_keys
from .base import PLANTS, Plant
from .fmi import read_description, resolve_fmu
from .fmu import FmuPlant
from .fmu_me import FmuModelExchangePlant

PLANT_KEYS = {"kind", "fmu", "path", "inputs", "outputs", "parameters", "states", "interface", "rtol", "max_step"}


@PLANTS.register("fmu")
def _fmu_factory(config: Mapping[str, Any], *, base_dir: Path | None = None, **_context: Any) -> Plant:
    cfg = take_keys(config, allowed=PLANT_KEYS, where="plant fmu", error=PlantError)
    path = resolve_fmu(fmu=cfg.get("fmu"), path=cfg.get("path"), base_dir=base_dir)
    interface = cfg.get("interface", "auto")
    if interface not in ("auto", "cs", "me"):
        raise PlantError(f"plant fmu: interface must be auto, cs or me, not {interface!r}")
    md = read_description(path)
    if interface == "auto":
        interface = "cs" if md.coSimulation is not None else "me"
    common = dict(
        path=path,
        inputs=cfg.get("inputs"),
        outputs=cfg.get("outputs"),
        parameters=cfg.get("parameters"),
        states=cfg.get("states"),
    )
    if interface == "me":
        solver = {k: float(cfg[k]) for k in ("rtol", "max_step") if k in cfg}
        return FmuModelExchangePlant(**common, **solver)
    if "rtol" in cfg or "max_step" in cfg:
        raise PlantError('plant fmu: rtol and max_step set fmpy\'s solver, which runs only with interface = "me"')
    if md.coSimulation is None:
        raise PlantError(f'FMU {path} has no Co-Simulation interface (interface = "me" runs its Model Exchange)')
    return FmuPlant(**common)
