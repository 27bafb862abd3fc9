"""A controller node in Python speaking the gainlink CAN layout: the float64 reference of any law on the bus.

``python -m gainlink.hil.links.can_node ARTIFACT --config JSON`` behaves like the firmware's
``gainlink_can`` (same layout and encoding, the sample ``y, r`` then the law's external scheduling signals, the
step's flags in the status byte, same duplicate/stale handling, same ready line), with the artifact's law's float64
reference (:func:`gainlink.laws.law_of`) as the law. The bridge uses it as ``controller = "reference"``: a real
peer process on a real bus, without a C toolchain.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
from typing import Any

import numpy as np
from gainlink.laws import law_of
from gainlink.laws.flags import WIRE_VERSION
from gainlink.shipping.artifact import load

from .can import Assembler, FrameCodec, layout_from_config, open_link_buses


def serve(artifact: Any, config: dict, *, out: Any = sys.stdout) -> int:
    """Run the node until SIGTERM/SIGINT; returns the exit status."""
    fd = bool(config.get("fd", False))
    layout = layout_from_config(config, artifact=artifact)
    rx = Assembler(FrameCodec(layout.measurement, fd=fd))
    tx = FrameCodec(layout.command, fd=fd)
    ctl = law_of(artifact).reference(artifact)
    p, q = artifact.p, artifact.q
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    bus, out_bus = open_link_buses(config, controller=True)
    wire = f"law=float64 wire={WIRE_VERSION}"
    print(
        f"gainlink_can ready {artifact.name} sha256:{artifact.sha256} (python reference) {wire}", file=out, flush=True
    )
    last = None
    try:
        while not stop:
            msg = bus.recv(0.2)
            if msg is None:
                continue
            done = rx.feed(msg)
            if done is None:
                continue
            seq, vals, _status, _sat = done
            if last is not None and ((seq - last) & 0xFFFF == 0 or (seq - last) & 0xFFFF >= 0x8000):
                continue  # duplicate or stale sample, as the firmware app does
            v = vals.astype(np.float64)
            step = ctl.step(v[:p], v[p : p + q], v[p + q :])
            for frame in tx.encode(seq=seq, values=step.u, status=step.flags, sat=step.saturated):
                out_bus.send(frame)
            last = seq
    finally:
        if out_bus is not bus:
            out_bus.shutdown()
        bus.shutdown()
    return 0


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    ap = argparse.ArgumentParser(prog="python -m gainlink.hil.links.can_node")
    ap.add_argument("artifact")
    ap.add_argument("--config", required=True, help="python-can configuration as JSON")
    args = ap.parse_args(argv)
    return serve(load(args.artifact), json.loads(args.config))


if __name__ == "__main__":
    sys.exit(main())
