"""HIL over CAN of a fixed-point artifact: which law the node ran, and that law checked against its oracles.

The host CAN node of a fixed-point export runs the integer law (``gl_law.h``, chosen at compile time) and names it in
its ready line (``law=q31`` or ``law=q15``; a float node names none). After the run, with every sample answered:

- **bit for bit**: the bit-exact model (:class:`~gainlink.proof.fixed_law.FixedPointLoop`) fed the float32 samples
  and references the run recorded, from the initial state, must give the float32 command, the saturation bits and
  the status bits (fault, clipped, overflow) the node sent, step for step;
- **per step, resynchronised**: before each step the float64 law with the artifact's quantised coefficients
  (:class:`~gainlink.proof.derived_law.DerivedLoop` on ``FixedGains.ideal``) is put into the integer law's state
  (the model's, which is the node's when the first check holds) and steps the same sample; ``|U 2^-f_u - u|`` is
  what ``checks.fixed_point.error.per_step_rounding`` bounds for every compensator (``per_step`` in an artifact
  from before that figure, the same one), on unsaturated, unclipped steps;
- **in closed loop**: ``|u - u_twin|`` against the run's float64 twin of the design law (the report's ``twin``)
  while nothing saturates or clips, beside ``error.certified`` (the headline: any history in the declared ranges,
  initial states and disturbances included, about the design model: ``certificate_applies`` says whether the
  plant is it).
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np
from gainlink.firmware import fixed as fwfixed
from gainlink.proof.derived_law import DerivedLoop
from gainlink.proof.fixed_format import real
from gainlink.proof.fixed_law import FixedPointLoop
from gainlink.shipping.artifact import Artifact

from ..links.base import STATUS_CLIPPED, STATUS_FAULT, STATUS_OVERFLOW
from .pil_fixed import model_records


def law_of(ready_line: str) -> str:
    """The law a CAN node's ready line names (``law=``), ``float32`` when it names none."""
    m = re.search(r"\blaw=(\w+)", ready_line)
    return m.group(1) if m else "float32"


def expected_status(records: np.ndarray) -> np.ndarray:
    """The status byte the node sends for each of the model's records."""
    flags = records["flags"].astype(np.int64)
    status = np.where(flags & fwfixed.FAULT, STATUS_FAULT, 0)
    status |= np.where(flags & fwfixed.CLIPPED, STATUS_CLIPPED, 0)
    return status | np.where(flags & fwfixed.OVERFLOW, STATUS_OVERFLOW, 0)


def _first_difference(trace: Any, records: np.ndarray, a: Artifact) -> dict | None:
    """The first step whose command bits, saturation bits or status differ from the model's (None: none)."""
    sat = np.sum(trace.sat.astype(np.int64) << np.arange(a.m), axis=1)
    checks = {
        "u": np.any(trace.u.astype(np.float32).view(np.uint32) != records["u"].view(np.uint32), axis=1),
        "sat": sat != records["sat"],
        "status": trace.status.astype(np.int64) != expected_status(records),
    }
    first = None
    for field, bad in checks.items():
        idx = np.flatnonzero(bad)
        if idx.size and (first is None or idx[0] < first["step"]):
            first = {"step": int(idx[0]), "field": field}
    return first


def per_step_deviation(a: Artifact, Y: np.ndarray, R: np.ndarray, window: int) -> np.ndarray:
    """Max over the first ``window`` steps of ``|U 2^-f_u - u64|``: the float64 law with the quantised coefficients,
    put into the integer law's state before each step, on the same float32 samples."""
    integer = FixedPointLoop(a)
    ideal = DerivedLoop(integer.g.ideal)
    worst = np.zeros(a.m)
    for k in range(window):
        ideal.xh, ideal.z = integer.xh.copy(), integer.z.copy()
        y, r = Y[k].astype(np.float64), R[k].astype(np.float64)
        u64 = ideal.step(y, r).u
        s = integer.step_samples(y, r)
        worst = np.maximum(worst, np.abs(real(s.U, integer.f["u"]) - u64))
    return worst


def fixed_can_check(a: Artifact, trace: Any, *, ready_line: str, model_plant: bool) -> dict:
    """The ``fixed_point`` block of a HIL report over CAN (module docstring)."""
    fp = a.checks["fixed_point"]
    err = fp["error"]
    out: dict[str, Any] = {"law": law_of(ready_line), "numeric": fp["numeric"], "steps": int(trace.t.size)}
    Y, R = trace.y.astype(np.float32), trace.r.astype(np.float32)
    records = model_records(a, Y, R)
    events = (records["sat"] != 0) | (records["flags"] != 0)
    window = int(np.argmax(events)) if events.any() else len(records)
    if not np.all(trace.got):
        out["bit_exact"] = None
        out["note"] = "a sample went unanswered: the node's steps are not the recorded samples one for one"
    else:
        diff = _first_difference(trace, records, a)
        out["bit_exact"], out["first_difference"] = diff is None, diff
    span = a.u_max - a.u_min
    out["unsaturated_steps"] = window
    out["measured_du_per_step"] = _floats(per_step_deviation(a, Y, R, window))
    out["certified_du_per_step"] = _floats(err.get("per_step_rounding", err["per_step"]))
    design = None
    if trace.has_twin:
        design = np.abs(trace.u[:window] - trace.twin_u[:window]).max(axis=0, initial=0.0)
    out["measured_du_design"] = _floats(design)
    out["certified_du_design"] = _floats(err["certified"])
    out["measured_du_design_fraction_of_span"] = None if design is None else _floats(design / span)
    out["certified_du_design_fraction_of_span"] = _floats(err["fraction_of_span"])
    out["certificate_case"] = fp.get("case")
    out["certificate_applies"] = model_plant
    out["clipped_steps"] = int(np.count_nonzero(records["flags"] & fwfixed.CLIPPED))
    out["overflow_steps"] = int(np.count_nonzero(records["overflow"]))
    within = np.array(out["measured_du_per_step"]) <= np.array(out["certified_du_per_step"])
    out["within_per_step"] = bool(np.all(within))
    return out


def summary_lines(fx: dict | None) -> list[str]:
    """The summary's lines on the fixed-point law (nothing for a float32 artifact)."""
    if not fx:
        return []
    exact = {
        True: "bit for bit the integer model",
        False: f"DIFFERS from the integer model at {fx.get('first_difference')}",
        None: "not compared (a sample went unanswered)",
    }[fx["bit_exact"]]
    lines = [f"  law ran: {fx['law']} (artifact {fx['numeric']}): {exact} on the recorded samples"]
    lines.append(
        f"    vs the float64 law with the quantised coefficients, per step (resynchronised, {fx['unsaturated_steps']} "
        "unsaturated steps): max |du| "
        + ", ".join(f"{m:.3g}" for m in fx["measured_du_per_step"])
        + " (certified <= "
        + ", ".join(f"{c:.3g}" for c in fx["certified_du_per_step"])
        + ")"
    )
    if fx["measured_du_design"] is not None:
        applies = "" if fx["certificate_applies"] else "; the plant is not the design model"
        lines.append(
            "    vs the float64 twin, closed loop: max |du| "
            + ", ".join(f"{m:.3g}" for m in fx["measured_du_design"])
            + " (certified in operation around the design model <= "
            + ", ".join(f"{c:.3g}" for c in fx["certified_du_design"])
            + applies
            + ")"
        )
    if fx["overflow_steps"] or fx["clipped_steps"]:
        lines.append(f"    clipped steps {fx['clipped_steps']}, second-line saturation steps {fx['overflow_steps']}")
    return lines


def _floats(x) -> list[float] | None:
    return None if x is None else [float(v) for v in np.asarray(x, dtype=float).ravel()]
