"""Benchmark: lockstep HIL steps per second over MAVLink (DEBUG_FLOAT_ARRAY -> HIL_ACTUATOR_CONTROLS).

A closed loop of the pendulum artifact's own discrete plant (numpy, x+ = Ad x + Bd u) against the
``gainlink_mavlink`` firmware app over UDP loopback, one sample in flight (lockstep). The baseline,
measured in the same run, is the same loop with the same C control law called in-process through
ctypes (``gainlink.engines.native.NativeLoop.step``): the ratio is what the link costs. The first
steps of both runs must agree (the firmware's commands equal the in-process library's).
Also runs the HIL bridge (``gainlink hil run`` machinery, cart-pendulum FMU) over MAVLink for the
same plant time and reports its steps/s.

Every measurement is made twice, interleaved in the same run against the same baseline: the default
link (both ends block in select/poll while waiting, pinned to one shared CPU as the bridge does in
lockstep) and the busy-poll variant (transport ``busy_poll_us``, firmware ``--spin-us``: both ends
read without sleeping for that long before blocking; one busy CPU each, fewer wake-ups). The busy-poll
commands must equal the default's.
Target: >= 10,000 lockstep steps/s; ``meets_target`` is true when either variant reaches it and
``meets_target_with`` says which.

Prints one JSON object. Usage: ``python bench/mavlink_hil.py [--steps N] [--busy-poll-us N]``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _setups import free_udp_port

ROOT = Path(__file__).resolve().parents[1]
TARGET = 10000.0


def _loop(art, controller_step, steps: int) -> tuple[float, np.ndarray]:
    x = np.zeros(art.n)
    x[min(2, art.n - 1)] = 0.05
    r = np.full(art.q, 0.2, dtype=np.float32)
    u = np.zeros(art.m)
    U = np.zeros((steps, art.m))
    t0 = time.perf_counter()
    for k in range(steps):
        y = (art.Cd @ x + art.Dd @ u).astype(np.float32)
        u = controller_step(k, y, r)
        U[k] = u
        x = art.Ad @ x + art.Bd @ u
    return steps / (time.perf_counter() - t0), U


def _links(art, busy_poll_us: int) -> dict:
    """The default and busy-poll MAVLink links, each to a firmware of its own on a free UDP port."""
    from gainlink.hil.links.mavlink import MavlinkTransport

    links = {}
    for variant, busy_us in (("default", 0), ("busy_poll", busy_poll_us)):
        port = free_udp_port()
        links[variant] = MavlinkTransport(
            url=f"udpout:127.0.0.1:{port}",
            controller_url=f"udpin:127.0.0.1:{port}",
            n_inputs=art.m,
            n_outputs=art.p,
            n_refs=art.q,
            ts=art.Ts,
            busy_poll_us=busy_us,
        )
    return links


def _over(link):
    """A controller step through ``link``: one sample out, its command back (lockstep)."""

    def step(k, y, r):
        link.send_frames(link.encode_sample(seq=k, y=y, r=r))
        c = link.receive_command(timeout=1.0)
        if c is None or c.seq != k:
            raise SystemExit(f"no command for step {k}")
        return c.u

    return step


def _measure(art, exe, args) -> tuple[dict, float, bool]:
    """Steps/s of both links and of the in-process library, interleaved ``args.repeats`` times; the largest
    command difference link vs in-process over the first 500 steps; whether busy-poll equals default."""
    from gainlink.engines.native import NativeLoop
    from gainlink.firmware.mavlink_app import MavlinkFirmware
    from gainlink.hil.loop.scheduler import Placement, resolve_affinity

    native = NativeLoop(art)
    links = _links(art, args.busy_poll_us)
    rates = {"default": [], "busy_poll": [], "in_process": []}
    U = {}
    firmware = {
        "default": MavlinkFirmware(exe, url=links["default"].controller_url),
        "busy_poll": MavlinkFirmware(exe, url=links["busy_poll"].controller_url, busy_poll_us=args.busy_poll_us),
    }
    cpus = sorted(os.sched_getaffinity(0))
    with firmware["default"], links["default"], firmware["busy_poll"], links["busy_poll"]:
        for _ in range(args.repeats):
            for variant, link in links.items():
                link.send_frames(link.encode_reset(seq=0))
                link.receive_command(timeout=1.0)
                # The bridge's own placement (affinity = "auto"): one CPU for both, or one each when spinning.
                where = resolve_affinity("auto", mode="lockstep", busy_poll=variant == "busy_poll", cpus=cpus)
                with Placement(where, peer_pid=firmware[variant].proc.pid):
                    rate, U[variant] = _loop(art, _over(link), args.steps)
                rates[variant].append(rate)
            native.reset()
            rate_n, U_n = _loop(art, lambda k, y, r: native.step(y.astype(float), r.astype(float)).u, args.steps)
            rates["in_process"].append(rate_n)
    agree = float(np.max(np.abs(U["default"][:500] - U_n[:500])))
    return rates, agree, bool(np.array_equal(U["busy_poll"], U["default"]))


def _bridge_runs(path: Path, busy_poll_us: int) -> dict:
    """The HIL bridge (cart-pendulum FMU) over MAVLink, 5 s of plant time, with each link variant."""
    from gainlink.hil.loop.bridge import run_scenario
    from gainlink.hil.loop.scenario import parse_scenario

    bridge = {}
    for variant, extra in (("default", {}), ("busy_poll", {"busy_poll_us": busy_poll_us})):
        scen = parse_scenario(
            {
                "name": "bench_mavlink",
                "artifact": str(path),
                "duration": 5.0,
                "mode": "lockstep",
                "controller": "firmware",
                "twin": False,
                "seed": 1,
                "plant": {"kind": "fmu", "fmu": "cart_pendulum", "outputs": ["x", "theta"]},
                "transport": {"kind": "mavlink", "port": free_udp_port(), **extra},
                "initial_state": {"theta": 0.1},
            },
            path=path.parent / "scenario.toml",
        )
        bridge[variant] = run_scenario(scen)
    return bridge


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument(
        "--busy-poll-us", type=int, default=200, help="busy_poll_us / --spin-us of the busy-poll variant"
    )
    args = parser.parse_args()

    from gainlink.firmware.mavlink_app import mavlink_executable
    from gainlink.laws import design as design_spec
    from gainlink.shipping import artifact as artifact_mod
    from gainlink.spec import load_spec

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "gains.json"
        artifact_mod.write(path, design_spec(load_spec(ROOT / "examples" / "pendulum.toml")).artifact)
        art = artifact_mod.load(path)
        rates, agree, busy_equals_default = _measure(art, mavlink_executable(art), args)
        bridge = _bridge_runs(path, args.busy_poll_us)

    base = statistics.median(rates["in_process"])
    mav = {v: statistics.median(rates[v]) for v in ("default", "busy_poll")}
    meeting = [v for v in ("default", "busy_poll") if mav[v] >= TARGET]

    def report(variant: str) -> dict:
        return {
            "steps_per_s": round(mav[variant], 1),
            "all_repeats_steps_per_s": [round(x, 1) for x in rates[variant]],
            "ratio_vs_in_process": round(mav[variant] / base, 3),
            "round_trip_us": round(1e6 / mav[variant], 1),
            "bridge_fmu_steps_per_s": round(bridge[variant].metrics["steps_per_s"], 1),
            "bridge_complete": bridge[variant].complete,
        }

    print(
        json.dumps(
            {
                "benchmark": "mavlink_hil_lockstep",
                "link": "UDP loopback: DEBUG_FLOAT_ARRAY -> gainlink_mavlink -> HIL_ACTUATOR_CONTROLS",
                "steps": args.steps,
                "repeats": args.repeats,
                "baseline_in_process_steps_per_s": round(base, 1),
                "default": report("default"),
                "busy_poll": {"busy_poll_us": args.busy_poll_us, **report("busy_poll")},
                "max_abs_du_vs_in_process_first_500": agree,
                "busy_poll_commands_equal_default": busy_equals_default,
                "target_steps_per_s": TARGET,
                "meets_target": bool(meeting),
                "meets_target_with": meeting,
                "load_average_1min": round(os.getloadavg()[0], 2),
                "cpus": os.cpu_count(),
            },
            indent=2,
        )
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
