"""``gainlink hil ...`` (HIL bridge, DBC, project FMUs, saturation study, scheduled showcase) and
``gainlink linearize``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import GainlinkError


def _progress_bar(enabled: bool):
    """A rich progress bar on stderr (a no-op when disabled or not a terminal)."""
    from contextlib import nullcontext

    if not enabled or not sys.stderr.isatty():
        return nullcontext(None)
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    return Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total}"),
        TimeRemainingColumn(),
        transient=True,
    )


def _run(args: argparse.Namespace) -> int:
    from gainlink.hil import run
    from gainlink.hil.loop.report import summary_text

    report_dir = Path(args.report)
    with _progress_bar(not args.no_progress) as bar:
        callback = None
        if bar is not None:
            task = bar.add_task(f"HIL {args.scenario}", total=None)
            callback = lambda done, total: bar.update(task, completed=done, total=total)  # noqa: E731
        result = run(
            args.scenario, artifact=args.artifact, report=report_dir, progress=callback, plots=not args.no_plots
        )
    sys.stdout.write(summary_text(result, report_dir=report_dir))
    return 0 if result.complete else 1


def _dbc(args: argparse.Namespace) -> int:
    from gainlink.fileio import atomic_write_text
    from gainlink.hil.links.can import layout_from_config
    from gainlink.hil.links.can_firmware import read_can_config
    from gainlink.shipping.artifact import load

    config = read_can_config(args.can) if args.can else {}
    if args.fd:
        config["fd"] = True
    if args.base_id is not None:
        config["base_id"] = args.base_id
    layout = layout_from_config(config, artifact=load(args.artifact))
    text = layout.dbc()
    if args.out:
        atomic_write_text(args.out, text)
        print(f"wrote {args.out} ({len(layout.measurement)} measurement + {len(layout.command)} command frames)")
    else:
        sys.stdout.write(text)
    return 0


def _fmu(args: argparse.Namespace) -> int:
    from gainlink.hil.paths import fmu_source_names
    from gainlink.hil.plants.build import build_fmu

    names = args.names or fmu_source_names()
    for name in names:
        print(build_fmu(name, out_dir=args.out))
    return 0


def _study(args: argparse.Namespace) -> int:
    from gainlink.hil.loop.study import default_study, run_saturation_study

    study_desc = None
    if args.study and not Path(args.study).exists() and "/" not in args.study and not args.study.endswith(".toml"):
        study_desc = default_study(args.study)
    elif args.study:
        from gainlink.fileio import read_toml

        study_desc, _ = read_toml(args.study, what="study", error=GainlinkError)
    study = run_saturation_study(
        spec_path=Path(args.spec) if args.spec else None,
        report_dir=Path(args.report),
        controller=args.controller,
        study=study_desc,
        plots=not args.no_plots,
    )
    sys.stdout.write(study.summary)
    return 0


def _showcase(args: argparse.Namespace) -> int:
    from gainlink.hil.loop.showcase import run_showcase

    result = run_showcase(
        spec_path=Path(args.spec) if args.spec else None, report_dir=Path(args.report), controller=args.controller
    )
    sys.stdout.write(result.summary)
    return 0


def _linearize(args: argparse.Namespace) -> int:
    from gainlink.hil.plants.linearize import linearize_to_spec

    at = {}
    for item in args.at:
        if "=" not in item:
            raise GainlinkError(f"--at expects NAME=VALUE, got {item!r}")
        name, value = item.split("=", 1)
        try:
            at[name.strip()] = float(value)
        except ValueError:
            raise GainlinkError(f"--at {name}: {value!r} is not a number") from None
    if args.schedule:
        return _linearize_schedule(args, at)
    result = linearize_to_spec(
        fmu=args.fmu,
        at=at,
        out=Path(args.out),
        Ts=args.Ts,
        name=args.name,
        inputs=args.inputs,
        outputs=args.outputs,
        method=args.method,
        template=Path(args.template) if args.template else None,
        horizon=args.horizon,
        interface=args.interface,
    )
    if args.json:
        import json

        sys.stdout.write(json.dumps({"spec": args.out, **result.to_json()}, indent=2, sort_keys=True) + "\n")
        return 0
    lin, validity = result.lin, result.validity
    print(
        f"wrote {args.out}: n={lin.A.shape[0]} m={lin.B.shape[1]} p={lin.C.shape[0]} "
        f"({lin.method}, operating point {', '.join(f'{k}={v:g}' for k, v in lin.point.items()) or 'start values'})"
    )
    print(f"  runs at Ts = {args.Ts:g} s use {validity.choice.interface}: {validity.choice.reason}")
    print(
        "  fit to the FMU: "
        + ", ".join(f"{k} NRMSE {f.nrmse:.2g} final {f.final_error:.2g}" for k, f in validity.fit.outputs.items())
        + (" - POOR (see the warning)" if validity.fit.poor else "")
    )
    return 0


def _linearize_schedule(args: argparse.Namespace, at: dict) -> int:
    """``linearize FMU --schedule NAME=v1,v2,...``: trim at each value and write the scheduled spec."""
    from gainlink.hil.plants.trim import trim_schedule_to_spec

    name, _, values = args.schedule.partition("=")
    try:
        points = [float(v) for v in values.split(",") if v.strip()]
    except ValueError:
        raise GainlinkError(f"--schedule expects NAME=v1,v2,... (numbers), got {args.schedule!r}") from None
    if not name.strip() or not points:
        raise GainlinkError(f"--schedule expects NAME=v1,v2,..., got {args.schedule!r}")
    written = trim_schedule_to_spec(
        fmu=args.fmu,
        sigma=name.strip(),
        values=points,
        at=at,
        out=Path(args.out),
        Ts=args.Ts,
        name=args.name,
        inputs=args.inputs,
        outputs=args.outputs,
        method=args.method,
        template=Path(args.template) if args.template else None,
        interface=args.interface,
    )
    if args.json:
        import json

        sys.stdout.write(json.dumps({"spec": args.out, **written.to_json()}, indent=2, sort_keys=True) + "\n")
        return 0
    trims = written.trims
    print(
        f"wrote {args.out}: scheduled on {name.strip()} at {', '.join(f'{t.sigma:g}' for t in trims)}, each point "
        f"trimmed (Newton steps {', '.join(str(t.iterations) for t in trims)}; "
        f"max residual {max(t.residual for t in trims):.2g})"
    )
    for f in written.fits:
        fit = f.validity.fit
        print(
            f"  fit at {f.sigma} = {f.value:g} (through {fit.interface}): "
            + ", ".join(f"{k} NRMSE {o.nrmse:.2g} final {o.final_error:.2g}" for k, o in fit.outputs.items())
            + (" - POOR (see the warning)" if fit.poor else "")
        )
    return 0


def _add_run_parser(sub: argparse._SubParsersAction) -> None:
    """``hil run``: a HIL scenario and its report."""
    p = sub.add_parser("run", help="run a HIL scenario and write its report")
    p.add_argument("scenario", help="scenario TOML, or a built-in scenario name (e.g. pendulum_fmu)")
    p.add_argument("--artifact", help="use this gains.json instead of the scenario's artifact")
    p.add_argument("--report", required=True, help="report folder (report.json, PNG plots, summary.txt)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-plots", action="store_true", help="report.json and summary.txt only (no PNG plots)")
    p.set_defaults(func=_run)


def _add_dbc_parser(sub: argparse._SubParsersAction) -> None:
    """``hil dbc``: the CAN layout of an artifact as a DBC file."""
    p = sub.add_parser("dbc", help="write the CAN layout of an artifact as a DBC file")
    p.add_argument("artifact")
    p.add_argument("--fd", action="store_true", help="CAN FD layout (else classic CAN)")
    p.add_argument("--base-id", help="first 11-bit identifier (default 0x100)")
    p.add_argument(
        "--can",
        metavar="CONFIG",
        help="the layout of this CAN transport table (a scenario or a TOML/JSON file with its "
        "[transport], or inline JSON): fd, base_id, encoding (float32 | int16) and ranges, e.g. "
        '\'{"interface": "socketcan", "encoding": "int16", "ranges": '
        '{"x": [-5, 5], "theta": [-1, 1], "r_x": [-5, 5]}}\'',
    )
    p.add_argument("--out", help="DBC file (default: stdout)")
    p.set_defaults(func=_dbc)


def _add_fmu_parser(sub: argparse._SubParsersAction) -> None:
    """``hil fmu``: build and validate the project's plant FMUs."""
    p = sub.add_parser("fmu", help="build (cached) and validate the project's plant FMUs")
    p.add_argument("names", nargs="*", help="FMU names (default: all)")
    p.add_argument("--out", help="folder for the .fmu files (default .cache/fmus)")
    p.set_defaults(func=_fmu)


def _add_study_parser(sub: argparse._SubParsersAction) -> None:
    """``hil study``: the saturation study."""
    p = sub.add_parser("study", help="saturation study: anti-windup none vs clamp vs backcalc")
    p.add_argument("--spec", help="plant spec (default: examples/pendulum.toml of the checkout)")
    p.add_argument("--study", help="study TOML, or a built-in study: saturation_study (default), saturation_kick")
    p.add_argument("--controller", choices=("firmware", "reference"), help="override the study's controller")
    p.add_argument("--report", required=True, help="report folder")
    p.add_argument("--no-plots", action="store_true", help="study.json and the text files only (no PNG plots)")
    p.set_defaults(func=_study)


def _add_showcase_parser(sub: argparse._SubParsersAction) -> None:
    """``hil showcase``: the scheduled design against its single point across the envelope."""
    p = sub.add_parser("showcase", help="scheduled vs single-point design across the envelope (tank FMU)")
    p.add_argument("--spec", help="scheduled spec (default: examples/tank_showcase.toml of the checkout)")
    p.add_argument("--controller", choices=("firmware", "reference"), help="override the controller (firmware)")
    p.add_argument("--report", required=True, help="report folder")
    p.set_defaults(func=_showcase)


def _add_linearize_parser(subparsers: argparse._SubParsersAction) -> None:
    """``linearize``: an FMU linearised into a plant spec."""
    p = subparsers.add_parser("linearize", help="linearise an FMU about an operating point into a plant spec")
    p.add_argument("fmu", help=".fmu file, or the name of a project FMU (e.g. cart_pendulum)")
    p.add_argument(
        "--at",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="operating point: state, input or parameter value (repeatable)",
    )
    p.add_argument("--out", required=True, help="spec TOML to write")
    p.add_argument(
        "--Ts",
        type=float,
        default=0.01,
        help="sample time written into the spec (default 0.01); for a Co-Simulation-only FMU also the "
        "communication step of the identified discrete model",
    )
    p.add_argument("--horizon", type=int, help="Co-Simulation-only FMUs: steps recorded per input pulse (default 100)")
    p.add_argument("--name", help="spec name (default: the FMU's model name)")
    p.add_argument("--inputs", nargs="+", help="FMU inputs to keep (default: all)")
    p.add_argument("--outputs", nargs="+", help="FMU outputs to keep (default: all)")
    p.add_argument(
        "--method",
        choices=("auto", "directional", "differences"),
        default="auto",
        help="directional derivatives when the FMU provides them (auto), or central differences",
    )
    p.add_argument("--template", help="copy controller/integral/observer/limits from this spec")
    p.add_argument(
        "--interface",
        choices=("auto", "cs", "me"),
        default="auto",
        help="the FMU interface the model is checked through (default auto: Co-Simulation where it reproduces "
        "the Model Exchange derivatives at --Ts, as runs choose)",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help="print the result and the [linearization] record as JSON (with --schedule: each point's fit too)",
    )
    p.add_argument(
        "--schedule",
        metavar="NAME=v1,v2,...",
        help="a scheduled spec: trim the FMU at each value of NAME (an output, a state or a parameter; --at values "
        "are held at every point) and linearise there",
    )
    p.set_defaults(func=_linearize)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``hil`` and ``linearize`` to the gainlink CLI."""
    hil = subparsers.add_parser("hil", help="hardware-in-the-loop bridge over CAN or MAVLink (FMU or built-in plants)")
    sub = hil.add_subparsers(dest="hil_command", metavar="HIL_COMMAND")
    sub.required = True
    _add_run_parser(sub)
    _add_dbc_parser(sub)
    _add_fmu_parser(sub)
    _add_study_parser(sub)
    _add_showcase_parser(sub)
    _add_linearize_parser(subparsers)
