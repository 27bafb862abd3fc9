"""The one-screen summary of a PIL run (``gainlink pil run``), as ``hil run`` prints one: from the same numbers
``pil.json`` holds (:meth:`.pil.PilResult.summary` with the run's identity and its model twin), so the two never say
different things. ``--json`` prints the JSON instead."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from gainlink.laws.scheduled_run import schedule_lines

from .report import model_lines, twin_lines, unit_of


def _g(v: Any, digits: int = 4) -> str:
    return "n/a" if v is None else f"{v:.{digits}g}"


def pil_summary_text(summary: dict, *, artifact: Any, out_dir: Path | None = None) -> str:
    """The text summary of a PIL run's ``summary`` (the dict ``pil.json`` holds) for ``artifact``."""
    s, sig = summary, artifact.signals
    lines = [
        f"PIL run {s['artifact']} on {s['board']} ({s['target']}, QEMU), plant {s['plant']}: {s['steps']} steps",
        f"  artifact {s['artifact']} sha256:{s['sha256'][:16]}  law {_law(s)}",
        f"  emulated loop: {_g(s['steps_per_second'], 5)} steps/s; round trip (sample out, command back) "
        f"p50 {_g(s['round_trip_us_p50'])} us, p99 {_g(s['round_trip_us_p99'])} us",
        f"  saturated {s['saturated_steps']} of {s['steps']} steps (any input); refused samples (faults) {s['faults']}",
    ]
    lines += _fixed_lines(s.get("fixed_point"))
    lines += _scheduled_lines(s.get("scheduled"))
    units = sig.get("units")
    lines += twin_lines(s.get("twin"), units=units)
    lines += model_lines(s.get("model_twin"), units=units)
    lines.append(
        "  final outputs: "
        + ", ".join(f"{name} {_g(v)}{unit_of(units, name)}" for name, v in zip(sig["outputs"], s["final_output"]))
    )
    if out_dir is not None:
        lines.append(f"  report: {out_dir / 'pil.json'}, pil.csv, twin.png")
    return "\n".join(lines) + "\n"


def _law(s: dict) -> str:
    if s.get("law"):
        return s["law"]
    fx = s.get("fixed_point")
    return f"{fx['numeric']} (integer image)" if fx else "float32"


def _fixed_lines(fx: dict | None) -> list[str]:
    """The integer image against its bit-exact model and its certified bounds (nothing for a float32 artifact)."""
    if not fx:
        return []
    first = fx["first_difference"]
    exact = "bit for bit the integer model" if fx["bit_exact"] else f"DIFFERS from the integer model at {first}"
    lines = [f"  integer law {fx['numeric']}: {exact} on the samples it received"]
    if fx["measured_du_rounding"] is not None:
        verdict = {True: "within", False: "OUTSIDE"}.get(fx["within_certified"], "not judged against")
        applies = "" if fx["certificate_applies"] else " (about the design model; the plant is not it)"
        lines.append(
            f"    vs the quantised float64 twin over {fx['unsaturated_steps']} unsaturated steps: max |du| "
            + ", ".join(_g(v, 3) for v in fx["measured_du_rounding"])
            + f", {verdict} the certified "
            + ", ".join(_g(v, 3) for v in fx["certified_du_rounding"])
            + applies
        )
    if fx["clipped_steps"] or fx["overflow_steps"]:
        lines.append(f"    clipped steps {fx['clipped_steps']}, second-line saturation steps {fx['overflow_steps']}")
    return lines


def _scheduled_lines(sch: dict | None) -> list[str]:
    """The scheduled image against the float32 model and the host C, and where sigma went."""
    if not sch:
        return []
    model = "bit for bit" if sch["bit_exact_model"] else f"DIFFERS at {sch['first_difference_model']}"
    host = "bit for bit" if sch["bit_exact_host"] else f"DIFFERS at {sch['first_difference_host']}"
    return [f"  scheduled law: the float32 model {model}, the host C {host}", *schedule_lines(sch["schedule"])]
