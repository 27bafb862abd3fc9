"""Plant specs: the TOML a user writes (plant, controller, integral action, observer, limits, operating point,
implementation), parsed once into frozen, typed dataclasses that design and analysis take."""

from .model import (
    ControllerSpec,
    ImplementationSpec,
    IntegralSpec,
    LimitsSpec,
    MpcBox,
    MpcSpec,
    ObserverSpec,
    OperatingPoint,
    PlantModel,
    PlantSpec,
    ScheduleSpec,
    TransferFunctionSource,
)
from .parse import load_spec, parse_spec
from .values import as_matrix, as_vector

__all__ = [
    "ControllerSpec",
    "ImplementationSpec",
    "IntegralSpec",
    "LimitsSpec",
    "MpcBox",
    "MpcSpec",
    "ObserverSpec",
    "OperatingPoint",
    "PlantModel",
    "PlantSpec",
    "ScheduleSpec",
    "TransferFunctionSource",
    "as_matrix",
    "as_vector",
    "load_spec",
    "parse_spec",
]
