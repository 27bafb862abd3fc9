"""``gainlink mavlink``: upload a gain artifact to a vehicle, list its parameters, give it a signing key.

Exit status of ``upload``: 0 every set verified by its echo (on a gainlink node the commit confirmed by its
AUTOPILOT_VERSION uid; on another vehicle, which cannot show that its loop runs the set, the summary says so), and
persisted with ``--persist``; 2 nothing was changed (bad input, no heartbeat, missing parameter or one of another
type, other dimensions, an ``--encoding`` that contradicts the vehicle's, a vehicle that requires signing and was
given no ``--signing-key``); 3 the upload failed after writing and every changed parameter was restored; 4 the upload
failed and the rollback is incomplete. Without ``-v`` stderr carries nothing but an error's lines.
``setup-signing``: 0 the vehicle answers signed with the new key; 2 it does not (or bad input, no heartbeat).
"""

from __future__ import annotations

import argparse
import sys

SIGNING_HELP = (
    "MAVLink 2 signing key file (64 hex digits, from `gainlink mavlink keygen`): sign every request "
    "and take only answers signed with it"
)

EXIT_ROLLED_BACK = 3
EXIT_ROLLBACK_INCOMPLETE = 4


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``gainlink mavlink upload``, ``params``, ``setup-signing`` and ``keygen``."""
    p = subparsers.add_parser("mavlink", help="MAVLink parameter upload and listing")
    sub = p.add_subparsers(dest="mavlink_command", metavar="ACTION")
    sub.required = True
    _add_upload(sub)
    _add_params(sub)
    _add_setup_signing(sub)
    _add_keygen(sub)


def _add_upload(sub: argparse._SubParsersAction) -> None:
    up = sub.add_parser("upload", help="upload an artifact's gains (verified, rolled back on failure)")
    up.add_argument("artifact", help="gains.json")
    up.add_argument("--connect", help="pymavlink URL: udpout:HOST:PORT, udpin:HOST:PORT, /dev/ttyACM0")
    up.add_argument(
        "--against",
        metavar="FILE.params",
        help="with --dry-run, instead of --connect: diff against a vehicle's saved parameters (QGroundControl .params)",
    )
    up.add_argument("--mapping", help="TOML mapping of gains to the vehicle's own parameter names and types")
    up.add_argument("--persist", action="store_true", help="send MAV_CMD_PREFLIGHT_STORAGE and check the ack")
    up.add_argument("--dry-run", action="store_true", help="read and print the diff only")
    up.add_argument("--window", type=int, default=16, help="PARAM_SETs in flight (default 16)")
    up.add_argument("--timeout", type=float, default=0.25, help="seconds before a request is re-sent (default 0.25)")
    up.add_argument("--retries", type=int, default=10, help="re-sends per parameter (default 10)")
    up.add_argument("--heartbeat-timeout", type=float, default=5.0, help="seconds to wait for a heartbeat (default 5)")
    up.add_argument(
        "--encoding",
        choices=("auto", "bytewise", "c_cast"),
        default="auto",
        help="integer parameter encoding (default: from AUTOPILOT_VERSION / the autopilot type)",
    )
    up.add_argument("--signing-key", metavar="FILE", help=SIGNING_HELP)
    up.add_argument(
        "--target-system",
        type=int,
        metavar="N",
        help="upload to the vehicle with this system id (default: the first vehicle heard, not a ground station)",
    )
    up.add_argument("--target-component", type=int, metavar="N", help="and this component id (default: any)")
    up.set_defaults(func=_upload)


def _add_params(sub: argparse._SubParsersAction) -> None:
    ls = sub.add_parser(
        "params",
        help="list a vehicle's, an artifact's or a .params file's parameters, or write them as a QGroundControl "
        ".params file",
    )
    ls.add_argument("source", nargs="?", help="gains.json (the parameters it gives the firmware) or a .params file")
    ls.add_argument("--connect", help="pymavlink URL of the vehicle (PARAM_REQUEST_LIST)")
    ls.add_argument("--out", metavar="FILE.params", help="write them as QGroundControl's .params file")
    ls.add_argument("--mapping", help="with gains.json: the vehicle parameters a mapping TOML names instead")
    ls.add_argument("--system", type=int, default=1, help="with gains.json: the vehicle id written (default 1)")
    ls.add_argument("--component", type=int, default=1, help="with gains.json: the component id written (default 1)")
    ls.add_argument("--heartbeat-timeout", type=float, default=5.0, help="seconds to wait for a heartbeat (default 5)")
    ls.add_argument("--signing-key", metavar="FILE", help=SIGNING_HELP)
    ls.set_defaults(func=_params)


def _add_setup_signing(sub: argparse._SubParsersAction) -> None:
    ss = sub.add_parser("setup-signing", help="give a vehicle a signing key (SETUP_SIGNING) and check it signs with it")
    ss.add_argument("key", help="key file to give (from `gainlink mavlink keygen`)")
    ss.add_argument("--connect", required=True, help="pymavlink URL: tcp:HOST:PORT (the image's UART), a serial device")
    ss.add_argument(
        "--signing-key",
        metavar="FILE",
        help="the vehicle's current key file: sign the SETUP_SIGNING with it (a key change); without "
        "it the message goes unsigned, which a vehicle takes only on a trusted link (a cable)",
    )
    ss.add_argument("--heartbeat-timeout", type=float, default=5.0, help="seconds to wait for a heartbeat (default 5)")
    ss.set_defaults(func=_setup_signing)


def _add_keygen(sub: argparse._SubParsersAction) -> None:
    kg = sub.add_parser("keygen", help="write a new MAVLink 2 signing key file (64 hex digits, mode 0600)")
    kg.add_argument("out", help="key file to create (an existing file is not replaced)")
    kg.set_defaults(func=_keygen)


def _upload(args: argparse.Namespace) -> int:
    from gainlink.errors import ParameterError
    from gainlink.mavlink.params import Encoding
    from gainlink.mavlink.signing import read_key
    from gainlink.mavlink.upload import UploadFailed, format_changes, upload
    from gainlink.mavlink.upload_text import upload_summary
    from gainlink.shipping.artifact import load

    if args.against:
        from ._mavlink_params import upload_against

        return upload_against(args)
    if not args.connect:
        raise ParameterError("mavlink upload: give --connect URL (or, with --dry-run, --against FILE.params)")
    if args.window < 1 or args.retries < 0 or args.timeout <= 0:
        raise ParameterError("--window must be >= 1, --retries >= 0 and --timeout > 0")
    for name, value, low in (
        ("--target-system", args.target_system, 1),
        ("--target-component", args.target_component, 0),
    ):
        if value is not None and not low <= value <= 255:
            raise ParameterError(f"{name} must be {low}..255, not {value}")
    artifact = load(args.artifact)
    key = read_key(args.signing_key) if args.signing_key else None

    def show_diff(changes) -> None:
        for line in format_changes(changes):
            print(line)
        sys.stdout.flush()

    try:
        res = upload(
            artifact,
            connect=args.connect,
            mapping=args.mapping,
            persist=args.persist,
            dry_run=args.dry_run,
            window=args.window,
            timeout=args.timeout,
            retries=args.retries,
            heartbeat_timeout=args.heartbeat_timeout,
            encoding=None if args.encoding == "auto" else Encoding(args.encoding),
            on_diff=show_diff,
            signing_key=key,
            target_system=args.target_system,
            target_component=args.target_component,
        )
    except UploadFailed as exc:
        for line in exc.events:
            print(f"gainlink: {line}", file=sys.stderr)
        print(f"gainlink: error: {exc}", file=sys.stderr)
        return EXIT_ROLLED_BACK if exc.rolled_back else EXIT_ROLLBACK_INCOMPLETE
    print(upload_summary(artifact, res))
    return 0


def _params(args: argparse.Namespace) -> int:
    from ._mavlink_params import params

    return params(args)


def _setup_signing(args: argparse.Namespace) -> int:
    from gainlink.mavlink.keysetup import setup_signing
    from gainlink.mavlink.signing import read_key

    key = read_key(args.key)
    current = read_key(args.signing_key) if args.signing_key else None
    res = setup_signing(args.connect, key, current=current, heartbeat_timeout=args.heartbeat_timeout)
    print(
        f"vehicle {res.target[0]}/{res.target[1]} signs with the key in {args.key} "
        f"({'replaced its key' if res.replaced else 'its first key'}); give the same file to the ground tools "
        "(--signing-key)"
    )
    return 0


def _keygen(args: argparse.Namespace) -> int:
    from gainlink.mavlink.signing import new_key, write_key

    path = write_key(args.out, new_key())
    print(
        f"wrote a new signing key to {path} (mode 0600); give the same file to the vehicle "
        f"(gainlink firmware run --signing-key) and to the ground tools (--signing-key)"
    )
    return 0
