"""Benchmark: verified MAVLink parameter sets per second against the firmware app, on loopback.

A 100-parameter gain set (the first 100 REAL32 gains of the Wood-Berry column's firmware) is set and
every echo verified, with the uploader's bounded window (16 in flight) and, as the baseline measured
in the same run, one parameter at a time (set, wait for the echo, next: how MAVProxy paces). Each
round writes values different from the previous round's, so every set really changes the staged set.
Also reports the end-to-end ``upload()`` of a retuned Wood-Berry artifact (read, diff, set, commit).

Prints one JSON object. Usage: ``python bench/mavlink_upload.py [--rounds N]``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
import tomllib
from pathlib import Path

from _setups import free_udp_port

ROOT = Path(__file__).resolve().parents[1]
TARGET = 5000.0


def wood_berry(spec: dict, params: int):
    """The Wood-Berry design, its firmware app and the first ``params`` REAL32 gains of its parameter table."""
    from gainlink.firmware.mavlink_app import mavlink_executable
    from gainlink.laws import design as design_spec
    from gainlink.mavlink.params import REAL32, firmware_params
    from gainlink.shipping.artifact import from_dict
    from gainlink.spec import parse_spec

    art = from_dict(design_spec(parse_spec(spec)).artifact)
    gains = [s for s in firmware_params(art) if s.ptype == REAL32][:params]
    if len(gains) < params:
        raise SystemExit(f"the Wood-Berry firmware has only {len(gains)} REAL32 parameters")
    return gains, mavlink_executable(art)


def set_rates(link, gains: list, rounds: int) -> dict[str, list[float]]:
    """Verified parameters per second of each round, windowed (16 in flight) and sequential, each round writing
    new values; the compiled values are set back at the end."""
    from gainlink.mavlink.params import REAL32, Encoding
    from gainlink.mavlink.session import ParamSession

    results: dict[str, list[float]] = {"windowed": [], "sequential": []}
    for round_ in range(rounds):
        for mode, window in (("windowed", 16), ("sequential", 1)):
            session = ParamSession(link, target_system=1, target_component=1, encoding=Encoding.BYTEWISE, window=window)
            scale = 1.0 + 0.01 * (2 * round_ + (mode == "sequential") + 1)
            items = [(g.name, REAL32, float(g.value) * scale + 1e-3) for g in gains]
            t0 = time.perf_counter()
            out = session.set(items)
            dt = time.perf_counter() - t0
            if not out.ok or len(out.verified) != len(items):
                raise SystemExit(f"{mode} upload did not verify: {out}")
            results[mode].append(len(items) / dt)
    session = ParamSession(link, target_system=1, target_component=1, encoding=Encoding.BYTEWISE)
    session.set([(g.name, REAL32, float(g.value)) for g in gains])
    return results


def retuned_upload(spec: dict, port: int):
    """``upload()`` of the Wood-Berry design retuned (bryson_u_max / 1.7) to the app on ``port``: read, diff, set,
    commit."""
    from gainlink.laws import design as design_spec
    from gainlink.mavlink.upload import upload
    from gainlink.shipping import artifact as artifact_mod
    from gainlink.spec import parse_spec

    spec = dict(spec, controller=dict(spec["controller"]))
    spec["controller"]["bryson_u_max"] = [v / 1.7 for v in spec["controller"]["bryson_u_max"]]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "gains.json"
        artifact_mod.write(path, design_spec(parse_spec(spec)).artifact)
        retuned = artifact_mod.load(path)
    return upload(retuned, connect=f"udpout:127.0.0.1:{port}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=15)
    parser.add_argument("--params", type=int, default=100)
    args = parser.parse_args()

    from gainlink.firmware.mavlink_app import MavlinkFirmware
    from gainlink.mavlink.link import MavLink

    spec = tomllib.loads((ROOT / "examples" / "wood_berry.toml").read_text())
    gains, exe = wood_berry(spec, args.params)
    port = free_udp_port()
    fw = MavlinkFirmware(exe, url=f"udpin:127.0.0.1:{port}").start()
    try:
        with MavLink(f"udpout:127.0.0.1:{port}") as link:
            link.wait_heartbeat(timeout=5)
            results = set_rates(link, gains, args.rounds)
        full = retuned_upload(spec, port)
    finally:
        fw.stop()

    windowed = statistics.median(results["windowed"])
    sequential = statistics.median(results["sequential"])
    print(
        json.dumps(
            {
                "benchmark": "mavlink_upload",
                "link": "UDP loopback, gainlink_mavlink firmware app",
                "params": args.params,
                "rounds": args.rounds,
                "verified_params_per_s": round(windowed, 1),
                "baseline_sequential_params_per_s": round(sequential, 1),
                "ratio_vs_sequential": round(windowed / sequential, 2),
                "window": 16,
                "target_params_per_s": TARGET,
                "meets_target": windowed >= TARGET,
                "full_upload": {
                    "artifact": "wood_berry retuned (bryson_u_max / 1.7)",
                    "changed": len(full.changes),
                    "verified": full.verified,
                    "committed": full.committed,
                    "seconds": round(full.seconds, 4),
                },
            },
            indent=2,
        )
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
