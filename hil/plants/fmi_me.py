"""An FMU's Model Exchange instance, FMI 2.0 (``FMU2Model``) or FMI 3.0 (``FMU3Model``), behind one set of calls.

The two versions differ in names and in a few signatures (``getReal`` / ``getFloat64``, ``getDerivatives`` /
``getContinuousStateDerivatives``, ``newDiscreteStates`` / ``updateDiscreteStates``, ``setupExperiment`` +
``enterInitializationMode`` / ``enterInitializationMode(startTime)``); the plant (:mod:`.fmu_me`) and the
Jacobians of linearisation (:mod:`.jacobian`) use this class and never ask which version they hold.
"""

from __future__ import annotations

import logging
import shutil
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

from gainlink.errors import PlantError

from .fmi import fmi2_callbacks, fmi3_logger, forget_log, open_binary, set_values

log = logging.getLogger(__name__)


def check_model_exchange(path: Path, md: Any) -> None:
    """One :class:`PlantError` line unless ``md`` is an FMI 2.0 or 3.0 FMU with a Model Exchange interface."""
    if md.fmiVersion not in ("2.0", "3.0"):
        raise PlantError(f"FMU {path} is FMI {md.fmiVersion}; gainlink runs FMI 2.0 and 3.0 FMUs")
    if md.modelExchange is None:
        raise PlantError(f"FMU {path} has no Model Exchange interface")


def provides_directional(path: Path, md: Any) -> bool:
    """Whether the Model Exchange interface declares directional derivatives (FMI 3.0 spells the attribute
    ``providesDirectionalDerivatives``, which fmpy 0.3 does not read: it is read here from the XML)."""
    if md.fmiVersion == "2.0":
        return bool(md.modelExchange.providesDirectionalDerivative)
    path = Path(path)
    try:
        if path.is_file():
            with zipfile.ZipFile(path) as z:
                root = ElementTree.fromstring(z.read("modelDescription.xml"))
        else:
            root = ElementTree.parse(path / "modelDescription.xml").getroot()
    except (OSError, KeyError, zipfile.BadZipFile, ElementTree.ParseError):
        return False
    me = root.find("ModelExchange")
    return me is not None and me.get("providesDirectionalDerivatives") in ("true", "1")


class ModelExchange:
    """One Model Exchange instance of the FMU at ``path``: load, instantiate, and the calls a solver makes.

    Parameters
    ----------
    path : Path
        The ``.fmu`` file (or extracted folder).
    md : fmpy ModelDescription
        Its model description (FMI 2.0 or 3.0, with Model Exchange).
    messages : list of str
        Filled with the FMU's latest warning or error (the reason of a failed call).
    key : int
        Identifies the owner in the shared FMI 2.0 log dispatcher.
    """

    def __init__(self, path: Path, md: Any, *, messages: list[str], key: int) -> None:
        check_model_exchange(path, md)
        self.md, self.v3 = md, md.fmiVersion == "3.0"
        self.messages, self.key = messages, key
        if self.v3:
            from fmpy.fmi3 import FMU3Model as cls
        else:
            from fmpy.fmi2 import FMU2Model as cls
        self.fmu, self._unzip, self._own_unzip = open_binary(path, md, cls, md.modelExchange.modelIdentifier)
        self.nx, self.nz = md.numberOfContinuousStates, md.numberOfEventIndicators
        self.instantiated = False
        fmu = self.fmu
        if self.v3:
            self.get_dx, self.get_real, self.set_real = (
                fmu.getContinuousStateDerivatives,
                fmu.getFloat64,
                fmu.setFloat64,
            )
        else:
            self.get_dx, self.get_real, self.set_real = fmu.getDerivatives, fmu.getReal, fmu.setReal
        self.get_x, self.set_x, self.get_z = fmu.getContinuousStates, fmu.setContinuousStates, fmu.getEventIndicators
        self.get_nominals, self.set_time = fmu.getNominalsOfContinuousStates, fmu.setTime
        self._logger: Any = None

    def initialise(self, values: Mapping[str, Any], *, vars_: dict, start: float = 0.0) -> None:
        """Instantiate (or reset), set ``values`` in initialisation mode and leave it; the caller then runs
        :meth:`update_discrete` and :meth:`enter_continuous`."""
        fmu = self.fmu
        if self.instantiated:
            fmu.terminate()
            fmu.reset()
        elif self.v3:
            self._logger = fmi3_logger(self.messages)
            fmu.instantiate(logMessage=self._logger)
            self.instantiated = True
        else:
            fmu.instantiate(False, fmi2_callbacks(self.key, self.messages))
            self.instantiated = True
        if self.v3:
            fmu.enterInitializationMode(startTime=start)
        else:
            fmu.setupExperiment(None, start)
            fmu.enterInitializationMode()
        if values:
            set_values(fmu, self.md, values, vars_=vars_)
        fmu.exitInitializationMode()

    def update_discrete(self) -> tuple[bool, bool, bool, float]:
        """One event iteration: (discrete states need another update, terminate, next event defined, its time)."""
        f = self.fmu.updateDiscreteStates if self.v3 else self.fmu.newDiscreteStates
        needed, terminate, _, _, defined, next_time = f()
        return bool(needed), bool(terminate), bool(defined), float(next_time)

    def enter_continuous(self) -> None:
        self.fmu.enterContinuousTimeMode()

    def enter_event(self) -> None:
        self.fmu.enterEventMode()

    def completed_step(self) -> tuple[bool, bool]:
        """``completedIntegratorStep``: (enter event mode, terminate)."""
        event, terminate = self.fmu.completedIntegratorStep()
        return bool(event), bool(terminate)

    def directional(self, unknowns: list[int], knowns: list[int], seed: list[float]) -> list[float]:
        return list(self.fmu.getDirectionalDerivative(unknowns, knowns, seed))

    def get_state(self) -> Any:
        return self.fmu.getFMUState() if self.v3 else self.fmu.getFMUstate()

    def set_state(self, state: Any) -> None:
        (self.fmu.setFMUState if self.v3 else self.fmu.setFMUstate)(state)

    def close(self) -> None:
        """Terminate and free the instance and the library, remove the unzip folder (best effort)."""
        fmu, self.fmu = self.fmu, None
        if fmu is not None:
            try:
                if self.instantiated:
                    fmu.terminate()
                    fmu.freeInstance()  # FMI 3.0: also frees the library
                if not (self.v3 and self.instantiated):
                    fmu.freeLibrary()
            except Exception:  # best effort; a broken FMU already reported its error
                log.debug("FMU close failed", exc_info=True)
        forget_log(self.key)
        if self._own_unzip and self._unzip:
            shutil.rmtree(self._unzip, ignore_errors=True)
        self._unzip = None
