"""Benchmark: the Cortex-M4F image on its emulated UART (QEMU) against the host apps over UDP, in one run.

Round trips: one sample in flight (lockstep), the pendulum artifact's own discrete plant in numpy, the
transports the HIL bridge uses: MAVLink (DEBUG_FLOAT_ARRAY -> HIL_ACTUATOR_CONTROLS) and CAN through slcan
(python-can ``slcan`` on ``socket://``, classic float32 frames) to the image in QEMU on each board, and the
baselines measured beside them: the host MAVLink app over UDP and the host CAN app over udp_multicast
(classic frames, the slcan layout). Reports round trips/s and latency p50/p99 for each, and each UART link's
ratio to its host baseline, and whether its commands equalled the host MAVLink app's (same C, same samples).

Realtime: the bridge's realtime mode (cart-pendulum FMU, ``--realtime-s`` seconds each, default 30) at
descending loop rates; the highest rate with no deadline miss is each link's answer. Rates whose period is
below the link's median round trip are skipped (they cannot hold) and listed as such.

Prints one JSON object. Usage: ``python bench/target_uart.py [--steps N] [--realtime-s S] [--boards B ...]``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _setups import free_udp_port

ROOT = Path(__file__).resolve().parents[1]
RATES_HZ = (1000, 500, 200, 100, 50, 25, 10)


def _round_trips(art, transport, steps: int) -> tuple[dict, np.ndarray]:
    """``steps`` lockstep round trips through ``transport`` (open); statistics and the commands."""
    x = np.zeros(art.n)
    x[min(2, art.n - 1)] = 0.05
    r = np.full(art.q, 0.2)
    u = np.zeros(art.m)
    U = np.zeros((steps, art.m))
    lat = np.zeros(steps)
    t0 = time.perf_counter()
    for k in range(steps):
        y = (art.Cd @ x + art.Dd @ u).astype(np.float32).astype(float)
        t1 = time.perf_counter_ns()
        transport.send_frames(transport.encode_sample(seq=k + 1, y=y, r=r))
        while True:
            c = transport.receive_command(timeout=5.0)
            if c is None:
                raise RuntimeError(f"no command for sample {k}")
            if c.seq == (k + 1) % transport.seq_modulo:
                break
        lat[k] = (c.t_ns - t1) / 1e3
        u = U[k] = c.u
        x = art.Ad @ x + art.Bd @ u
    wall = time.perf_counter() - t0
    stats = {
        "round_trips_per_s": round(steps / wall, 1),
        "latency_us_p50": round(float(np.median(lat)), 1),
        "latency_us_p99": round(float(np.percentile(lat, 99)), 1),
        "steps": steps,
    }
    return stats, U


def _links(art, *, board: str):
    """(name, controller factory, transport config) of every link measured, baselines first."""
    from gainlink.firmware.uart import free_tcp_port

    return [
        ("host_mavlink_udp", "firmware", {"kind": "mavlink", "port": free_udp_port()}),
        (
            "host_can_udp_multicast",
            "firmware",
            {"interface": "udp_multicast", "channel": "239.74.163.71", "hop_limit": 0},
        ),
        (f"image_mavlink_uart_{board}", "qemu", {"kind": "mavlink", "url": f"tcp:127.0.0.1:{free_tcp_port()}"}),
        (
            f"image_slcan_uart_{board}",
            "qemu",
            {"interface": "slcan", "channel": f"socket://127.0.0.1:{free_tcp_port()}"},
        ),
    ]


def _peer(kind: str, *, art, transport, board: str, stack):
    """Start the controller of a link the way the bridge does (host process, or the image in QEMU)."""
    from gainlink.hil.loop.controller import ControllerProcess, controller_argv, qemu_peer

    if kind == "qemu":
        peer = qemu_peer(artifact=art, transport=transport, board=board, elf=None, duration_s=600)
        stack.callback(peer.close)
        peer.start()
        transport.open()
        stack.callback(transport.close)
        return peer
    transport.open()
    stack.callback(transport.close)
    peer = ControllerProcess(controller_argv("firmware", artifact=art, artifact_path=None, transport=transport))
    stack.callback(peer.close)
    peer.start()
    return peer


def measure_round_trips(art, *, boards: list[str], steps: int) -> dict:
    from contextlib import ExitStack

    from gainlink.hil.links.config import transport_from_config

    out: dict = {}
    reference = None
    for board in boards:
        for name, kind, cfg in _links(art, board=board):
            if name in out:
                continue
            with ExitStack() as stack:  # a fresh controller per link: every run starts from the same loop state
                transport = transport_from_config(cfg, artifact=art)
                _peer(kind, art=art, transport=transport, board=board, stack=stack)
                stats, U = _round_trips(art, transport, steps)
            if reference is None:
                reference = U
            stats["commands_equal_host_mavlink"] = bool(np.array_equal(U, reference))
            out[name] = stats
    for name, stats in out.items():
        base = "host_mavlink_udp" if "mavlink" in name else "host_can_udp_multicast"
        if name.startswith("image_"):
            stats["ratio_to_" + base] = round(stats["round_trips_per_s"] / out[base]["round_trips_per_s"], 4)
    return out


def realtime_scenario(art_path: Path, transport: dict, *, controller: str, board: str, rate_hz: float, duration: float):
    from gainlink.hil.loop.scenario import parse_scenario

    data = {
        "name": f"rt_{rate_hz:g}hz",
        "artifact": str(art_path),
        "duration": duration,
        "mode": "realtime",
        "controller": controller,
        "period": 1.0 / rate_hz,
        "peer_timeout": 5.0,
        "seed": 3,
        "twin": False,
        "plant": {"kind": "fmu", "fmu": "cart_pendulum", "outputs": ["x", "theta"]},
        "transport": transport,
        "initial_state": {"theta": 0.05},
    }
    if controller == "qemu":
        data["board"] = board
    return parse_scenario(data, path=art_path.parent / "scenario.toml")


def highest_rate(art, art_path: Path, *, kind: str, cfg: dict, board: str, p50_us: float, seconds: float) -> dict:
    """The highest of RATES_HZ whose realtime run of ``seconds`` has no deadline miss."""
    from gainlink.hil.loop.bridge import run_scenario

    tried, skipped = [], []
    for rate in RATES_HZ:
        if 1e6 / rate < p50_us:
            skipped.append(rate)
            continue
        # the plant advances Ts per tick whatever the period: only the wall-clock pacing changes
        res = run_scenario(
            realtime_scenario(
                art_path, cfg, controller=kind, board=board, rate_hz=rate, duration=seconds * rate * art.Ts
            )
        )
        m = res.metrics
        tried.append(
            {
                "rate_hz": rate,
                "steps": m["steps"],
                "deadline_misses": m["deadline_misses"],
                "overruns": m.get("overruns"),
                "latency_us_p99": m["latency_us"]["p99"],
                "complete": res.complete,
            }
        )
        if res.complete and m["deadline_misses"] == 0:
            return {"highest_rate_hz_without_miss": rate, "tried": tried, "skipped_above_p50": skipped}
    return {"highest_rate_hz_without_miss": None, "tried": tried, "skipped_above_p50": skipped}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000, help="lockstep round trips per link")
    parser.add_argument("--realtime-s", type=float, default=30.0, help="length of each realtime run [s]")
    parser.add_argument("--boards", nargs="+", default=["mps2-an386", "netduinoplus2"])
    parser.add_argument("--realtime-board", default="mps2-an386", help="board of the realtime search")
    args = parser.parse_args()

    import logging

    from gainlink.laws import design as design_spec
    from gainlink.shipping import artifact as artifact_mod
    from gainlink.spec import load_spec

    logging.disable(logging.WARNING)
    with tempfile.TemporaryDirectory() as tmp:
        art_path = Path(tmp) / "gains.json"
        art = design_spec(load_spec(ROOT / "examples" / "pendulum.toml")).artifact
        artifact_mod.write(art_path, art)
        art = artifact_mod.load(art_path)
        rt = measure_round_trips(art, boards=args.boards, steps=args.steps)
        realtime = {}
        for name, kind, cfg in _links(art, board=args.realtime_board):
            if name.startswith("image_") or name == "host_mavlink_udp":
                realtime[name] = highest_rate(
                    art,
                    art_path,
                    kind=kind,
                    cfg=cfg,
                    board=args.realtime_board,
                    p50_us=rt[name]["latency_us_p50"],
                    seconds=args.realtime_s,
                )
    result = {
        "benchmark": "target_uart",
        "artifact": "pendulum (examples/pendulum.toml), n=4 m=1 p=2 q=1",
        "cpus": os.cpu_count(),
        "load_avg_1min": round(os.getloadavg()[0], 2),
        "round_trips": rt,
        "realtime_seconds_each": args.realtime_s,
        "realtime_board": args.realtime_board,
        "realtime": realtime,
    }
    json.dump(result, sys.stdout, indent=2)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
