"""What a closed loop (:mod:`gainlink.hil.loop`) asks of the lq law beyond its step: the design's own model of the
plant, for the model twin, and what a run's report says about the artifact."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ...proof.sampled_plant import SampledPlant


class DesignModel:
    """The artifact's discrete model (design coordinates, about its operating point: absolute inputs and outputs,
    deviation state) as a plant advancing one sample at a time."""

    def __init__(self, artifact: Any, *, x0: np.ndarray) -> None:
        Ad, Bd, Cd, Dd = artifact.design_plant()
        self.model = SampledPlant(Ad, Bd, Cd, Dd, u_op=artifact.u_op, y_op=artifact.y_op, x0=x0)

    def outputs(self) -> np.ndarray:
        """The absolute output of this sample."""
        return self.model.outputs()

    def advance(self, u: np.ndarray) -> None:
        """One sample under the absolute command ``u``."""
        self.model.advance(u)


def design_model(artifact: Any, *, state: Mapping[str, float] | None, deviation: bool) -> tuple[DesignModel, str]:
    """The model started at the plant's ``state`` (by name), as a deviation from the artifact's ``x_op`` (``state``
    already is one when ``deviation``: a linear plant's). When a model state has no counterpart in the plant (an
    identified model, a transfer function), the model starts at the operating point and the note says so."""
    a = artifact
    names = list(a.signals["states"])
    if state is None or len(names) != a.n or any(s not in state for s in names):
        return DesignModel(a, x0=np.zeros(a.n)), "the operating point (the plant's states do not map onto the model's)"
    x_op = np.zeros(a.n) if a.x_op is None or deviation else a.x_op
    x0 = np.array([float(state[s] - x_op[i]) for i, s in enumerate(names)])
    return DesignModel(a, x0=x0), "the plant's initial state"


def describe(artifact: Any) -> dict:
    """The compensator's stability and, for a model ``linearize`` wrote, the interface it was checked through and
    its fit (from the provenance)."""
    from ...synthesis.compensator import compensator_stability

    comp = compensator_stability(artifact)
    out: dict = {"compensator": {**comp.to_dict(), "summary": comp.describe()}}
    model = {k: artifact.provenance[k] for k in ("plant_interface", "plant_fit") if k in artifact.provenance}
    if model:
        out["model"] = model
    return out


def image_stream(artifact: Any, *, target: str, board: str) -> Any:
    """The float32 law's replay-only image (``main.c``) and its stream (:func:`.image.law_image_stream`): its
    records' flags are the status flags (the one table)."""
    from ..base import Step
    from ..image import law_image_stream

    def decode(rec: Any) -> Step:
        return Step(u=rec["u"].astype(float), flags=int(rec["flags"]), sat=int(rec["sat"]))

    return law_image_stream(artifact, target=target, board=board, decode=decode)


def cost(artifact: Any, *, target: str, board: str, Y: np.ndarray, R: np.ndarray, S: np.ndarray) -> Any:
    """Instructions per call of the law's step (``gl_loop_step``, callees included) replaying the samples on the
    image (:func:`gainlink.firmware.cost.count_step_instructions`, the one count for every law)."""
    from ...firmware.build import replay_image
    from ...firmware.cost import count_step_instructions

    elf = replay_image(artifact, target=target, board=board)
    return count_step_instructions(elf, artifact, Y=Y, R=R if artifact.q else None, S=S if S.shape[1] else None,
                                   board=board)  # fmt: skip
