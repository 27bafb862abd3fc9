"""``gainlink firmware build|flash|run`` and ``gainlink pil run``."""

from __future__ import annotations

import argparse
import json
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

from ..errors import DataError, FirmwareError, GainlinkError, ToolchainError
from ..firmware.targets import BOARDS, CORTEX_M_TARGETS, TARGETS, resolve, resolve_cortex_m

_BOARD_HELP = "QEMU board of the Cortex-M image (default: the target's first): " + ", ".join(
    f"{b.name} ({b.core})" for b in BOARDS.values()
)

# Flashing commands for a real board: (board, probe) -> argv template ({hex}, {elf}).
FLASH_COMMANDS = {
    ("netduinoplus2", "pyocd"): ["pyocd", "flash", "--target", "stm32f405rg", "--format", "hex", "{hex}"],
    ("netduinoplus2", "openocd"): [
        "openocd",
        "-f",
        "interface/stlink.cfg",
        "-f",
        "target/stm32f4x.cfg",
        "-c",
        "program {elf} verify reset exit",
    ],
    ("mps2-an386", "pyocd"): ["pyocd", "flash", "--target", "cortex_m", "--format", "elf", "{elf}"],
    ("microbit", "pyocd"): ["pyocd", "flash", "--target", "nrf51", "--format", "hex", "{hex}"],
}


# --- firmware build ---------------------------------------------------------------------------------


def _build(args: argparse.Namespace) -> int:
    from gainlink.fileio import publish_files
    from gainlink.firmware.build import build
    from gainlink.firmware.size import size_report
    from gainlink.laws import law_of
    from gainlink.shipping.artifact import load

    platform = resolve(args.target, args.board)  # a wrong target or board is refused before any work
    artifact = load(args.artifact)
    law = law_of(artifact)
    res = build(artifact, target=platform.target.name, board=platform.board.name if platform.board else None)
    stem = f"gainlink_{artifact.name}"
    files: dict[str, bytes | str] = {}
    manifest = {
        "artifact": artifact.name,
        "sha256": artifact.sha256,
        "target": args.target,
        "board": res.board,
        "law": law.label,
        "files": {},
    }
    if platform.board is not None:
        for ext in ("elf", "bin", "hex", "map"):
            files[f"{stem}.{ext}"] = res.files[ext].read_bytes()
            manifest["files"][ext] = f"{stem}.{ext}"
        report = size_report(res.files["elf"], board=res.board)
        report["elf"] = f"{stem}.elf"
        files[f"{stem}.size.json"] = json.dumps(report, indent=2) + "\n"
        manifest["files"]["size"] = f"{stem}.size.json"
    else:
        for role, name in (
            ("shared", "libgainlink_host.so"),
            ("static", "libgainlink_loop.a"),
            ("exe", "gainlink_loop_host"),
        ):
            files[name] = res.files[role].read_bytes()
            manifest["files"][role] = name
    for name, text in sorted((p.name, p.read_text("utf-8")) for p in res.gains_dir.iterdir()):
        files[f"src/{name}"] = text
    files["firmware.json"] = json.dumps(manifest, indent=2) + "\n"
    written = publish_files(args.out, files)
    out = Path(args.out)
    if args.target == "host":
        (out / "gainlink_loop_host").chmod(0o755)
    else:
        print(_size_line(f"{stem}.elf", report, _image_role(law, platform.board)))
    print(
        f"built {artifact.name} for {args.target}{' / ' + res.board if res.board else ''}: "
        + ", ".join(p.name for p in written if p.parent == out)
    )
    return 0


def _size_line(name: str, report: dict, what: str) -> str:
    return (
        f"{name} on {report['board']}: flash {report['flash_bytes']} B, RAM {report['ram_bytes_without_stack']} B "
        f"+ stack ({report['ram_bytes']} B total); {what}"
    )


def _image_role(law, board) -> str:
    """What an image runs: the law, the nodes its UART serves on ``board``, and its replay."""
    if board.serves:
        nodes = "its UART's MAVLink and slcan nodes"
    else:
        nodes = "its UART's slcan node" if law.name in board.slcan_laws else None
    replay = "replay and PIL over semihosting"
    return f"the {law.label} law: {nodes}, {replay}" if nodes else f"the {law.label} law: {replay}"


# --- firmware flash ---------------------------------------------------------------------------------


def flash_command(out_dir: Path, *, probe: str) -> list[str]:
    """The exact flashing command for the image in ``out_dir`` (written by ``firmware build``)."""
    manifest_path = out_dir / "firmware.json"
    if not manifest_path.is_file():
        raise FirmwareError(
            f"{out_dir} holds no firmware.json: run `gainlink firmware build ... --out {out_dir}` first"
        )
    manifest = json.loads(manifest_path.read_text("utf-8"))
    if manifest.get("target") not in CORTEX_M_TARGETS:
        raise FirmwareError(
            f"{out_dir} holds a {manifest.get('target')} build; flashing needs a Cortex-M image (--target cortex-mN)"
        )
    board = manifest["board"]
    template = FLASH_COMMANDS.get((board, probe))
    if template is None:
        known = ", ".join(p for b, p in FLASH_COMMANDS if b == board)
        if not known:  # the MPS2/MPS3 FPGA boards load images from their USB mass storage (images.txt)
            raise FirmwareError(
                f"no flashing recipe for board {board}: copy {manifest['files']['bin']} with the board's own loader"
            )
        raise FirmwareError(f"no {probe} recipe for board {board} (use --probe {known})")
    paths = {
        "hex": str((out_dir / manifest["files"]["hex"]).resolve()),
        "elf": str((out_dir / manifest["files"]["elf"]).resolve()),
    }
    for path in paths.values():
        if not Path(path).is_file():
            raise FirmwareError(f"{path} is missing (rebuild the firmware)")
    return [part.format(**paths) for part in template]


def _flash(args: argparse.Namespace) -> int:
    cmd = flash_command(Path(args.dir), probe=args.probe)
    print(shlex.join(cmd))
    if args.dry_run:
        return 0
    if shutil.which(cmd[0]) is None:
        raise ToolchainError(f"{cmd[0]} not found: install it to flash a real board (or use --dry-run)")
    return subprocess.run(cmd, stdin=subprocess.DEVNULL).returncode


# --- firmware run ------------------------------------------------------------------------------------


def _run_host(args: argparse.Namespace) -> int:
    """Start the host executable of the artifact's law (``gainlink_loop_host``: a fixed-point artifact's runs its
    integer law): replay a CSV through it, or pass stdin/stdout through."""
    from gainlink.firmware.build import build
    from gainlink.shipping.artifact import load

    artifact = load(args.artifact)
    res = build(artifact, target="host", only="gainlink_loop_host")
    exe = res.files["exe"]
    if args.input is None:
        from gainlink.firmware.foreground import run_in_foreground

        return run_in_foreground([str(exe)])
    return _replay_through_process(artifact, exe, Path(args.input), Path(args.output) if args.output else None)


def _replay_through_process(artifact, exe: Path, input_path: Path, output_path: Path | None) -> int:
    """Replay the CSV ``input_path`` through the host executable of the artifact's law (one line per sample: its
    outputs, references and external signals) and write the trace ``gainlink replay --engine native`` writes."""
    from gainlink.fileio import atomic_write_text
    from gainlink.laws import law_of
    from gainlink.proof.replay_io import read_samples

    from ._host_exec import answer_samples, parse_records

    a, law = artifact, law_of(artifact)
    samples = read_samples(input_path, a, law.externals(a))
    stdout, N = answer_samples(exe, samples.Y, samples.R, samples.S)
    records = parse_records(a, stdout, count=N, executable=exe.name)
    trace = law.records_trace(a, records)
    text = law.trace_text(a, trace, samples.t, engine="native")
    if output_path is None:
        sys.stdout.write(text)
    else:
        if output_path.is_dir():
            raise DataError(f"output {output_path} is a directory")
        atomic_write_text(output_path, text)
        print(f"ran {N} samples through {exe.name}{law.host_run_note(a, records, trace)}")
    return 0


def _run(args: argparse.Namespace) -> int:
    # Transport options (added by the CAN and MAVLink work) each select their own host application here;
    # without one, the plain loop executable runs. --target cortex-mN serves them from the image in QEMU.
    from gainlink.shipping.artifact import load

    on_host = args.target == "host" and args.board is None
    bus_node = getattr(args, "can", None) or getattr(args, "mavlink", None)
    if args.from_artifact and not getattr(args, "mavlink", None):
        raise FirmwareError("--from-artifact is for the MAVLink node (--mavlink), the one that persists gain sets")
    if not bus_node:  # the CAN and MAVLink nodes (host apps, and the image's on its UART) run every law
        from gainlink.laws import law_of

        artifact = load(args.artifact)
        law_of(artifact).refuse("firmware_run", what="gainlink firmware run")
    if not on_host:
        return _run_image(args)
    if getattr(args, "can", None):
        from gainlink.hil.links.can_firmware import run_firmware_can

        return run_firmware_can(artifact_path=args.artifact, can=args.can)
    if getattr(args, "mavlink", None):
        from gainlink.firmware.mavlink_app import run_foreground

        return run_foreground(
            Path(args.artifact),
            url=args.mavlink,
            param_file=args.param_file and Path(args.param_file),
            signing_key=args.signing_key and Path(args.signing_key),
            from_artifact=args.from_artifact,
        )
    return _run_host(args)


def _run_image(args: argparse.Namespace) -> int:
    """A Cortex-M image in QEMU serving MAVLink (``--mavlink tcp:...``) or slcan (``--can`` slcan config)."""
    from gainlink.firmware.uart import run_foreground

    platform = resolve_cortex_m(args.target, args.board)
    image = {"target": platform.target.name, "board": platform.board.name}
    flash = Path(args.flash_dir) if args.flash_dir else None
    if args.input or args.output:
        raise FirmwareError(
            "--input/--output replay through the host build (the image replays with "
            "`gainlink replay ... --engine qemu`)"
        )
    if args.mavlink and not args.can:
        return run_foreground(
            Path(args.artifact),
            **image,
            protocol="mavlink",
            url=args.mavlink,
            options=("gains=artifact",) if args.from_artifact else (),
            flash_dir=flash,
        )
    if args.can and not args.mavlink:
        from gainlink.hil.links.can import layout_from_config, slcan_image_options
        from gainlink.hil.links.can_firmware import read_can_config
        from gainlink.shipping.artifact import load

        config = read_can_config(args.can)
        if config.get("interface") != "slcan" or config.get("fd"):
            raise FirmwareError(
                f"--target {platform.target.name} --can needs a classic slcan configuration "
                '(e.g. {"interface": "slcan", "channel": "socket://127.0.0.1:5761"})'
            )
        layout = layout_from_config(config, artifact=load(args.artifact))
        return run_foreground(
            Path(args.artifact),
            **image,
            protocol="slcan",
            url=str(config.get("channel", "")),
            options=slcan_image_options(layout),
            flash_dir=flash,
        )
    raise FirmwareError(
        f"--target {platform.target.name} serves one link: --mavlink tcp:HOST:PORT or --can with an slcan configuration"
    )


# --- pil run ---------------------------------------------------------------------------------------


def _pil(args: argparse.Namespace) -> int:
    import numpy as np
    from gainlink.fileio import publish_files
    from gainlink.hil.loop.model_twin import model_mismatch
    from gainlink.hil.loop.pil import make_plant, run_pil, twin_figure
    from gainlink.proof.twin_plot import png_bytes
    from gainlink.shipping.artifact import load

    from ._signals import signal_ramps

    platform = resolve_cortex_m(args.target, args.board)
    artifact = load(args.artifact)
    ref = args.reference
    if ref is not None and len(ref) != artifact.q:
        raise GainlinkError(f"--reference needs {artifact.q} values for artifact {artifact.name}")
    signals = signal_ramps(artifact, args.schedule_signal, args.steps)
    x0 = None if args.x0 is None else np.array(args.x0)
    plant, twin, check = (make_plant(args.plant, artifact=artifact, x0=x0) for _ in range(3))  # run, twin, check
    result = run_pil(artifact, plant=plant, steps=args.steps, reference=ref, signals=signals,
                     target=platform.target.name, board=platform.board.name, twin=twin,
                     check_plant=check)  # fmt: skip
    summary = {"artifact": artifact.name, "sha256": artifact.sha256, "target": platform.target.name,
               "board": platform.board.name, "plant": args.plant, **result.summary()}  # fmt: skip
    if result.model_twin is not None:
        mismatch = model_mismatch(
            t=np.arange(args.steps) * artifact.Ts,
            y=result.y,
            r=result.reference,
            model_y=result.model_twin.y,
            artifact=artifact,
            start=result.model_twin_start,
        )
        summary["model_twin"] = mismatch.to_dict()  # fmt: skip
    text = json.dumps(summary, indent=2) + "\n"
    if args.out:
        title = f"PIL {artifact.name} ({result.law}) on {platform.board.name}, plant {args.plant}"
        files = {"pil.csv": _pil_csv(artifact, result), "pil.json": text,
                 "twin.png": png_bytes(twin_figure(result, artifact, title=title))}  # fmt: skip
        publish_files(args.out, files)
    from ._pil_output import print_pil_summary

    return print_pil_summary(args, summary, artifact=artifact, json_text=text)


def _pil_csv(artifact, result) -> str:
    """pil.csv: per step the samples, commands, saturation, status flags and sigma, and the closed-loop and model
    twins' samples and commands (when they ran)."""
    a, tw, mt = artifact, result.twin, result.model_twin
    cols = [f"y{i}" for i in range(a.p)] + [f"u{i}" for i in range(a.m)] + [f"sat{i}" for i in range(a.m)]
    cols += ["flags", "sigma"]
    for name, twin in (("twin", tw), ("model", mt)):
        if twin is not None:
            cols += [f"{name}_y{i}" for i in range(a.p)] + [f"{name}_u{i}" for i in range(a.m)]
    rows = [",".join(cols)]
    for k in range(result.y.shape[0]):
        vals = [repr(float(v)) for v in (*result.y[k], *result.u[k])]
        vals += [str(int(s)) for s in result.saturated[k]] + [str(int(result.flags[k])), repr(float(result.sigma[k]))]
        for twin in (tw, mt):
            if twin is not None:
                vals += [repr(float(v)) for v in (*twin.y[k], *twin.u[k])]
        rows.append(",".join(vals))
    return "\n".join(rows) + "\n"


# --- parsers -----------------------------------------------------------------------------------------


def _add_build_parser(sub) -> None:
    p = sub.add_parser(
        "build",
        help="build the firmware for an artifact (host or a Cortex-M core)",
        description="Build the firmware with the artifact's gains. A Cortex-M target writes .elf .bin .hex "
        ".map and a JSON size report; host writes the shared/static libraries and the loop executable.",
    )
    p.add_argument("artifact", help="gains.json")
    p.add_argument("--target", choices=tuple(TARGETS), required=True)
    p.add_argument("--board", choices=tuple(BOARDS), help=_BOARD_HELP)
    p.add_argument("--out", required=True, help="output folder")
    p.set_defaults(func=_build)


def _add_flash_parser(sub) -> None:
    p = sub.add_parser(
        "flash",
        help="flash a built Cortex-M image to a real board",
        description="Print (and unless --dry-run, run) the flashing command for an image built by "
        "`gainlink firmware build --target cortex-mN --out DIR`.",
    )
    p.add_argument("dir", help="folder written by `firmware build`")
    p.add_argument("--probe", choices=("pyocd", "openocd"), required=True)
    p.add_argument("--dry-run", action="store_true", help="only print the command")
    p.set_defaults(func=_flash)


RUN_DESCRIPTION = """\
Build (cached) and start the host firmware's loop executable (a fixed-point artifact: its integer loop, the law it
certifies).

Without --input the loop reads stdin and answers each line with one line on stdout, flushed at once::

  (first)       gainlink-loop NAME sha256:HEX n m p q law=LAW variant=VARIANT wire=4
  y0.. r0.. [s0..]  the samples, the references (and a scheduled law's external signals; numbers separated by
                spaces, tabs or commas; nan, inf allowed) -> step and the step's record: the law's fields in
                order (status, flags, saturation, commands, a fixed-point law's words, the state), integers in
                decimal, floats round-trip
  idle          -> idle and the record             a period without a sample (the watchdog)
  reset         -> reset and the record            the law restarts from its initial state
  stage, crc    -> stage STATUS, crc 0xHEX         re-stage the built-in gain set through the law's checks; its CRC
  other lines   -> error ...                       nothing changes and the loop goes on; the exit status is 2 at
                                                   the end of stdin, else 0

Ctrl-C stops the loop (exit status 130); a SIGTERM to the command stops it too (exit status 0).

With --input, replay a CSV (columns y0.., r0.., optionally t) through the loop and write the replay CSV (fixed
point: after a '# numeric=q31|q15' line, as `gainlink replay` writes it).

With a Cortex-M --target (or --board), run the image in QEMU as a bus node on its UART, served as a TCP socket:
--mavlink tcp:HOST:PORT, or --can with an slcan configuration (channel socket://HOST:PORT)."""


def _add_run_parser(sub) -> None:
    p = sub.add_parser(
        "run",
        help="run the firmware for an artifact (host build, or a Cortex-M image in QEMU)",
        description=RUN_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("artifact", help="gains.json")
    p.add_argument(
        "--target",
        choices=tuple(TARGETS),
        default="host",
        help="host (default) or a Cortex-M core (the image in QEMU, on its UART)",
    )
    p.add_argument("--board", choices=tuple(BOARDS), help=_BOARD_HELP)
    p.add_argument(
        "--flash-dir",
        help="with a Cortex-M target: the image's flash (persisted parameters; default "
        "flash-BOARD beside the artifact)",
    )
    p.add_argument("--input", help="replay input CSV; without it stdin/stdout are passed to the executable")
    p.add_argument("--output", help="replay output CSV (default: stdout)")
    # Transport options go here, one argument each (--can CONFIG, --mavlink URL), dispatched in _run.
    p.add_argument(
        "--can", metavar="CONFIG", help="run the CAN node on a python-can bus (TOML/JSON file or inline JSON)"
    )
    p.add_argument(
        "--mavlink",
        metavar="URL",
        help="run the MAVLink app (parameter server + HIL link) on "
        "udpin:HOST:PORT or udpout:HOST:PORT; with a Cortex-M target: tcp:HOST:PORT (the image's UART)",
    )
    p.add_argument(
        "--param-file", help="with --mavlink: persisted parameters (default: mavlink_params.txt beside the artifact)"
    )
    p.add_argument(
        "--signing-key",
        metavar="FILE",
        help="with --mavlink: MAVLink 2 signing key file (gainlink mavlink "
        "keygen); PARAM_SET, COMMAND_LONG and HIL samples must then be signed with it",
    )
    p.add_argument(
        "--from-artifact",
        action="store_true",
        help="with --mavlink: start on the artifact's gain set even when a set persisted by an earlier upload is "
        "stored (the param file or the image's flash: kept until the next persist); without it the persisted set "
        "runs, and the start-up line says which (gains=persisted|artifact crc32=...)",
    )
    p.set_defaults(func=_run)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``firmware build|flash|run`` and ``pil run``."""
    fw = subparsers.add_parser("firmware", help="build, flash or run the firmware")
    fw_sub = fw.add_subparsers(dest="firmware_command", metavar="ACTION", parser_class=type(fw))
    fw_sub.required = True
    _add_build_parser(fw_sub)
    _add_flash_parser(fw_sub)
    _add_run_parser(fw_sub)

    pil = subparsers.add_parser("pil", help="processor-in-the-loop: firmware in QEMU, plant in Python")
    pil_sub = pil.add_subparsers(dest="pil_command", metavar="ACTION", parser_class=type(pil))
    pil_sub.required = True
    p = pil_sub.add_parser(
        "run",
        help="close the loop with a Cortex-M image in QEMU",
        description="Run a Cortex-M image in QEMU against a plant simulated in Python, one "
        "sample per semihosting FIFO round trip; prints a summary (--json: the JSON pil.json holds). A fixed-point "
        "artifact runs its integer "
        "image; the summary's fixed_point block says whether it equals the bit-exact model on the samples it "
        "received and its deviation from the float64 law with the quantised coefficients beside the certified "
        "bound. A scheduled artifact runs its scheduled image (gl_sched_step, sigma from its output or "
        "--schedule-signal); the summary's scheduled block says whether every record equals the float32 model's "
        "and the host C's, and how often sigma was held, clipped or rate-limited.",
    )
    p.add_argument("artifact", help="gains.json")
    p.add_argument(
        "--plant",
        default="artifact",
        help="'artifact' (the artifact's discrete model; alias 'linear') or a gainlink.hil plant name",
    )
    p.add_argument("--steps", type=int, required=True, help="number of samples")
    p.add_argument(
        "--target",
        choices=CORTEX_M_TARGETS,
        help="the core whose image runs (default cortex-m4, or the core of --board)",
    )
    p.add_argument("--board", choices=tuple(BOARDS), help=_BOARD_HELP)
    p.add_argument(
        "--reference",
        type=float,
        nargs="+",
        help="constant absolute reference (q values; default: the tracked outputs at the operating point)",
    )
    p.add_argument("--x0", type=float, nargs="+", help="initial plant state (n values)")
    p.add_argument(
        "--schedule-signal",
        action="append",
        metavar="NAME=START[,END]",
        help="a scheduled artifact's external scheduling signal: constant, or a linear ramp over the run",
    )
    p.add_argument("--out", help="folder for pil.csv, pil.json and twin.png (the run minus its float64 twin)")
    p.add_argument("--json", action="store_true", help="print the JSON summary (what pil.json holds) instead")
    p.set_defaults(func=_pil)
