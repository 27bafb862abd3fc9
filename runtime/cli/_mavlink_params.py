"""``gainlink mavlink params`` (a vehicle's parameters, an artifact's, or a ``.params`` file's: listed, or written as
QGroundControl's ``.params`` file) and ``mavlink upload --dry-run --against FILE.params`` (the diff an upload would
make to the vehicle whose parameters the file holds). :mod:`gainlink.mavlink.params_file` does the work."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import GainlinkError, ParameterError


def params(args: argparse.Namespace) -> int:
    """List or write the parameters of the vehicle at ``--connect``, of an artifact, or of a ``.params`` file."""
    from gainlink.fileio import atomic_write_text, prepare_output_dir
    from gainlink.mavlink.params_file import render_params_file

    if (args.source is None) == (args.connect is None):
        raise GainlinkError("mavlink params: give a vehicle (--connect URL) or a file (gains.json or .params), one")
    if args.out and Path(args.out).is_dir():
        raise GainlinkError(f"--out {args.out} is a directory")
    if args.out:
        prepare_output_dir(Path(args.out).parent)
    if args.connect is not None:
        entries, law, vehicle = _vehicle_entries(args)
    else:
        entries, law, vehicle = _file_entries(args)
    if args.out:
        from gainlink.version import __version__

        text = render_params_file(entries, law=law, vehicle=vehicle, version=f"gainlink {__version__}")
        atomic_write_text(args.out, text)
        print(f"wrote {args.out}: {len(entries)} parameters of {vehicle or 'the file'} (QGroundControl .params)")
        return 0
    from gainlink.mavlink.params_file import format_value

    for e in entries:
        print(f"{e.name:<16} {format_value(e.value, e.ptype)}")
    return 0


def _vehicle_entries(args: argparse.Namespace):
    """Every parameter the vehicle lists (PARAM_REQUEST_LIST), the law its HEARTBEAT names, and its id."""
    from gainlink.mavlink.link import MavLink
    from gainlink.mavlink.params import Encoding
    from gainlink.mavlink.params_file import ParamsEntry
    from gainlink.mavlink.session import ParamSession
    from gainlink.mavlink.signing import read_key
    from gainlink.mavlink.upload import detect_encoding
    from gainlink.shipping.law_c import label_of_id

    key = read_key(args.signing_key) if args.signing_key else None
    with MavLink(args.connect, signing_key=key) as link:
        hb = link.wait_heartbeat(timeout=args.heartbeat_timeout)
        system, component = hb.get_srcSystem(), hb.get_srcComponent()
        session = ParamSession(link, target_system=system, target_component=component, encoding=Encoding.C_CAST)
        session.encoding = detect_encoding(session, autopilot=hb.autopilot)
        values = sorted(session.read_all().values(), key=lambda pv: pv.index)
    law = label_of_id(int(hb.custom_mode))
    entries = [ParamsEntry(system, component, pv.name, pv.value, pv.ptype) for pv in values]
    return entries, (law if not law.startswith("law ") else None), f"vehicle {system}/{component}"


def _file_entries(args: argparse.Namespace):
    """An artifact's parameters (as the gainlink firmware, or a mapping, holds them) or a ``.params`` file's."""
    from gainlink.mavlink.params_file import ParamsEntry, artifact_law, artifact_parameters, read_params_file

    source = Path(args.source)
    if source.suffix == ".params":
        pf = read_params_file(source)
        return list(pf.entries), pf.law, ""
    from gainlink.mavlink.params import load_mapping
    from gainlink.shipping.artifact import load

    artifact = load(source)
    mapping = load_mapping(args.mapping) if args.mapping else None
    specs = artifact_parameters(artifact, mapping)
    entries = [ParamsEntry(args.system, args.component, s.name, s.value, s.ptype) for s in specs]
    law = None if mapping is not None else artifact_law(artifact)
    return entries, law, f"{artifact.name} sha256:{artifact.sha256[:12]}"


def upload_against(args: argparse.Namespace) -> int:
    """``mavlink upload ARTIFACT --dry-run --against FILE.params``: the diff, as against the vehicle."""
    from gainlink.mavlink.params_file import read_params_file, session_for
    from gainlink.mavlink.upload import dry_run_against, format_changes
    from gainlink.shipping.artifact import load

    if not args.dry_run:
        raise ParameterError("--against diffs against a saved file only: give --dry-run (an upload needs --connect)")
    if args.connect:
        raise ParameterError("give --connect (a vehicle) or --against (its saved .params file), not both")
    artifact = load(args.artifact)
    saved = read_params_file(args.against)
    res = dry_run_against(artifact, session_for(saved, artifact), target=saved.target, mapping=args.mapping)
    for line in format_changes(res.changes):
        print(line)
    print(
        f"dry run against {args.against}: {len(res.changes)} parameter(s) would change, {res.unchanged} already "
        f"match (vehicle {res.vehicle.system}/{res.vehicle.component}"
        + ("" if saved.law else "; the file names no law: not checked")
        + ")"
    )
    return 0
