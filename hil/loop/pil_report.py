"""The one-screen summary of a PIL run (``gainlink pil run``), as ``hil run`` prints one: from the same numbers
``pil.json`` holds (:meth:`.pil.PilResult.summary` with the run's identity and its model twin), so the two never say
different things. ``--json`` prints the JSON instead."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from gainlink.laws import law_of

from .report import model_lines, twin_lines, unit_of


def _g(v: Any, digits: int = 4) -> str:
    return "n/a" if v is None else f"{v:.{digits}g}"


def pil_summary_text(summary: dict, *, artifact: Any, out_dir: Path | None = None) -> str:
    """The text summary of a PIL run's ``summary`` (the dict ``pil.json`` holds) for ``artifact``."""
    s, sig = summary, artifact.signals
    lines = [
        f"PIL run {s['artifact']} on {s['board']} ({s['target']}, QEMU), plant {s['plant']}: {s['steps']} steps",
        f"  artifact {s['artifact']} sha256:{s['sha256'][:16]}  law {s['law']}",
        f"  emulated loop: {_g(s['steps_per_second'], 5)} steps/s; round trip (sample out, command back) "
        f"p50 {_g(s['round_trip_us_p50'])} us, p99 {_g(s['round_trip_us_p99'])} us",
        f"  saturated {s['saturated_steps']} of {s['steps']} steps (any input); refused samples (faults) {s['faults']}",
    ]
    lines += instruction_lines(s.get("instructions_per_step"))
    lines += law_of(artifact).pil_lines(s)
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


def instruction_lines(block: dict | None) -> list[str]:
    """The summary's lines on the instructions of the law's step in the run (``pil.json``'s
    ``instructions_per_step``) and the law's bound on them."""
    if not block:
        return []
    return [
        f"  instructions per step in {block['symbol']} (callees included, counted by QEMU): mean {block['mean']:g}, "
        f"worst {block['worst']} over {block['calls']} steps; instructions, not cycles"
    ] + bound_lines(block.get("bound"))


def bound_lines(bound: dict | None) -> list[str]:
    """The summary's line on the law's bound on those instructions (``instructions_per_step.bound``), if it states
    one."""
    if not bound:
        return []
    if not bound["proved"]:
        return [f"  bound at the cap: none ({bound['covers']})"]
    b = bound
    at_cap = f"fixed {b['fixed']} + cap {b['cap']} x {b['per_iteration']} per iteration"
    how = f"= {at_cap} (a refused step {b['refused_step']})"
    if b["per_step"] != b["fixed"] + b["cap"] * b["per_iteration"]:
        how = f"= a refused step's, dearer than {at_cap}"
    return [
        f"  bound at the cap, proved on {b['core']}: {b['per_step']} instructions per step {how}; "
        f"covers {b['covers']}; premises: {'; '.join(b['premises'])}"
    ]
