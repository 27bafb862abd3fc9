"""PIL of a fixed-point law: its integer image's oracle (docs/design.md, fixed point: PIL), the law's block of a PIL
run (:meth:`gainlink.laws.fixed.law.FixedLaw.pil_check`).

Two checks of the run the image (``firmware/ports/cortex-m/main.c`` on the integer law) made in closed loop:

- **bit for bit**: the bit-exact model (:class:`~gainlink.laws.fixed.model.FixedPointLoop`) fed the very float32
  samples and references the image received, from the initial state, must write the image's records step for
  step: command words, unsaturated commands, estimate, integrators, saturation, clip and overflow masks, fault
  flag and the float command;
- **within the certified bound**: beside the run, the float64 law with the artifact's quantised coefficients
  (:class:`~gainlink.proof.derived_law.DerivedLoop` on ``FixedGains.ideal``, the law the certificate's rounding
  bound compares with) closes the loop on a further instance of the plant. While no input saturates (in either
  loop) and no sample is clipped, ``|u - u_q|`` is what ``checks.fixed_point.error.closed_loop`` bounds, around the
  design model. PIL carries samples and commands as float32, roundings the certificate's budget does not hold (it is
  about the law between the floats the C receives and returns), so the oracle is the same bound with them added
  (:func:`gainlink.laws.fixed.link.bound_float32_link`); both are reported.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ...proof.derived_law import DerivedLoop
from ...shipping.artifact import Artifact
from ..image import first_difference
from . import firmware as fwfixed
from .model import FixedPointLoop
from .qformat import real


class QuantisedTwin:
    """The float64 law with the artifact's quantised coefficients (and sample clip) closing the loop on its own
    plant, a sample at a time beside the run (the interface of :class:`gainlink.proof.twin.TwinLoop`)."""

    def __init__(self, artifact: Artifact, *, plant, steps: int) -> None:
        self.law = DerivedLoop(FixedPointLoop(artifact).g.ideal)
        self.plant = plant
        a = artifact
        self.U = np.zeros((steps, a.m))
        self.saturated = np.zeros(steps, dtype=bool)
        self.clipped = np.zeros(steps, dtype=bool)

    def step(self, k: int, *, noise: np.ndarray, r: np.ndarray, d: np.ndarray) -> None:
        """Sample ``k``: sample the plant (plus ``noise``), run the law, apply ``u + d``."""
        law = self.law.law
        y = np.asarray(self.plant.outputs(), dtype=float) + noise
        res = self.law.step(y, r)
        clipped = np.any((y < law.y_min) | (y > law.y_max))
        if law.q:
            clipped |= np.any((r < law.r_min) | (r > law.r_max))
        self.U[k], self.saturated[k], self.clipped[k] = res.u, bool(res.saturated.any()), bool(clipped)
        self.plant.advance(u=res.u + d)


@dataclass(frozen=True)
class FixedPilCheck:
    """What a PIL run of a fixed-point image showed (module docstring); deviations and bounds per input, in its
    units.

    - ``bit_exact``: every record equal to the model's on the samples the image received (``first_difference``:
      the first step that is not, and its field).
    - ``unsaturated_steps``: the steps before the first saturation (image or quantised twin), clipped sample or
      reference, fault or second-line saturation; the deviations below are over those steps.
    - ``measured_du_rounding``: max ``|u - u_q|``, ``u`` the float32 command the plant got, ``u_q`` the quantised
      twin's; beside ``certified_du_rounding`` (``checks.fixed_point.error.closed_loop``) and
      ``bound_du_float32_link`` (that bound with the link's float32 roundings: the oracle).
    - ``measured_du_design``: max ``|u - u64|`` against the design's float64 twin (the run's ``twin``), beside
      ``certified_du_design`` (``error.certified``, the headline: any history in the declared ranges, initial
      states and disturbances included, without the float32 link's sample roundings); both also as fractions of
      each input's limit span.
    - ``certificate_applies``: the plant is the design model, the loop the bounds are about.
    """

    numeric: str
    steps: int
    bit_exact: bool
    first_difference: dict | None
    unsaturated_steps: int
    measured_du_rounding: list[float] | None
    certified_du_rounding: list[float]
    bound_du_float32_link: list[float]
    measured_du_design: list[float] | None
    certified_du_design: list[float]
    measured_du_design_fraction_of_span: list[float] | None
    certified_du_design_fraction_of_span: list[float]
    clipped_steps: int
    overflow_steps: int
    certificate_applies: bool

    @property
    def within_bound(self) -> bool | None:
        """The measured rounding deviation within ``bound_du_float32_link`` on every input (None when no
        quantised twin ran or the plant is not the design model)."""
        if self.measured_du_rounding is None or not self.certificate_applies:
            return None
        return bool(np.all(np.array(self.measured_du_rounding) <= np.array(self.bound_du_float32_link)))

    @property
    def within_certified(self) -> bool | None:
        """The measured rounding deviation within the certificate's own ``certified_du_rounding``."""
        if self.measured_du_rounding is None or not self.certificate_applies:
            return None
        return bool(np.all(np.array(self.measured_du_rounding) <= np.array(self.certified_du_rounding)))

    def to_dict(self) -> dict:
        """JSON form (the ``fixed_point`` block of the PIL summary)."""
        return asdict(self) | {"within_bound": self.within_bound, "within_certified": self.within_certified}


def model_records(a: Artifact, Y: np.ndarray, R: np.ndarray) -> np.ndarray:
    """The records the C writes (:func:`gainlink.laws.fixed.firmware.record_dtype`), from the bit-exact model fed
    float32 samples ``Y`` (N, p) and references ``R`` (N, q) from the initial state."""
    loop = FixedPointLoop(a)
    out = np.zeros(Y.shape[0], dtype=fwfixed.record_dtype(a))
    fu = loop.f["u"]
    for k in range(Y.shape[0]):
        s = loop.step_samples(Y[k].astype(np.float64), R[k].astype(np.float64))
        rec = out[k]
        bits = [int(b) for b in (*s.clipped_y, *s.clipped_r)]
        overflow = sum(bit for name, bit in fwfixed.OVERFLOW_BITS.items() if name in s.overflow)
        rec["sat"] = sum(int(b) << i for i, b in enumerate(s.saturated))
        rec["status"] = -2 if s.fault else (1 if rec["sat"] else 0)  # GL_ERR_NANINF, GL_SATURATED, GL_OK
        rec["clip"] = sum(b << i for i, b in enumerate(bits))
        rec["overflow"] = overflow
        flags = (fwfixed.FAULT if s.fault else 0) | (fwfixed.CLIPPED if any(bits) else 0)
        rec["flags"] = flags | (fwfixed.OVERFLOW if overflow else 0)
        rec["U"], rec["V"], rec["XH"] = s.U, s.V, loop.XH
        rec["Z"][: a.q] = loop.Z
        rec["u"] = real(s.U, fu).astype(np.float32)
    return out


def fixed_pil_check(
    a: Artifact,
    records: np.ndarray,
    *,
    Y: np.ndarray,
    R: np.ndarray,
    quantised: QuantisedTwin | None,
    design_u: np.ndarray | None,
    model_plant: bool,
) -> FixedPilCheck:
    """Check a PIL run of the fixed-point image (module docstring).

    Parameters
    ----------
    a : Artifact
        The fixed-point artifact.
    records : ndarray
        The image's output records, one per step (:func:`gainlink.laws.fixed.firmware.record_dtype`).
    Y, R : ndarray
        The samples (N, p) and references (N, q) sent to the image (cast to float32 on the way).
    quantised : QuantisedTwin, optional
        The quantised twin that ran beside, if any.
    design_u : ndarray, optional
        The design's float64 twin's commands (N, m), if it ran.
    model_plant : bool
        Whether the plant is the design model (the certificate's premise).
    """
    from gainlink.laws.fixed.link import bound_float32_link  # SciPy: not imported by a float32 run

    fp = a.checks["fixed_point"]
    err = fp["error"]
    model = model_records(a, Y.astype(np.float32), R.astype(np.float32))
    diff = first_difference(records, model)
    window = _unsaturated_steps(records, quantised)
    u = records["u"].astype(np.float64)[:window]
    span = a.u_max - a.u_min
    measured = None if quantised is None else np.abs(u - quantised.U[:window]).max(axis=0, initial=0.0)
    design = None if design_u is None else np.abs(u - design_u[:window]).max(axis=0, initial=0.0)
    return FixedPilCheck(
        numeric=fp["numeric"],
        steps=len(records),
        bit_exact=diff is None,
        first_difference=diff,
        unsaturated_steps=window,
        measured_du_rounding=_floats(measured),
        certified_du_rounding=_floats(err["closed_loop"]),
        bound_du_float32_link=_floats(bound_float32_link(a)),
        measured_du_design=_floats(design),
        certified_du_design=_floats(err["certified"]),
        measured_du_design_fraction_of_span=None if design is None else _floats(design / span),
        certified_du_design_fraction_of_span=_floats(err["fraction_of_span"]),
        clipped_steps=int(np.count_nonzero(records["clip"])),
        overflow_steps=int(np.count_nonzero(records["overflow"])),
        certificate_applies=model_plant,
    )


def _unsaturated_steps(records: np.ndarray, quantised: QuantisedTwin | None) -> int:
    """Steps before the first saturation (image or quantised twin), clipped sample or reference, fault or
    second-line saturation."""
    events = (records["sat"] != 0) | (records["clip"] != 0) | (records["flags"] & fwfixed.FAULT != 0)
    events |= records["overflow"] != 0
    if quantised is not None:
        events |= quantised.saturated | quantised.clipped
    return int(np.argmax(events)) if events.any() else len(records)


def _floats(x) -> list[float] | None:
    return None if x is None else [float(v) for v in np.asarray(x, dtype=float).ravel()]


def image_stream(artifact: Artifact, *, target: str, board: str) -> Any:
    """The integer law's replay-only image (``main.c`` on the integer law) and its stream
    (:func:`.image.law_image_stream`): the integer law's records (:func:`gainlink.laws.fixed.firmware.record_dtype`),
    their flags the status flags (the one table), their words ``U`` the step's."""
    from ..base import Step
    from ..image import law_image_stream

    def decode(rec: Any) -> Step:
        return Step(u=rec["u"].astype(float), flags=int(rec["flags"]), sat=int(rec["sat"]),
                    word=np.array(rec["U"], dtype=np.int64))  # fmt: skip

    return law_image_stream(artifact, target=target, board=board, decode=decode)


def pil_check(a: Artifact, records: np.ndarray, *, Y: np.ndarray, R: np.ndarray, design_u: np.ndarray | None,
              design_model: bool, check_plant: Any) -> dict:  # fmt: skip
    """The ``fixed_point`` block of a PIL run: the quantised twin closes its loop on ``check_plant`` (an instance of
    the plant in the run's initial state; None: no quantised twin) over the run's references, then
    :func:`fixed_pil_check`."""
    quantised = None
    if check_plant is not None:
        steps = len(records)
        quantised = QuantisedTwin(a, plant=check_plant, steps=steps)
        for k in range(steps):
            quantised.step(k, noise=np.zeros(a.p), r=R[k], d=np.zeros(a.m))
    return {"fixed_point": fixed_pil_check(a, records, Y=Y, R=R, quantised=quantised, design_u=design_u,
                                           model_plant=design_model)}  # fmt: skip


def pil_lines(block: dict | None) -> list[str]:
    """The PIL summary's lines on the integer image (its model, its certified bounds)."""
    if not block:
        return []
    fx = block.to_dict() if hasattr(block, "to_dict") else block
    first = fx["first_difference"]
    exact = "bit for bit the integer model" if fx["bit_exact"] else f"DIFFERS from the integer model at {first}"
    lines = [f"  integer law {fx['numeric']}: {exact} on the samples it received"]
    if fx["measured_du_rounding"] is not None:
        verdict = {True: "within", False: "OUTSIDE"}.get(fx["within_certified"], "not judged against")
        applies = "" if fx["certificate_applies"] else " (about the design model; the plant is not it)"
        lines.append(
            f"    vs the quantised float64 twin over {fx['unsaturated_steps']} unsaturated steps: max |du| "
            + ", ".join(_g(v) for v in fx["measured_du_rounding"])
            + f", {verdict} the certified "
            + ", ".join(_g(v) for v in fx["certified_du_rounding"])
            + applies
        )
    if fx["clipped_steps"] or fx["overflow_steps"]:
        lines.append(f"    clipped steps {fx['clipped_steps']}, second-line saturation steps {fx['overflow_steps']}")
    return lines


def cost(artifact: Artifact, *, target: str, board: str, Y: np.ndarray, R: np.ndarray, S: np.ndarray) -> Any:
    """Instructions per call of ``gl_fixed_step`` (callees included) replaying the samples on the integer image."""
    elf, board_name = fwfixed.image(artifact, target=target, board=board, options=fwfixed.REPLAY_OPTIONS)
    return fwfixed.count_fixed_step_instructions(elf, artifact, Y, R, board=board_name)


def _g(v: Any) -> str:
    return "n/a" if v is None else f"{v:.3g}"
