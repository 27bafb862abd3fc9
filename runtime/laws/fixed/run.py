"""A closed-loop run of a fixed-point law, checked against its oracles: the ``fixed_point`` block of the run's report
(SIL with the host C, HIL over CAN or MAVLink, the image in QEMU).

The controller names the law it ran (``ran``: a node's ready line says ``law=q31`` or ``law=q15``; a float node
names none). After the run, with every sample answered:

- **bit for bit**: the bit-exact model (:class:`~gainlink.laws.fixed.model.FixedPointLoop`, as the law's ``model``)
  fed the float32 samples and references the controller received (NaN where a ``nan`` fault replaced the sample),
  from the initial state, must give the float32 command, the saturation bits and the status flags (fault, clipped,
  overflow) the controller returned, step for step;
- **per step, resynchronised**: before each step the float64 law with the artifact's quantised coefficients
  (:class:`~gainlink.proof.derived_law.DerivedLoop` on ``FixedGains.ideal``) is put into the integer law's state
  (the model's, which is the controller's when the first check holds) and steps the same sample; ``|U 2^-f_u - u|``
  is what ``checks.fixed_point.error.per_step_rounding`` bounds for every compensator (``per_step`` in an artifact
  from before that figure, the same one), on unsaturated, unclipped steps;
- **in closed loop**: ``|u - u_twin|`` against the run's float64 twin of the design law (the report's ``twin``)
  while nothing saturates or clips, beside ``error.certified`` (the headline: any history in the declared ranges,
  initial states and disturbances included, about the design model: ``certificate_applies`` says whether the
  plant is it).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...proof.derived_law import DerivedLoop
from .. import flags
from .model import FixedPointLoop
from .qformat import real


def _model_steps(a: Any, model: Any, Y: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The integer ``model``'s float32 commands, saturation masks and status flags on these float32 samples, from
    its initial state."""
    e = np.zeros(0)
    steps = [model.step(Y[k].astype(np.float64), R[k].astype(np.float64), e) for k in range(Y.shape[0])]
    U = np.array([s.u for s in steps], dtype=np.float32).reshape(len(steps), a.m)
    return U, np.array([s.sat for s in steps], dtype=np.int64), np.array([s.flags for s in steps], dtype=np.int64)


def _first_difference(trace: Any, model: tuple[np.ndarray, np.ndarray, np.ndarray], a: Any) -> dict | None:
    """The first step whose command bits, saturation bits or status flags differ from the model's (None: none)."""
    U, sat, bits = model
    trace_sat = np.sum(trace.sat.astype(np.int64) << np.arange(a.m), axis=1)
    checks = {
        "u": np.any(trace.u.astype(np.float32).view(np.uint32) != U.view(np.uint32), axis=1),
        "sat": trace_sat != sat,
        "status": np.asarray(trace.flags, dtype=np.int64) != bits,
    }
    first = None
    for field, bad in checks.items():
        idx = np.flatnonzero(bad)
        if idx.size and (first is None or idx[0] < first["step"]):
            first = {"step": int(idx[0]), "field": field}
    return first


def per_step_deviation(a: Any, Y: np.ndarray, R: np.ndarray, window: int) -> np.ndarray:
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


def run_check(a: Any, trace: Any, *, model: Any, ran: str, design_model: bool) -> dict:
    """The ``fixed_point`` block of a run's report (module docstring); ``model`` is the law's bit-exact model."""
    fp = a.checks["fixed_point"]
    err = fp["error"]
    out: dict[str, Any] = {"law": ran, "numeric": fp["numeric"], "steps": int(trace.t.size)}
    Y = np.where(np.asarray(trace.nan_sent)[:, None], np.nan, trace.y).astype(np.float32)
    R = trace.r.astype(np.float32)
    model = _model_steps(a, model, Y, R)
    events = (model[1] != 0) | (model[2] != 0)
    window = int(np.argmax(events)) if events.any() else len(events)
    if not np.all(trace.got):
        out["bit_exact"] = None
        out["note"] = "a sample went unanswered: the controller's steps are not the recorded samples one for one"
    else:
        diff = _first_difference(trace, model, a)
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
    out["certificate_applies"] = design_model
    out["clipped_steps"] = int(np.count_nonzero(model[2] & flags.CLIPPED))
    out["overflow_steps"] = int(np.count_nonzero(model[2] & flags.OVERFLOW))
    within = np.array(out["measured_du_per_step"]) <= np.array(out["certified_du_per_step"])
    out["within_per_step"] = bool(np.all(within))
    return out


def summary_lines(fx: dict | None) -> list[str]:
    """The summary's lines on the fixed-point law (nothing without a ``fixed_point`` block)."""
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
