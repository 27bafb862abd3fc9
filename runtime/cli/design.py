"""Design-side commands: analyze, design, validate, simulate, replay."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from ..errors import DataError, GainlinkError, VerificationError
from ..fileio import atomic_write_text, publish_files
from ..proof.fixed_onestep import fixed_one_step_check, trace_words
from ..proof.replay_io import compare_traces, engine_names, one_step_check, read_samples, read_trace, write_trace
from ..proof.simulation import samples_csv
from ..shipping import artifact as artifact_mod
from ..shipping.codegen_fixed import is_fixed

# The API and the design side (SciPy, python-control) are imported by the commands that use them, not when the
# parser is built: every command builds it, ``gainlink hil run`` too, which uses none of them.


def register(sub: argparse._SubParsersAction) -> None:
    """Add the design-side subcommands."""
    p = sub.add_parser("analyze", help="structural analysis of a plant spec")
    p.add_argument("spec", help="plant spec (TOML)")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=cmd_analyze)

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

    p = sub.add_parser("validate", help="check a gain artifact against its schema, hash and invariants")
    p.add_argument("artifact", help="gains.json")
    p.set_defaults(func=cmd_validate)

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

    p = sub.add_parser("replay", help="run recorded samples through an engine of the control law")
    p.add_argument("artifact", help="gains.json")
    p.add_argument("--input", required=True, help="CSV with y0..y{p-1}, r0..r{q-1} (and optionally t)")
    p.add_argument("--output", required=True, help="CSV to write: u, sat, fault, xh, z")
    p.add_argument("--engine", default="reference", help=f"one of {', '.join(engine_names())}")
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
    from ..synthesis.schedule import describe_schedule

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
    if rep.schedule is not None:
        print(f"  scheduled on {rep.schedule['sigma']} (the plant above is the first point's):")
        for line in describe_schedule(rep.schedule):
            print(f"    {line}")
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
    plots = _design_plots(loaded) if plots_dir is not None else {}
    publish_files(out, {"gains.json": artifact_mod.render(result.artifact)})
    if plots:
        publish_files(plots_dir, plots)
    if result.schedule is not None:
        if plots_dir is not None:
            print(f"  --plots: not drawn for a scheduled law (its loop changes along {loaded.schedule.sigma})")
        return _print_scheduled(result, out, as_json=args.json)
    if args.json:
        print(json.dumps(_design_json(result, out / "gains.json"), indent=2))
        return 0
    _print_gains(result)
    _print_checks(result)
    if result.fixed_point is not None:
        _print_fixed_point(result.fixed_point, result.artifact["checks"]["fixed_point"]["measured"])
    print(f"  wrote {out / 'gains.json'} (sha256 {result.artifact['sha256'][:16]})")
    if plots:
        print(f"  plots in {plots_dir}: {', '.join(sorted(plots))}")
    return 0


def _design_plots(artifact) -> dict[str, bytes]:
    """``design --plots``: the broken loops and the step response (nothing for a scheduled law)."""
    if artifact.schedule is not None:
        return {}
    from ..synthesis.loop_plots import design_plots

    return design_plots(artifact)


def _design_json(result, path: Path) -> dict:
    from ..synthesis.analysis import complex_pairs

    a = result.artifact
    return {
        "artifact": str(path),
        "sha256": a["sha256"],
        "K": a["K"],
        "L": a["L"],
        "Ki": a.get("Ki"),
        "controller_poles": complex_pairs(result.controller_poles),
        "observer_poles": complex_pairs(result.observer_poles),
        "margins": a["checks"]["margins"],
        "u_op": a.get("u_op"),
        "y_op": a.get("y_op"),
        "compensator": a["checks"]["compensator"],
        "float32": a["checks"].get("float32"),
        "fixed_point": a["checks"].get("fixed_point"),
        "realization": a.get("realization", {}).get("kind", "as_designed"),
        "warnings": result.warnings,
    }


def _print_gains(result) -> None:
    """The design's summary line, gains, poles and margins."""
    a = result.artifact
    print(
        f"{a['name']}: n={a['n']} m={a['m']} p={a['p']} q={a['q']}, Ts={a['Ts']:g} s, "
        f"{a['design']['controller']['method']} + {a['design']['observer']['method']} "
        f"({a['observer_form']}), anti-windup {a['anti_windup']}"
    )
    with np.printoptions(precision=5, suppress=True, linewidth=110):
        print(f"  K  = {np.array(a['K'])}".replace("\n", "\n       "))
        if a["q"]:
            print(f"  Ki = {np.array(a['Ki'])}".replace("\n", "\n       "))
    print(
        f"  controller poles |z| max {np.max(np.abs(result.controller_poles)):.5f}, "
        f"observer poles |z| max {np.max(np.abs(result.observer_poles)):.5f}, "
        f"closed loop spectral radius {a['checks']['spectral_radius']:.5f}"
    )
    for mg in result.margins:
        up = "inf" if mg.gain_margin_up_db is None else f"+{mg.gain_margin_up_db:.1f}"
        down = "-inf" if mg.gain_margin_down_db is None else f"{mg.gain_margin_down_db:.1f}"
        pm = "n/a" if mg.phase_margin_deg is None else f"{mg.phase_margin_deg:.1f} deg"
        print(f"  margins at input {mg.input}: gain {up} / {down} dB, phase {pm}")


def _print_checks(result) -> None:
    """The operating point and the implementation checks: compensator, dead times, float32."""
    a = result.artifact
    if "u_op" in a or "y_op" in a:
        op = [
            f"{name}={v:.6g}"
            for key, names in (("u_op", a["signals"]["inputs"]), ("y_op", a["signals"]["outputs"]))
            for name, v in zip(names, a.get(key, [0.0] * len(names)))
        ]
        print(f"  operating point: {', '.join(op)} (samples, references and commands are absolute)")
    print(f"  {result.compensator.describe()}")
    if result.dead_time is not None:
        print(f"  {result.dead_time.describe()}")
    realization = a.get("realization", {}).get("kind", "as_designed")
    if result.float32 is not None:
        f = result.float32
        print(
            f"  float32 in closed loop ({realization} realisation, {f.steps} steps, noise, reference step, "
            f"saturating disturbance): max |u32 - u64| {f.max_rel_u:.3g} of the limit span, max |y32 - y64| "
            f"{f.max_rel_y:.3g} of the output excursion ({'within' if f.ok else 'ABOVE'} {f.threshold:g})"
        )


def _print_fixed_point(cert, measured: dict) -> None:
    """The certificate's lines, and the deviation measured in closed loop beside the certified bound."""
    from ..synthesis.fixed_point import describe as describe_fixed_point

    for line in describe_fixed_point(cert):
        print(f"  {line}")
    worst = ", ".join(
        f"{name} {got:.3g} (bound {bound:.3g})"
        for name, got, bound in zip(cert.names["u"], measured["max_abs_u_unsaturated"], measured["bound_closed_loop"])
    )
    print(
        f"    measured in closed loop ({measured['steps']} steps, noise, reference step, saturating disturbance): "
        f"unsaturated, against the float64 law with the quantised coefficients (the rounding alone, closed loop) "
        f"{worst} over {measured['unsaturated_steps']} steps; whole run "
        f"{measured['max_rel_u_quantised']:.3g} of the span against the float64 law with the same coefficients and "
        f"clip, {measured['max_rel_u']:.3g} against the design's"
        + (f" ({measured['clipped_steps']} steps clipped to the ranges)" if measured["clipped_steps"] else "")
        + ("" if not measured["overflow"] else f"; SECOND-LINE SATURATION on {', '.join(measured['overflow'])}")
    )


def _compensator_note(a) -> str:
    """What the compensator's stability says about an open-loop comparison (scheduled: see each point's)."""
    from ..synthesis.compensator import compensator_stability

    if a.schedule is not None:
        return "the scheduled law's compensator at each point is in checks.schedule.points"
    comp = compensator_stability(a)
    if comp.stable:
        return comp.describe()
    return (
        f"{comp.describe()}; replayed open loop, rounding grows like {comp.radius_without_integrators:.3g}^k"
        ": the one-step check is the verdict"
    )


def _print_scheduled(result, out: Path, *, as_json: bool) -> int:
    """``gainlink design`` of a scheduled spec: every point, the grid, the verdict on a moving sigma."""
    from ..synthesis.schedule import describe_schedule

    a = result.artifact
    sch = a["checks"]["schedule"]
    if as_json:
        print(json.dumps({"artifact": str(out / "gains.json"), "sha256": a["sha256"], "schedule": sch,
                          "rate_max": a["schedule"]["rate_max"], "rate_certified": a["schedule"]["rate_certified"],
                          "warnings": result.warnings}, indent=2))  # fmt: skip
        return 0
    s = a["schedule"]
    print(
        f"{a['name']}: n={a['n']} m={a['m']} p={a['p']} q={a['q']}, Ts={a['Ts']:g} s, scheduled on {sch['sigma']} "
        f"({s['sigma']['source']}) at {', '.join(f'{v:g}' for v in s['points'])}: "
        f"{a['design']['controller']['method']} + {a['design']['observer']['method']} ({a['observer_form']}) per "
        "point, velocity form"
    )
    for line in describe_schedule(sch):
        print(f"  {line}")
    print(f"  coefficients that vary between points (interpolated by the C): {', '.join(s['varying']) or 'none'}")
    print(f"  wrote {out / 'gains.json'} (schema 2, sha256 {a['sha256'][:16]})")
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
    other = words = None
    if args.compare:  # read and checked before the replay writes anything
        if not Path(args.compare).is_file():
            raise DataError(f"comparison file {args.compare} not found")
        other = read_trace(args.compare, a)
        if is_fixed(a):  # a fixed-point trace: its words, refused when they are not this artifact's
            words = trace_words(a, other, f"comparison file {args.compare}")
        steps = read_samples(args.input, a).Y.shape[0]
        if other.u.shape[0] != steps:
            raise DataError(
                f"comparison file {args.compare} has {other.u.shape[0]} samples, input {args.input} has {steps}"
            )
    samples = read_samples(args.input, a)
    trace = api.replay(a, samples.Y, samples.R, s=samples.S, engine=args.engine, target=args.target, board=args.board)
    write_trace(args.output, trace, samples.t, artifact=a, engine=args.engine)
    where = f" ({'/'.join(x for x in (args.target, args.board) if x)})" if args.target or args.board else ""
    print(
        f"replayed {trace.u.shape[0]} samples through {args.engine}{where}: "
        f"{int(trace.saturated.any(axis=1).sum())} saturated, {int(trace.fault.sum())} refused as non-finite; "
        f"wrote {args.output}"
    )
    if other is None:
        return 0
    if is_fixed(a):
        return _compare_fixed(a, args, samples, trace, other, words)
    c32 = a.schedule is not None and args.engine != "reference"  # the scheduled C: against its float32 model
    checks = {
        args.engine: one_step_check(a, samples.Y, samples.R, trace, S=samples.S, c_engine=c32),
        args.compare: one_step_check(a, samples.Y, samples.R, other, S=samples.S),
    }
    for name, check in checks.items():
        law = "the C's float32 arithmetic, bit for bit," if c32 and name == args.engine else "float64 law"
        print(f"one-step check of {name} ({law} from its own state at each step): {check.summary()}")
    return _report_compare(a, args, trace, other, checks)


def _compare_fixed(a, args: argparse.Namespace, samples, trace, other, words) -> int:
    """``--compare`` on a fixed-point artifact: both traces bit for bit against the integer law (the ``reference``
    engine's own trace, the float64 law, against its float32 bound)."""
    mine = (
        one_step_check(a, samples.Y, samples.R, trace)
        if args.engine == "reference"
        else fixed_one_step_check(a, samples.Y, samples.R, trace_words(a, trace, f"the trace of engine {args.engine}"))
    )
    checks = {args.engine: mine, args.compare: fixed_one_step_check(a, samples.Y, samples.R, words)}
    for name, check in checks.items():
        law = " (float64 law from its own state at each step)" if check is mine and args.engine == "reference" else ""
        print(f"one-step check of {name}{law}: {check.summary()}")
    return _report_compare(a, args, trace, other, checks)


def _report_compare(a, args: argparse.Namespace, trace, other, checks: dict) -> int:
    c = compare_traces(a, trace, other)
    print(
        f"open loop against {args.compare} (information): max |du| = {c.max_abs_u:.3g} ({c.max_rel_u:.3g} of the "
        f"limit span), saturation flags differ on {c.sat_mismatches} (per input: "
        f"{', '.join(f'{name} {k}' for name, k in zip(a.signals['inputs'], c.sat_mismatches_per_input))}), "
        f"fault flags on {c.fault_mismatches} of {c.steps} steps; {_compensator_note(a)}"
    )
    for name, check in checks.items():
        if not check.passed:
            raise VerificationError(f"one-step check failed at {check.first_failure.describe(name)}")
    return 0
