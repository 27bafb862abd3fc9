"""The artifact's content as the design writes it: matrices, signals, the plant as specified, the design record,
the checks, the operating point and the provenance (versions and the spec's hash)."""

from __future__ import annotations

import functools
import platform
from dataclasses import dataclass
from importlib import metadata

import numpy as np

from ..shipping.artifact import SCHEMA_VERSION, matrix_to_json, vector_to_json
from ..spec import PlantSpec
from ..version import __version__
from .discretize import Discretised


@dataclass(frozen=True)
class Gains:
    """What the design computed: ``K`` (m x n), ``Ki`` (m x q), ``L`` (n x p), ``M`` (current form, else None),
    ``Kaw`` (q x m) and the integrator selector ``Ci`` (q x p)."""

    K: np.ndarray
    Ki: np.ndarray
    L: np.ndarray
    M: np.ndarray | None
    Kaw: np.ndarray
    Ci: np.ndarray

    def loop(self, spec: PlantSpec) -> dict:
        """The keyword arguments of :func:`~gainlink.synthesis.loop.closed_loop_matrix` for these gains."""
        return {"K": self.K, "Ki": self.Ki, "L": self.L, "M": self.M, "Ci": self.Ci, "Ts": spec.Ts,
                "form": spec.observer.form}  # fmt: skip


def artifact_data(spec: PlantSpec, d: Discretised, gains: Gains, *, design_record: dict, checks: dict) -> dict:
    """The artifact's content (unsealed, before the implementation choices)."""
    plant, limits = spec.plant, spec.limits
    data = {
        "schema_version": SCHEMA_VERSION,
        "name": spec.name,
        "Ts": spec.Ts,
        "n": plant.n,
        "m": plant.m,
        "p": plant.p,
        "q": spec.q,
        "Ad": matrix_to_json(d.A),
        "Bd": matrix_to_json(d.B),
        "Cd": matrix_to_json(d.C),
        "Dd": matrix_to_json(d.D),
        "K": matrix_to_json(gains.K),
        "L": matrix_to_json(gains.L),
        "u_min": vector_to_json(limits.u_min),
        "u_max": vector_to_json(limits.u_max),
        "anti_windup": limits.anti_windup,
        "observer_form": spec.observer.form,
        "signals": _signals(spec),
        "plant": _plant_as_specified(spec),
        "design": design_record,
        "checks": checks,
        "provenance": provenance(spec),
    }
    if gains.M is not None:
        data["M"] = matrix_to_json(gains.M)
    if spec.q:
        data["Ci"], data["Ki"], data["Kaw"] = (
            matrix_to_json(gains.Ci),
            matrix_to_json(gains.Ki),
            matrix_to_json(gains.Kaw),
        )
    data.update(operating_point_keys(spec))
    return data


def _signals(spec: PlantSpec) -> dict:
    plant = spec.plant
    out = {
        "states": list(plant.states),
        "inputs": list(plant.inputs),
        "outputs": list(plant.outputs),
        "references": [f"r_{plant.outputs[int(np.argmax(row))]}" for row in spec.Ci],
    }
    if spec.units:  # written only when the spec gives them: every artifact before keeps its sha256
        out["units"] = dict(spec.units)
    return out


def _plant_as_specified(spec: PlantSpec) -> dict:
    plant = spec.plant
    out = {"kind": plant.kind} | {k: matrix_to_json(getattr(plant, k)) for k in ("A", "B", "C", "D")}
    if plant.pade_order is not None:
        out["pade_order"] = plant.pade_order
    return out


def operating_point_keys(spec: PlantSpec) -> dict:
    """The artifact keys ``u_op``, ``y_op``, ``x_op`` for the spec's operating point.

    A key is written only when it holds a non-zero entry. An absent key means zeros, so a design about
    the origin has one form whether its spec writes a zero table or none, and every spec written before
    operating points existed designs to exactly the artifact (and sha256) it designed then.
    """
    op = spec.operating_point
    if op is None:
        return {}
    keys = {"u_op": op.u_op, "y_op": op.y_op, "x_op": op.x_op}
    return {k: vector_to_json(v) for k, v in keys.items() if v is not None and np.any(v != 0.0)}


@functools.cache
def _version(dist: str) -> str:
    """The installed version of ``dist`` (read once per process: each lookup scans the installed packages'
    metadata, a fifth of a small design's time when read on every design)."""
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return "absent"


def provenance(spec: PlantSpec) -> dict:
    """Versions of everything that computed the gains, and the spec's hash."""
    given = [part for part, s in (("controller", spec.controller), ("observer", spec.observer)) if s.method == "given"]
    return {
        "gainlink": __version__,
        "numpy": _version("numpy"),
        "scipy": _version("scipy"),
        "control": _version("control"),
        "slycot": _version("slycot"),
        "python": platform.python_version(),
        "spec_sha256": spec.source_sha256,
        "gains": "given: " + ", ".join(given) if given else "designed",
        **_plant_model_provenance(spec.linearization),
    }


def _plant_model_provenance(record: dict | None) -> dict:
    """From a spec's ``[linearization]`` record (``gainlink linearize``): which interface of the FMU runs use and
    why (``plant_interface``), and the model's fit to the FMU there (``plant_fit``); nothing without one."""
    if not record:
        return {}
    out = {"plant_interface": f"{record.get('interface')}: {record.get('interface_reason')}"}
    fit = record.get("fit")
    if isinstance(fit, dict) and fit:
        parts = [
            f"{name} NRMSE {f.get('nrmse', float('nan')):.2g}, final off by {f.get('final_error', float('nan')):.2g}"
            for name, f in fit.items()
            if isinstance(f, dict)
        ]
        poor = "; POOR: " + str(record["fit_warning"]) if record.get("fit_warning") else ""
        out["plant_fit"] = f"at Ts = {record.get('Ts')} s through {record.get('interface')}: {'; '.join(parts)}{poor}"
    return out
