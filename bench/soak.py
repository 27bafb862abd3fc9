"""Soak: long HIL runs (FMU plant, CAN FD over udp_multicast, the firmware's gainlink_can): memory and books.

Two phases, each one long run with one bridge and one firmware process (the pendulum redesigned at 1 kHz,
the nonlinear cart-pendulum FMU):
  1. lockstep at full speed for --lockstep-minutes (default 30): the run is planned for three times the steps a
     short calibration run in the same process says fit (the baseline: `speed_vs_calibration`; at most 10
     million) and ended on time by stopping the firmware with SIGTERM (it exits cleanly with its summary; the
     one sample then in flight is `lost_at_stop`, not a loss of the link);
  2. real time at 1 kHz for --realtime-minutes (default 30), SCHED_FIFO and PM QoS when permitted.
Every --sample-s (default 10) seconds the resident memory (RSS) of the bridge (this process) and of the
firmware process is sampled; the JSON gives the samples and each process's least-squares slope (KiB/min,
first minute excluded). The bridge keeps the whole trace of a run in arrays sized for it; those filled step by
step (zero-initialised numpy arrays, touched as the run records) grow its RSS by design:
`bridge_trace_growth_kib_per_min` is that growth (their bytes per step x steps per minute) and
`bridge_rss_slope_minus_trace` what is left. Books: every sample the bridge sent is answered, lost or late
(`unaccounted_bridge`), every frame the bridge sent was used by the firmware or dropped by the kernel
(`unaccounted_firmware`, from the firmware's exit summary). Every deadline miss of the real-time phase is
explained from the trace: the bridge itself woke late (its tick started after the deadline: the machine
stalled it) or the command came later than one period.

    .venv/bin/python bench/soak.py [--lockstep-minutes 30] [--realtime-minutes 30] [--sample-s 10]

Runs at nice 10 (the machine is shared); the real-time phase runs under SCHED_FIFO where permitted.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from _setups import multicast_transport, pendulum_1khz
from gainlink.hil.links.can_firmware import firmware_can_executable
from gainlink.hil.loop.bridge import run_scenario
from gainlink.hil.loop.scenario import parse_scenario
from gainlink.hil.plants.build import build_fmu
from gainlink.shipping import artifact as artifact_mod

PAGE_KIB = os.sysconf("SC_PAGE_SIZE") / 1024
# Recorder arrays the bridge fills step by step from zeros (hil/run/bridge.py _Recorder): Y (p), U (m), SAT (m,
# bool), GOT (bool), TICK, ST (int64); the NaN-filled ones are touched whole at allocation and do not grow.
RECORDER_ZERO_BYTES = lambda p, m: 8 * p + 8 * m + m + 1 + 8 + 8  # noqa: E731 - bytes per step


def rss_kib(pid: int | str = "self") -> float | None:
    """Resident set size of a process in KiB (None when it is gone)."""
    try:
        with open(f"/proc/{pid}/statm") as fh:
            pages = int(fh.read().split()[1])
    except (OSError, IndexError, ValueError):
        return None
    return pages * PAGE_KIB if pages else None  # 0: an exited process not yet reaped


def firmware_pid(name: str = "gainlink_can") -> int | None:
    """The pid of our child process ``name`` (the bridge starts it), if any."""
    me = os.getpid()
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as fh:
                stat = fh.read()
        except OSError:
            continue
        comm = stat[stat.index("(") + 1 : stat.rindex(")")]
        ppid = int(stat[stat.rindex(")") + 2 :].split()[1])
        if ppid == me and comm == name:
            return int(entry)
    return None


def cpu_steal() -> tuple[int, int]:
    """(steal, total) jiffies from /proc/stat."""
    with open("/proc/stat") as fh:
        fields = [int(v) for v in fh.readline().split()[1:]]
    return (fields[7] if len(fields) > 7 else 0), sum(fields)


class Sampler:
    """Samples the bridge's and the firmware's RSS, the load and CPU steal every ``period`` seconds."""

    def __init__(self, period: float) -> None:
        self.period = period
        self.rows: list[dict] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self.t0 = time.monotonic()

    def _run(self) -> None:
        steal_prev = cpu_steal()
        while not self._stop.wait(self.period):
            pid = firmware_pid()
            steal = cpu_steal()
            self.rows.append(
                {
                    "t_s": round(time.monotonic() - self.t0, 1),
                    "bridge_rss_kib": rss_kib(),
                    "firmware_rss_kib": rss_kib(pid) if pid else None,
                    "load1": os.getloadavg()[0],
                    "steal_fraction": round((steal[0] - steal_prev[0]) / max(1, steal[1] - steal_prev[1]), 4),
                }
            )
            steal_prev = steal

    def __enter__(self) -> Sampler:
        self.t0 = time.monotonic()
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()


def slope_kib_per_min(rows: list[dict], key: str, *, skip_s: float = 60.0) -> float | None:
    """Least-squares slope of ``key`` against time, after the first ``skip_s`` seconds (start-up)."""
    pts = [(r["t_s"], r[key]) for r in rows if r[key] is not None and r["t_s"] >= skip_s]
    if len(pts) < 3:
        return None
    t, v = np.array(pts, dtype=float).T
    return float(np.polyfit(t / 60.0, v, 1)[0])


def scenario(name: str, *, gains: Path, exe: Path, fmu: Path, transport: dict, mode: str, duration: float) -> dict:
    data = {
        "name": name,
        "artifact": str(gains),
        "duration": duration,
        "mode": mode,
        "controller": "firmware",
        "firmware": str(exe),
        "twin": False,
        "peer_timeout": 10.0,
        "step_timeout": 2.0,
        "plant": {"kind": "fmu", "path": str(fmu)},
        "transport": transport,
        "initial_state": {"theta": 0.1},
        "reference": {"r_x": {"kind": "step", "at": 1.0, "value": 0.2}},
    }
    if mode == "realtime":
        data["sched_fifo"] = True
    return data


def books(res, *, mode: str, stopped: bool = False) -> dict:
    """Every sample and frame accounted for, from the report (bridge side) and the firmware's exit summary.

    ``stopped``: the phase was ended by stopping the firmware; the last sample was then in flight (sent, not
    answered: ``lost_at_stop``), which is not a loss of the link.
    """
    m, info = res.metrics, res.info["transport"]
    c = m.get("controller", {}).get("counters", {})
    got = int(res.trace.got.sum())
    at_stop = int(stopped and not res.complete and not res.trace.got[-1])
    out = {
        "steps": m["steps"],
        "answered": got,
        "lost": m["lost"] - at_stop,
        "lost_at_stop": at_stop,
        "late": m["late"],
        "unaccounted_bridge": m["steps"] - got - m["lost"],
        "frames_sent": info.get("frames_sent"),
        "firmware_counters": c,
        "end": res.reason or "complete",
    }
    if c:
        in_flight = max(0, info["frames_sent"] - c["used"] - c["dropped"]) if at_stop else 0
        out["unaccounted_firmware"] = info["frames_sent"] - c["used"] - c["dropped"] - min(in_flight, 1)
        out["firmware_steps_vs_bridge_steps"] = c["steps"] - m["steps"]
    if mode == "realtime":
        out["overruns"] = m.get("overruns")
    return out


def explain_misses(res) -> dict:
    """Each missed deadline of a real-time run, by cause, from the trace (see the module doc).

    A tick that never ran (TICK is NaN) passed while the bridge itself was stalled — the machine did not run it
    (an overrun, skipped); a tick that ran sent its sample, and its command came after the deadline (counted
    ``late`` when it did arrive) or never. For those, how late the bridge's own tick woke is given too.
    """
    tr, m = res.trace, res.metrics
    missed = np.flatnonzero(~tr.got)
    skipped = missed[np.isnan(tr.tick_ns[missed])]
    sent = np.setdiff1d(missed, skipped)
    wake_us = (tr.tick_ns[sent] - tr.deadline_ns[sent]) / 1e3  # the tick's wake-up after its scheduled time
    return {
        "missed": int(missed.size),
        "skipped_while_the_bridge_was_stalled": int(skipped.size),
        "overruns_reported": m.get("overruns"),
        "sample_sent_command_after_deadline": int(sent.size),
        "of_which_arrived_late": m["late"],
        "of_which_never_arrived": int(sent.size) - m["late"],
        "bridge_wake_delay_us_of_those": {
            "median": float(np.median(wake_us)) if wake_us.size else None,
            "max": float(wake_us.max()) if wake_us.size else None,
        },
        "first_misses_s": [round(float(tr.t[k]), 3) for k in missed[:10]],
    }


def _stop_firmware_after(seconds: float) -> threading.Timer:
    """SIGTERM our firmware child after ``seconds`` (ends a lockstep phase on time)."""

    def stop() -> None:
        pid = firmware_pid()
        if pid is not None:
            os.kill(pid, signal.SIGTERM)

    timer = threading.Timer(seconds, stop)
    timer.daemon = True
    timer.start()
    return timer


def run_phase(name: str, data: dict, *, sample_s: float, stop_after_s: float | None = None) -> tuple[object, dict]:
    with Sampler(sample_s) as sampler:
        timer = _stop_firmware_after(stop_after_s) if stop_after_s else None
        t0 = time.perf_counter()
        try:
            res = run_scenario(parse_scenario(data))
        finally:
            if timer is not None:
                timer.cancel()
        wall = time.perf_counter() - t0
    rows = sampler.rows
    m = res.metrics
    steps_per_min = m["steps"] / (wall / 60.0) if wall > 0 else 0.0
    a = artifact_mod.load(data["artifact"])
    growth = RECORDER_ZERO_BYTES(a.p, a.m) * steps_per_min / 1024
    bridge_slope = slope_kib_per_min(rows, "bridge_rss_kib")
    out = {
        "wall_s": round(wall, 1),
        "steps": m["steps"],
        "steps_per_s": round(m["steps"] / wall, 1),
        "complete": res.complete,
        "reason": res.reason,
        "rss_samples": rows,
        "bridge_rss_slope_kib_per_min": bridge_slope,
        "bridge_trace_growth_kib_per_min": round(growth, 1),
        "bridge_rss_slope_minus_trace": None if bridge_slope is None else round(bridge_slope - growth, 1),
        "firmware_rss_slope_kib_per_min": slope_kib_per_min(rows, "firmware_rss_kib"),
        "firmware_rss_kib_first_last": [
            next((r["firmware_rss_kib"] for r in rows if r["firmware_rss_kib"]), None),
            next((r["firmware_rss_kib"] for r in reversed(rows) if r["firmware_rss_kib"]), None),
        ],
        "books": books(res, mode=data["mode"], stopped=stop_after_s is not None),
        "latency_us": m["latency_us"],
        "period_jitter_us": m["period_jitter_us"],
        "controller_stderr_bytes": m.get("controller", {}).get("stderr_bytes"),
        "theta_final": m["outputs_final"].get("theta"),
    }
    if data["mode"] == "realtime":
        out["misses"] = explain_misses(res)
        out["sched_fifo"], out["pm_qos"] = m.get("sched_fifo"), m.get("pm_qos")
    return res, out


def calibrate(common: dict, steps: int, Ts: float) -> dict:
    """A short lockstep run at full speed: the steps per second the lockstep phase is sized from."""
    t0 = time.perf_counter()
    cal = run_scenario(parse_scenario(scenario("soak_calibration", mode="lockstep", duration=steps * Ts, **common)))
    return {"steps": cal.metrics["steps"], "steps_per_s": round(cal.metrics["steps"] / (time.perf_counter() - t0), 1)}


def run_phases(args: argparse.Namespace, common: dict, Ts: float, rate: float) -> dict:
    """The lockstep phase (planned at three times the calibrated rate, stopped by the clock) and the real-time
    phase, each as ``run_phase`` reports it; a phase of 0 minutes is left out."""
    phases = {}
    if args.lockstep_minutes > 0:
        steps = min(int(3 * rate * args.lockstep_minutes * 60), 10_000_000)
        _, ph = run_phase(
            "lockstep",
            scenario("soak_lockstep", mode="lockstep", duration=steps * Ts, **common),
            sample_s=args.sample_s,
            stop_after_s=args.lockstep_minutes * 60,
        )
        ph["speed_vs_calibration"] = round(ph["steps_per_s"] / rate, 3)
        phases["lockstep"] = ph
    if args.realtime_minutes > 0:
        _, ph = run_phase(
            "realtime",
            scenario("soak_realtime", mode="realtime", duration=args.realtime_minutes * 60, **common),
            sample_s=args.sample_s,
        )
        phases["realtime"] = ph
    return phases


def summary(phases: dict) -> dict:
    """Whether every phase ran to its end with its books balanced, and the memory slopes side by side."""
    return {
        "complete": all(p["complete"] or p["books"]["lost_at_stop"] for p in phases.values()),
        "unaccounted_samples": sum(
            abs(p["books"]["unaccounted_bridge"]) + abs(p["books"].get("unaccounted_firmware", 0))
            for p in phases.values()
        ),
        "firmware_rss_slope_kib_per_min": {k: p["firmware_rss_slope_kib_per_min"] for k, p in phases.items()},
        "bridge_rss_slope_minus_trace": {k: p["bridge_rss_slope_minus_trace"] for k, p in phases.items()},
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lockstep-minutes", type=float, default=30.0)
    ap.add_argument("--realtime-minutes", type=float, default=30.0)
    ap.add_argument("--sample-s", type=float, default=10.0)
    ap.add_argument("--calibration-steps", type=int, default=20000)
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    os.nice(10)
    out: dict = {
        "benchmark": "soak",
        "transport": "CAN FD over udp_multicast",
        "plant": "cart_pendulum FMU",
        "sample_s": args.sample_s,
        "cpus": os.cpu_count(),
    }
    with tempfile.TemporaryDirectory() as tmp:
        gains = pendulum_1khz(Path(tmp))
        art = artifact_mod.load(gains)
        common = dict(
            gains=gains,
            exe=firmware_can_executable(art),
            fmu=build_fmu("cart_pendulum"),
            transport=multicast_transport(),
        )
        out["calibration"] = calibrate(common, args.calibration_steps, art.Ts)
        phases = run_phases(args, common, art.Ts, out["calibration"]["steps_per_s"])
    out.update(phases)
    out["summary"] = summary(phases)
    json.dump(out, sys.stdout, indent=2)
    sys.stdout.write("\n")
    return 0 if out["summary"]["complete"] and out["summary"]["unaccounted_samples"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
