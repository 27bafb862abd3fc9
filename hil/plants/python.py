"""Plants written by the user in Python, found as python-can finds its interface plugins.

Two ways to name one in a scenario's ``[plant]`` table:

``kind = "python", class = "my_package.plants:Heater"``
    any importable class deriving from :class:`gainlink.hil.plants.base.Plant`;
``kind = "heater"``
    a name that an installed distribution registers in the entry-point group ``gainlink.plants``
    (``[project.entry-points."gainlink.plants"] heater = "my_package.plants:Heater"``).

The other keys of the table are passed to the class as keyword arguments.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from importlib.metadata import entry_points
from typing import Any

from gainlink.errors import PlantError

from .base import PLANTS, Plant

ENTRY_POINT_GROUP = "gainlink.plants"


def installed_plugins() -> dict[str, Any]:
    """The entry points of group ``gainlink.plants``, by name."""
    return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}


def _load_class(target: str, *, where: str) -> type:
    module_name, sep, attr = target.partition(":")
    if not sep or not module_name or not attr:
        raise PlantError(f'{where}: {target!r} must be of the form "module:Class"')
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise PlantError(f"{where}: cannot import module {module_name!r} ({exc})") from None
    obj: Any = module
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise PlantError(f"{where}: module {module_name!r} has no class {attr!r}")
        obj = getattr(obj, part)
    if not (isinstance(obj, type) and issubclass(obj, Plant)):
        raise PlantError(f"{where}: {target} is not a Plant class (derive it from gainlink.hil.plants.base.Plant)")
    return obj


def build_plant(cls: type, options: Mapping[str, Any], *, where: str) -> Plant:
    """``cls(**options)``, with a constructor's complaint about its options as one :class:`PlantError` line."""
    try:
        plant = cls(**dict(options))
    except PlantError:
        raise
    except (TypeError, ValueError) as exc:
        raise PlantError(f"{where}: {cls.__name__}({', '.join(options)}) failed: {exc}") from None
    for attr in ("name", "input_names", "output_names", "state_names"):
        if not hasattr(plant, attr):
            raise PlantError(f"{where}: {cls.__name__} does not set {attr}")
    return plant


@PLANTS.register("python")
def _python_factory(config: Mapping[str, Any], **_context: Any) -> Plant:
    options = {k: v for k, v in config.items() if k not in ("kind", "class")}
    target = config.get("class")
    if not isinstance(target, str):
        raise PlantError('plant python: give class = "module:Class" (a gainlink.hil.plants.base.Plant subclass)')
    return build_plant(_load_class(target, where="plant python"), options, where="plant python")


def plugin_plant(name: str, config: Mapping[str, Any]) -> Plant | None:
    """The plant of the installed entry point ``name`` built from ``config`` (``None`` if none is installed)."""
    ep = installed_plugins().get(name)
    if ep is None:
        return None
    where = f"plant {name} (entry point {ep.value})"
    try:
        cls = ep.load()
    except (ImportError, AttributeError) as exc:
        raise PlantError(f"{where}: cannot load it ({exc})") from None
    if not (isinstance(cls, type) and issubclass(cls, Plant)):
        raise PlantError(f"{where}: it is not a Plant class (derive it from gainlink.hil.plants.base.Plant)")
    return build_plant(cls, {k: v for k, v in config.items() if k != "kind"}, where=where)
