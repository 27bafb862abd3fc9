"""Design-side commands: analyze, design, validate, simulate, replay."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from ..errors import DataError, GainlinkError, VerificationError
from ..fileio import atomic_write_text, publish_files
from ..laws import ENGINES, law_of
from ..proof.replay_io import compare_traces, read_samples, write_output
from ..proof.simulation import samples_csv
from ..shipping import artifact as artifact_mod

# The API and the design side (SciPy, python-control) are imported by the commands that use them, not when the
# parser is built: every command builds it, ``gainlink hil run`` too, which uses none of them.


def register(sub: argparse._SubParsersAction) -> None:
    """Add the design-side subcommands."""
    _add_analyze(sub)
    _add_design(sub)
    _add_validate(sub)
    _add_simulate(sub)
    _add_replay(sub)


def _add_analyze(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("analyze", help="structural analysis of a plant spec")
    p.add_argument("spec", help="plant spec (TOML)")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=cmd_analyze)


def _add_design(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("design", help="design controller + observer and write DIR/gains.json")
    p.add_argument("spec", help="plant spec (TOML)")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    p.add_argument(
        "--numeric",
        choices=("float32", "q31", "q15"),
        help="the law's arithmetic, overriding [implementation] numeric (q31/q15: fixed point, needs declared ranges)",
    )
    p.add_argument(
        "--plots",
        metavar="DIR",
        help="also draw the loop broken at each actuator (loop_INPUT.png: Bode, gain and phase margins marked) and "
        "the closed loop's step response (step.png) into DIR (python-control, matplotlib)",
    )
    p.set_defaults(func=cmd_design)


def _add_validate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("validate", help="check a gain artifact against its schema, hash and invariants")
    p.add_argument("artifact", help="gains.json")
    p.set_defaults(func=cmd_validate)


def _add_simulate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("simulate", help="closed-loop run on the artifact's discrete plant, written as replay input")
    p.add_argument("artifact", help="gains.json")
    p.add_argument("--steps", type=int, default=500, help="number of samples (default 500)")
    p.add_argument(
        "--x0", type=float, nargs="+", help="initial plant state, deviation from the operating point (n values)"
    )
    p.add_argument(
        "--ref",
        type=float,
        nargs="+",
        help="constant absolute reference (q values; default: the tracked outputs at the operating point)",
    )
    p.add_argument("--noise", type=float, default=0.0, help="measurement noise standard deviation")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--schedule-signal",
        action="append",
        metavar="NAME=START[,END]",
        help="a scheduled artifact's external scheduling signal: constant, or a linear ramp over the run",
    )
    p.add_argument("--out", required=True, help="output CSV (t, y0.., r0.., and a scheduled law's s0..)")
    p.set_defaults(func=cmd_simulate)


def _add_replay(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay", help="run recorded samples through an engine of the control law")
    p.add_argument("artifact", help="gains.json")
    p.add_argument("--input", required=True, help="CSV with y0..y{p-1}, r0..r{q-1} (and optionally t)")
    p.add_argument("--output", required=True, help="CSV to write: u, sat, fault, xh, z")
    p.add_argument(
        "--engine",
        default="reference",
        help=f"one of {', '.join(ENGINES)}: the law's float64 reference, the bit-exact model of its C, the host C, "
        "a Cortex-M image in QEMU",
    )
    p.add_argument(
        "--target",
        help="with --engine qemu: the Cortex-M core whose image runs (cortex-m0|m3|m4|m7|m33|m55; default cortex-m4)",
    )
    p.add_argument("--board", help="with --engine qemu: its QEMU board (default: the target's)")
    p.add_argument(
        "--compare",
        metavar="OTHER.csv",
        help="another replay output of the same input (e.g. the reference's): both are checked one step "
        "at a time against the float64 law (exit 2 on a failure); their open-loop difference is printed",
    )
    p.set_defaults(func=cmd_replay)


def _c(z: complex) -> str:
    return f"{z.real:.4g}" if abs(z.imag) < 1e-12 else f"{z.real:.4g}{z.imag:+.4g}j"


def cmd_analyze(args: argparse.Namespace) -> int:
    """``gainlink analyze SPEC``."""
    from .. import api

    rep = api.analyze(args.spec)
    if args.json:
        print(json.dumps(rep.to_dict(), indent=2, default=str))
        return 0
    dom = "s" if rep.kind != "discrete" else "z"
    print(f"{rep.name}: {rep.kind} plant, n={rep.n} m={rep.m} p={rep.p}, Ts={rep.Ts:g} s")
    print(f"  open-loop poles ({dom}): {', '.join(_c(z) for z in rep.open_loop_poles)}")
    print(
        f"  controllability: rank {rep.controllability_rank}/{rep.n}, cond {rep.controllability_cond:.3g}"
        f"  -> {'stabilizable' if rep.stabilizable else 'NOT stabilizable'}"
    )
    print(
        f"  observability:   rank {rep.observability_rank}/{rep.n}, cond {rep.observability_cond:.3g}"
        f"  -> {'detectable' if rep.detectable else 'NOT detectable'}"
    )
    print("  PBH per mode:")
    for md in rep.modes:
        print(
            f"    {_c(md.eigenvalue):>22}  {'stable  ' if md.stable else 'unstable'}"
            f"  {'controllable' if md.controllable else 'UNCONTROLLABLE'}"
            f"  {'observable' if md.observable else 'UNOBSERVABLE'}"
        )
    zeros = ", ".join(_c(z) for z in rep.transmission_zeros) or "none"
    print(f"  transmission zeros: {zeros}")
    print(
        f"  bandwidth ({rep.bandwidth_source}): {rep.bandwidth_rad_s:.3g} rad/s; "
        f"sampling is {rep.sample_rate_ratio:.1f}x that"
    )
    print(f"  state scaling spread: {rep.state_scale_ratio:.3g}x")
    if rep.compensator is not None:
        c = rep.compensator
        print(
            f"  compensator of the spec's design (y, r -> u, unsaturated): spectral radius {c['spectral_radius']:.4g}"
            f", {c['spectral_radius_without_integrators']:.4g} without integrators -> "
            f"{'stable' if c['stable'] else 'UNSTABLE'}"
        )
    if rep.float32 is not None:
        f = rep.float32
        print(
            f"  float32 in closed loop: max |u32 - u64| {f['max_rel_u']:.3g} of the limit span "
            f"({'within' if f['max_rel_u'] <= f['threshold'] else 'ABOVE'} {f['threshold']:.3g})"
        )
    if rep.dead_time is not None:
        d = rep.dead_time
        print(
            f"  with the exact dead times (design: Padé order {d['pade_order']}): closed-loop spectral radius "
            f"{d['spectral_radius']:.4f} -> {'stable' if d['stable'] else 'UNSTABLE'}"
        )
    for line in rep.law_lines:
        print(line)
    for w in rep.warnings:
        print(f"  warning: {w}")
    return 0


def cmd_design(args: argparse.Namespace) -> int:
    """``gainlink design SPEC --out DIR``."""
    from .. import api

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise GainlinkError(f"output path {out} exists and is not a directory")
    plots_dir = Path(args.plots) if args.plots else None
    if plots_dir is not None and plots_dir.exists() and not plots_dir.is_dir():
        raise GainlinkError(f"--plots {plots_dir} exists and is not a directory")
    numeric = None if args.numeric is None else {"numeric": args.numeric}
    result = api.design_report(args.spec, implementation=numeric)
    loaded = artifact_mod.from_dict(result.artifact)  # the written file must load: check before publishing
    law = law_of(loaded)
    plots, not_drawn = law.design_plots(loaded) if plots_dir is not None else ({}, None)
    publish_files(out, {"gains.json": artifact_mod.render(result.artifact)})
    if plots:
        publish_files(plots_dir, plots)
    if not_drawn:
        print(f"  --plots: {not_drawn}")
    if args.json:
        print(json.dumps(law.design_json(result, out / "gains.json"), indent=2))
        return 0
    for line in law.design_lines(result, out / "gains.json"):
        print(line)
    if plots:
        print(f"  plots in {plots_dir}: {', '.join(sorted(plots))}")
    return 0


def cmd_validate(args: argparse.Namespace) -> int:
    """``gainlink validate ARTIFACT``."""
    from .. import api

    a = api.load(args.artifact)
    print(
        f"{args.artifact}: valid gainlink artifact '{a.name}' (n={a.n} m={a.m} p={a.p} q={a.q}, "
        f"{a.observer_form}, anti-windup {a.anti_windup}), sha256 {a.sha256}"
    )
    return 0


def cmd_simulate(args: argparse.Namespace) -> int:
    """``gainlink simulate ARTIFACT --out CSV``."""
    from .. import api

    a = api.load(args.artifact)
    if args.x0 is not None and len(args.x0) != a.n:
        raise DataError(f"--x0 needs {a.n} values (one per state), got {len(args.x0)}")
    if args.ref is not None and len(args.ref) != a.q:
        raise DataError(f"--ref needs {a.q} values (one per tracked output), got {len(args.ref)}")
    if args.noise < 0 or not np.isfinite(args.noise):
        raise DataError("--noise must be a finite number >= 0")
    from ._signals import signal_ramps

    signals = signal_ramps(a, args.schedule_signal, args.steps)
    sim = api.simulate(a, steps=args.steps, x0=args.x0, reference=args.ref, noise_std=args.noise, seed=args.seed,
                       signals=signals if signals.shape[1] else None)  # fmt: skip
    out = Path(args.out)
    if not out.parent.is_dir():
        raise DataError(f"output folder {out.parent} does not exist")
    atomic_write_text(out, samples_csv(sim))
    print(
        f"wrote {args.steps} samples to {out}; final |y| = {np.abs(sim.y[-1]).max():.3g}, "
        f"saturated {np.mean(np.any((sim.u <= a.u_min) | (sim.u >= a.u_max), axis=1)) * 100:.1f}% of steps"
    )
    return 0


def cmd_replay(args: argparse.Namespace) -> int:
    """``gainlink replay ARTIFACT --input IN.csv --output OUT.csv [--compare OTHER.csv]``."""
    from .. import api

    a = api.load(args.artifact)
    law = law_of(a)
    engine = args.engine
    samples = read_samples(args.input, a, law.externals(a))
    other = None
    if args.compare:  # read and checked before the replay writes anything
        if not Path(args.compare).is_file():
            raise DataError(f"comparison file {args.compare} not found")
        other = law.read_trace(args.compare, a)
        if other.u.shape[0] != samples.Y.shape[0]:
            raise DataError(
                f"comparison file {args.compare} has {other.u.shape[0]} samples, input {args.input} has "
                f"{samples.Y.shape[0]}"
            )
    trace = api.replay(a, samples.Y, samples.R, s=samples.S, engine=engine, target=args.target, board=args.board)
    write_output(args.output, law.trace_text(a, trace, samples.t, engine=engine))
    where = f" ({'/'.join(x for x in (args.target, args.board) if x)})" if args.target or args.board else ""
    print(
        f"replayed {trace.u.shape[0]} samples through {args.engine}{where}: "
        f"{int(trace.saturated.any(axis=1).sum())} saturated, {int(trace.fault.sum())} refused as non-finite; "
        f"wrote {args.output}"
    )
    if other is None:
        return 0
    verdicts = [(args.engine, v) for v in law.one_step(a, samples.Y, samples.R, samples.S, trace, engine=engine)]
    verdicts += [(args.compare, v) for v in law.one_step(a, samples.Y, samples.R, samples.S, other, engine=None)]
    for name, v in verdicts:
        print(f"one-step check of {name}{f' ({v.against})' if v.against else ''}: {v.check.summary()}")
    return _report_compare(a, args, trace, other, verdicts)


def _report_compare(a, args: argparse.Namespace, trace, other, verdicts: list) -> int:
    c = compare_traces(a, trace, other)
    print(
        f"open loop against {args.compare} (information): max |du| = {c.max_abs_u:.3g} ({c.max_rel_u:.3g} of the "
        f"limit span), saturation flags differ on {c.sat_mismatches} (per input: "
        f"{', '.join(f'{name} {k}' for name, k in zip(a.signals['inputs'], c.sat_mismatches_per_input))}), "
        f"fault flags on {c.fault_mismatches} of {c.steps} steps; {law_of(a).open_loop_note(a)}"
    )
    for name, v in verdicts:
        if not v.passed:
            raise VerificationError(f"one-step check failed at {v.check.first_failure.describe(name)}")
    return 0
