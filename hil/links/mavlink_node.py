"""A controller node in Python speaking the gainlink MAVLink HIL link: the float64 reference of any law on UDP.

``python -m gainlink.hil.links.mavlink_node ARTIFACT --url udpin:127.0.0.1:14560`` answers like the
firmware's ``gainlink_mavlink`` does on its HIL link (DEBUG_FLOAT_ARRAY ``GL_SAMPLE``/``GL_RESET``/
``GL_IDLE`` in, the sample ``y, r`` then the law's external scheduling signals; HIL_ACTUATOR_CONTROLS out with the
sample's ``time_usec`` and the step's flags), with the artifact's law's float64 reference
(:func:`gainlink.laws.law_of`) as the law. The bridge uses it as ``controller = "reference"`` with the
``mavlink`` transport: a real peer process on a real link, without a C toolchain. It serves no parameters.
"""

from __future__ import annotations

import argparse
import signal
import socket
import sys
from typing import Any

import numpy as np
from gainlink.laws import flags as status_flags
from gainlink.laws import law_of
from gainlink.shipping.artifact import load
from pymavlink.dialects.v20 import common as mavlink2

from .mavlink import ARRAY_IDLE, ARRAY_RESET, ARRAY_SAMPLE, flags_of

WATCHDOG_PERIODS = 10  # as the firmware's default (GL_WATCHDOG_PERIODS_DEFAULT)


def serve(artifact: Any, *, url: str, out: Any = sys.stdout) -> int:
    """Run the node until SIGTERM/SIGINT; returns the exit status."""
    parts = url.split(":")
    if len(parts) != 3 or parts[0] != "udpin":
        print(f"gainlink.hil.links.mavlink_node: expected udpin:HOST:PORT, got {url!r}", file=sys.stderr)
        return 2
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind((parts[1], int(parts[2])))
    sock.settimeout(0.2)
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=mavlink2.MAV_COMP_ID_AUTOPILOT1)
    law = law_of(artifact)
    ctl = law.reference(artifact)
    m, p, q, e = artifact.m, artifact.p, artifact.q, len(law.externals(artifact))
    safe = law.safe_command(artifact)
    u, idle = safe.copy(), 0
    stop: list[int] = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    wire = f"law=float64 wire={status_flags.WIRE_VERSION}"
    print(
        f"gainlink-mavlink {artifact.name} sha256:{artifact.sha256} (python reference) {url} {wire}",
        file=out,
        flush=True,
    )
    try:
        while not stop:
            try:
                data, addr = sock.recvfrom(2048)
            except (TimeoutError, InterruptedError):
                continue
            try:
                msgs = mav.parse_buffer(bytearray(data)) or []
            except mavlink2.MAVError:
                continue
            for msg in msgs:
                if msg.get_msgId() != mavlink2.MAVLINK_MSG_ID_DEBUG_FLOAT_ARRAY:
                    continue
                bits, sat = 0, 0
                values = np.asarray(msg.data, dtype=np.float32).astype(np.float64)
                if msg.array_id == ARRAY_SAMPLE:
                    step = ctl.step(values[:p], values[p : p + q], values[p + q : p + q + e])
                    u, idle = np.asarray(step.u, dtype=float), 0
                    bits, sat = step.flags, step.sat
                elif msg.array_id == ARRAY_RESET:
                    ctl.reset()
                    u, idle, bits = safe.copy(), 0, status_flags.RESET
                elif msg.array_id == ARRAY_IDLE:
                    idle += 1
                    if idle >= WATCHDOG_PERIODS:
                        u, bits = safe.copy(), status_flags.WATCHDOG
                else:
                    continue
                controls = np.zeros(16, dtype=np.float32)
                controls[:m] = u
                flags = flags_of(bits, sat)  # status at bits 16-31, saturation at 32-47
                reply = mavlink2.MAVLink_hil_actuator_controls_message(msg.time_usec, controls.tolist(), 0, flags)
                sock.sendto(reply.pack(mav), addr)
    finally:
        sock.close()
    return 0


def main(argv: list[str] | None = None) -> int:
    """Command line: ``ARTIFACT --url udpin:HOST:PORT``."""
    parser = argparse.ArgumentParser(
        prog="python -m gainlink.hil.links.mavlink_node", description=__doc__.splitlines()[0]
    )
    parser.add_argument("artifact")
    parser.add_argument("--url", required=True, help="udpin:HOST:PORT")
    args = parser.parse_args(argv)
    return serve(load(args.artifact), url=args.url)


if __name__ == "__main__":
    sys.exit(main())
