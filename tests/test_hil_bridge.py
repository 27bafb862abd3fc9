"""The HIL bridge end to end: the firmware's gainlink_can (a real process) over python-can udp_multicast
against the nonlinear pendulum FMU; faults, dead and silent peers, bad inputs, real time, the report.

A float64 twin of the whole loop runs beside each run (the reference law around a second FMU instance,
same noise, references and disturbances): a fault-free run must stay within float32 accuracy of it
(1e-4 of the limit span and of each output's range), a run that loses 10 % of its samples must not.
"""

from __future__ import annotations

import glob
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from gainlink.hil.links.can import CanTransport
from gainlink.hil.loop.bridge import run_scenario
from gainlink.hil.loop.scenario import parse_scenario
from gainlink.shipping.artifact import load
from support.cli import assert_refused, run_cli
from support.hil import pendulum_scenario, udp_transport, write_scenario
from support.net import udp_port


def _run(data):
    return run_scenario(parse_scenario(data))


def test_lockstep_classic_can_stabilises_the_fmu_pendulum_and_writes_the_report(tmp_path, pend, can_firmware, cart_fmu):
    scenario = write_scenario(
        tmp_path / "s.toml",
        pendulum_scenario(
            gains=pend,
            fmu=cart_fmu,
            transport=udp_transport(fd=False),
            duration=10.0,
            reference={"r_x": {"kind": "step", "at": 1.0, "value": 0.2}},
            noise={"theta": 1e-4},
            seed=3,
            disturbances=[{"input": "F", "start": 2.5, "stop": 2.6, "value": 2.0}],
        ),
    )
    report = tmp_path / "report"
    res = run_cli("hil", "run", scenario, "--report", report, "--no-progress")
    assert res.code == 0, res.err
    m = json.loads((report / "report.json").read_text())
    for key in ("steps", "lost", "deadline_misses", "latency_us", "saturation_fraction", "outputs_final", "complete"):
        assert key in m
    assert m["complete"] is True and m["steps"] == 1000 and m["lost"] == 0 and m["late"] == 0
    assert m["run"]["transport"]["frames_per_sample"] == 3  # classic CAN: one value per frame
    assert set(m["latency_us"]) == {"p50", "p99", "max"} and 0 < m["latency_us"]["p50"] <= m["latency_us"]["max"]
    assert abs(m["outputs_final"]["theta"]) < 0.01
    assert m["outputs_final"]["x"] == pytest.approx(0.2, abs=0.02)  # integral action tracks the cart step
    tw = m["twin"]  # the fault-free run against its float64 twin: float32 accuracy
    assert 0 < tw["inputs"]["F"]["max_du_rel"] < 1e-4 and tw["worst_dy_rel"] < 1e-4
    assert abs(tw["iae"]["r_x"]["difference_rel"]) < 1e-4
    assert m["tracked"]["r_x"]["iae"] == pytest.approx(tw["iae"]["r_x"]["real"])
    assert m["peak_integrator"]["r_x"] > 0
    for name in ("outputs.png", "inputs.png", "latency.png", "twin.png"):
        assert (report / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    summary = (report / "summary.txt").read_text()
    assert "complete" in summary and str(report / "report.json") in summary
    assert "against the float64 twin" in summary and "max |u - u_twin|: F" in summary
    assert m["run"]["artifact"]["compensator"]["stable"] and "compensator poles max |z| = 0.90" in summary
    assert res.out == summary


def test_frame_faults_are_counted_by_sequence_number(pend, can_firmware, cart_fmu):
    # 0.5 s windows at 100 Hz, every 10th sample: 5 samples each.
    faults = [
        {"kind": "drop", "start": 0.5, "stop": 1.0, "every": 10},
        {"kind": "duplicate", "start": 1.0, "stop": 1.5, "every": 10},
        {"kind": "reorder", "start": 1.5, "stop": 2.0, "every": 10},
        {"kind": "delay", "start": 2.0, "stop": 2.5, "every": 10, "delay_steps": 2},
    ]
    r = _run(
        pendulum_scenario(
            gains=pend,
            fmu=cart_fmu,
            transport=udp_transport(fd=True),
            duration=3.0,
            faults=faults,
            step_timeout=0.2,
        )
    )
    m = r.metrics
    assert m["faults_injected"] == {"drop": 5, "duplicate": 5, "reorder": 5, "delay": 5}
    # Dropped samples never get a command; a reordered or delayed sample arrives after a newer one and
    # the controller ignores it (stale), so it is lost too; duplicates are answered once.
    assert m["lost"] == 15 and m["deadline_misses"] == 15
    assert m["late"] == 0
    lost_steps = np.flatnonzero(~r.trace.got)
    assert list(lost_steps[:5]) == [50, 60, 70, 80, 90]
    assert m["complete"] is True and abs(m["outputs_final"]["theta"]) < 0.05


def test_ten_percent_drops_show_as_a_cost_against_the_twin(pend, can_firmware, cart_fmu):
    """Every tenth sample dropped (the command is held for that period): the twin comparison measures what
    that costs the closed loop, far above the fault-free run's float32 differences."""
    common = dict(
        gains=pend,
        fmu=cart_fmu,
        transport=udp_transport(fd=True),
        duration=4.0,
        reference={"r_x": {"kind": "step", "at": 0.5, "value": 0.2}},
        noise={"theta": 1e-4},
        seed=4,
    )
    clean = _run(pendulum_scenario(**common))
    drops = _run(
        pendulum_scenario(faults=[{"kind": "drop", "start": 0.0, "stop": 4.0, "every": 10}], step_timeout=0.2, **common)
    )
    assert clean.complete and drops.complete
    assert clean.metrics["lost"] == 0
    lost = np.flatnonzero(~drops.trace.got)
    assert set(range(0, 400, 10)) <= set(lost.tolist()), "every dropped sample is lost"
    # a reply later than the 0.2 s step timeout on a loaded machine also counts as lost: allow a stray one or two
    assert len(lost) <= 42, f"{len(lost)} lost beyond the 40 dropped"
    c, d = clean.metrics["twin"], drops.metrics["twin"]
    print(
        f"against the twin: fault-free max |du| {c['worst_du_rel']:.3g} of span, "
        f"|dy| {c['worst_dy_rel']:.3g} of range, "
        f"IAE {c['iae']['r_x']['difference_rel']:+.3g}; 10 % drops {d['worst_du_rel']:.3g}, {d['worst_dy_rel']:.3g}, "
        f"IAE {d['iae']['r_x']['difference_rel']:+.3g}"
    )
    assert c["worst_du_rel"] < 1e-4 and c["worst_dy_rel"] < 1e-4
    assert d["worst_du_rel"] > 100 * c["worst_du_rel"] and d["worst_dy_rel"] > 100 * c["worst_dy_rel"]
    assert abs(d["iae"]["r_x"]["difference"]) > 100 * abs(c["iae"]["r_x"]["difference"])
    # the twin saw neither the faults nor the link: both twins are the same ideal loop
    np.testing.assert_array_equal(clean.trace.twin_u, drops.trace.twin_u)


def test_silent_controller_ends_the_run_in_bounded_time(pend, can_firmware, cart_fmu):
    """Frozen from step 50 of 3000: each unanswered sample waits its 0.05 s step timeout, so the 0.5 s peer timeout
    ends the run by the tenth of them, whatever the machine's load (a slower step only means fewer)."""
    r = _run(
        pendulum_scenario(
            gains=pend,
            fmu=cart_fmu,
            transport=udp_transport(),
            duration=30.0,
            faults=[{"kind": "silent", "start": 0.5}],
            step_timeout=0.05,
            peer_timeout=0.5,
        )
    )
    assert r.complete is False and r.metrics["complete"] is False
    assert r.metrics["reason"].startswith("controller silent for 0.5 s since step 50 "), r.metrics["reason"]
    unanswered = np.count_nonzero(~r.trace.got[50:])
    assert r.metrics["steps"] == 50 + unanswered and 1 <= unanswered <= 10, (r.metrics["steps"], unanswered)


def test_crashed_controller_ends_the_run_and_says_so(pend, can_firmware, cart_fmu):
    r = _run(
        pendulum_scenario(
            gains=pend,
            fmu=cart_fmu,
            transport=udp_transport(),
            duration=30.0,
            faults=[{"kind": "crash", "start": 0.3}],
            step_timeout=0.05,
        )
    )
    assert r.complete is False
    assert "exited with status -9" in r.metrics["reason"] and r.metrics["steps"] <= 32


def test_reference_controller_node_matches_the_firmware(pend, can_firmware, cart_fmu):
    common = dict(gains=pend, fmu=cart_fmu, duration=1.5)
    fw = _run(pendulum_scenario(transport=udp_transport(), **common))
    py = _run(pendulum_scenario(transport=udp_transport(), controller="reference", **common))
    assert fw.complete and py.complete
    # The node is the float64 law itself: only the float32 values on the wire separate it from its twin.
    assert py.metrics["twin"]["worst_du_rel"] < 1e-5
    np.testing.assert_allclose(fw.trace.u, py.trace.u, rtol=0, atol=1e-3)


@pytest.mark.parametrize("wire", ["", " wire=1", " wire=2", " wire=3", " wire=5"])
def test_a_controller_of_another_wire_format_is_refused_in_one_line(pend, wire):
    """A node whose ready line names another sample/command wire format than 4 (3: an FD frame's header was the
    classic one, 4 values a frame; 2: before CAPPED rode on CAN), or none (a firmware from before MAVLink's own flag
    bits were left to MAVLink), is refused before the first sample, in one line naming both formats, and stopped: its
    status bits would be read at other places. The peer is a real process printing that node's ready line."""
    from gainlink.errors import FirmwareError
    from gainlink.hil.loop.controller import ControllerProcess

    a = load(pend)
    line = f"gainlink_can ready {a.name} sha256:{a.sha256} n=4 m=1 p=2 q=1 fd=0 base_id=256 encoding=float32{wire}"
    peer = ControllerProcess([sys.executable, "-c", f"import time; print({line!r}, flush=True); time.sleep(30)"])
    peer.start()
    try:
        with pytest.raises(FirmwareError) as err:
            peer.check_artifact(a.sha256)
        msg = str(err.value)
        assert "\n" not in msg and "this gainlink wire format 4" in msg and "rebuild its firmware" in msg, msg
        assert (f"speaks wire format {wire.split('=')[1]}," if wire else "from before it was versioned") in msg, msg
        assert peer.proc.poll() is not None, "the refused node is stopped"
    finally:
        peer.stop()


def test_realtime_mode_keeps_its_period(pend, can_firmware, cart_fmu, realtime_alone):
    r = _run(pendulum_scenario(gains=pend, fmu=cart_fmu, transport=udp_transport(), duration=1.0, mode="realtime"))
    m = r.metrics
    assert m["complete"] is True and m["steps"] == 100
    # Paced by the clock, not as fast as possible: the deadlines are one period apart and no tick ran before its own
    # (a tick a stall of the machine skipped has none: a held step).
    tr, ran = r.trace, ~np.isnan(r.trace.tick_ns)
    assert np.all(np.diff(tr.deadline_ns) == 10_000_000) and np.all(tr.tick_ns[ran] >= tr.deadline_ns[ran])
    # Jitter and deadline misses are measured (bench/hil_realtime.py), never asserted on a shared machine.
    assert m["period_jitter_us"]["p50"] is not None and 0 <= m["deadline_misses"] <= m["steps"]
    assert abs(m["outputs_final"]["theta"]) < 0.05


def _longest_run(mask: np.ndarray) -> int:
    """The length of the longest run of True in ``mask``."""
    edges = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    return int((np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)).max(initial=0))


def _stall_once(seconds: float):
    """A progress callback that stalls the bridge once, half way (as a hypervisor or a page fault would)."""
    stalled = []

    def progress(done: int, total: int) -> None:
        if not stalled and done >= total // 2:
            stalled.append(done)
            time.sleep(seconds)

    return progress


def test_realtime_overrun_skips_the_missed_ticks_and_lets_the_plant_run_on(
    pend, can_firmware, cart_fmu, realtime_alone
):
    common = dict(gains=pend, fmu=cart_fmu, transport=udp_transport(), duration=2.0, mode="realtime")
    skip = run_scenario(parse_scenario(pendulum_scenario(**common)), progress=_stall_once(0.08))
    m = skip.metrics
    assert m["complete"] and m["steps"] == 200 and m["overrun_policy"] == "skip"
    # 80 ms stalled at 10 ms per tick: at least 7 ticks passed unserved; each is a deadline miss.
    assert m["overruns"] >= 7 and m["deadline_misses"] >= m["overruns"]
    # They are skipped, not run late: held steps (never sent, no tick), as many as the overruns, 7 or more of them in
    # a row (a stall of the machine may add others).
    held = np.isnan(skip.trace.tick_ns)
    assert held.sum() == m["overruns"] and _longest_run(held) >= 7, np.flatnonzero(held)
    assert not skip.trace.got[held].any()
    # Skipped ticks hold the command while the plant runs on: plant time stays whole, no gap in the trace.
    assert np.all(np.isfinite(skip.trace.y)) and np.all(np.any(skip.trace.y != 0, axis=1))
    assert abs(m["outputs_final"]["theta"]) < 0.05  # an 80 ms hold does not lose the pendulum

    catch_up = run_scenario(parse_scenario(pendulum_scenario(overrun="catch_up", **common)), progress=_stall_once(0.08))
    c = catch_up.metrics
    assert c["complete"] and c["steps"] == 200 and c["overruns"] == 0
    # Every tick ran (none held); the 7 or more due in the stall ran after it, back to back, each after the deadline
    # of its command (the next tick's), so each is a deadline miss.
    assert not np.isnan(catch_up.trace.tick_ns).any() and c["deadline_misses"] >= 7


def _cpu_wakeup_latency_request() -> int:
    """The kernel's current aggregate CPU wake-up latency request in us (PM QoS)."""
    return int.from_bytes(open("/dev/cpu_dma_latency", "rb").read(4), "little", signed=True)


@pytest.mark.skipif(not os.access("/dev/cpu_dma_latency", os.W_OK), reason="PM QoS needs root")
def test_realtime_holds_a_zero_wakeup_latency_request_only_while_it_runs(pend, can_firmware, cart_fmu, realtime_alone):
    before = _cpu_wakeup_latency_request()
    seen: list[int] = []
    common = dict(gains=pend, fmu=cart_fmu, transport=udp_transport(), duration=0.5, mode="realtime")
    r = run_scenario(
        parse_scenario(pendulum_scenario(**common)),
        progress=lambda done, total: seen.append(_cpu_wakeup_latency_request()) if done < total else None,
    )
    assert r.complete and r.metrics["pm_qos"] is True and seen and set(seen) == {0}
    assert _cpu_wakeup_latency_request() == before != 0  # withdrawn when the run ends
    seen.clear()
    off = run_scenario(
        parse_scenario(pendulum_scenario(pm_qos=False, **common)),
        progress=lambda done, total: seen.append(_cpu_wakeup_latency_request()),
    )
    assert off.complete and off.metrics["pm_qos"] is False and set(seen) == {before}


def test_bad_inputs_get_one_line_and_a_nonzero_exit(tmp_path, pend, cart_fmu, example_artifacts):
    base = pendulum_scenario(gains=pend, fmu=cart_fmu, transport=udp_transport(), duration=0.5, controller="reference")
    broken = tmp_path / "broken.fmu"
    broken.write_bytes(b"PK\x03\x04 truncated")
    cases = {
        "unknown key": ({**base, "durration": 1.0}, "unknown key(s) durration"),
        "bad affinity": ({**base, "affinity": "pinned"}, "affinity must be one of auto, shared, separate, none"),
        "bad overrun": ({**base, "overrun": "ignore"}, "overrun must be one of skip, catch_up"),
        "flag not a boolean": ({**base, "pm_qos": "no"}, "pm_qos must be true or false, not 'no'"),
        "missing fmu": ({**base, "plant": {"kind": "fmu", "path": str(tmp_path / "none.fmu")}}, "not found"),
        "broken fmu": ({**base, "plant": {"kind": "fmu", "path": str(broken)}}, str(broken)),
        "dimension mismatch": (
            {**base, "plant": {"kind": "fmu", "path": str(cart_fmu), "outputs": ["theta"]}},
            "expects m=1 input(s) and p=2 output(s)",
        ),
        "other artifact": ({**base, "artifact": str(example_artifacts["wood_berry"])}, "expects m=2"),
        "bus cannot open": (
            {**base, "transport": {"interface": "socketcan", "channel": "gl_nocan0"}},
            "cannot open CAN bus (interface=socketcan, channel=gl_nocan0)",
        ),
        "bad mode": ({**base, "mode": "fast"}, "mode must be one of lockstep, realtime"),
        "bad fault": ({**base, "faults": [{"kind": "gremlins"}]}, "faults[0].kind"),
    }
    for name, (data, needle) in cases.items():
        path = write_scenario(tmp_path / f"{name.replace(' ', '_')}.toml", data)
        report = tmp_path / f"report_{name.replace(' ', '_')}"
        assert_refused(("hil", "run", path, "--report", report, "--no-progress"), needle, tmp_path)
    assert_refused(("hil", "run", tmp_path / "nope.toml", "--report", tmp_path / "r"), "not found", tmp_path)


def test_firmware_run_with_can_config_serves_the_bus(tmp_path, pend, can_firmware):
    cfg = udp_transport(fd=False)
    (tmp_path / "can.json").write_text(json.dumps(cfg))
    gainlink = [sys.executable, "-c", "import sys; from gainlink.cli import main; sys.exit(main())"]
    proc = subprocess.Popen(
        [*gainlink, "firmware", "run", str(pend), "--can", str(tmp_path / "can.json")],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    art = load(pend)
    transport = CanTransport(cfg, artifact=art)
    try:
        assert b"gainlink_can ready" in proc.stdout.readline()
        transport.open()
        from gainlink.proof.reference import ReferenceLoop

        law = ReferenceLoop(art)
        for seq in (7, 8):  # predictor form: the first command is -K xh0 = 0, the second reacts to y
            y = np.array([0.0, 0.1], dtype=np.float32).astype(float)
            transport.send_frames(transport.encode_sample(seq=seq, y=y, r=np.zeros(1)))
            cmd = transport.receive_command(timeout=3.0)
            want = law.step(y, np.zeros(1)).u
            assert cmd is not None and cmd.seq == seq
            np.testing.assert_allclose(cmd.u, want, rtol=1e-4, atol=1e-6)
        assert cmd.u[0] != 0.0
    finally:
        transport.close()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=5) == 0
        proc.stdout.close()
        proc.stderr.close()


def test_wood_berry_with_true_dead_times_tracks_a_step(example_artifacts):
    # Designed on Pade approximants, run against the column's exact dead times (the built-in model).
    r = _run(
        {
            "artifact": str(example_artifacts["wood_berry"]),
            "duration": 150.0,
            "controller": "reference",
            "step_timeout": 2.0,
            "plant": {"kind": "wood_berry", "step": 0.1},
            "transport": udp_transport(),
            "reference": {"r_x_D": {"kind": "step", "at": 5.0, "value": 1.0}},
        }
    )
    m = r.metrics
    assert r.complete and m["steps"] == 150 and m["lost"] == 0
    assert m["outputs_final"]["x_D"] == pytest.approx(1.0, abs=0.05)
    assert m["outputs_final"]["x_B"] == pytest.approx(0.0, abs=0.05)
    assert m["tracked"]["r_x_D"]["settling_time_s"] is not None


def test_wood_berry_fmu_plant_tracks_a_step_like_the_builtin_model(example_artifacts):
    # The same run against the project FMU (FMI 2.0 CS, dead times as delay lines): a scenario swaps the plant.
    base = {
        "artifact": str(example_artifacts["wood_berry"]),
        "duration": 150.0,
        "controller": "reference",
        "step_timeout": 2.0,
        "transport": udp_transport(),
        "reference": {"r_x_D": {"kind": "step", "at": 5.0, "value": 1.0}},
    }
    builtin = _run({**base, "plant": {"kind": "wood_berry", "step": 0.1}})
    fmu = _run({**base, "plant": {"kind": "fmu", "fmu": "wood_berry"}})
    m, mb = fmu.metrics, builtin.metrics
    assert fmu.complete and m["steps"] == 150 and m["lost"] == 0
    assert m["outputs_final"]["x_D"] == pytest.approx(1.0, abs=0.05)
    assert m["outputs_final"]["x_B"] == pytest.approx(0.0, abs=0.05)
    assert m["tracked"]["r_x_D"]["settling_time_s"] == pytest.approx(mb["tracked"]["r_x_D"]["settling_time_s"], abs=1.0)
    # Both plants integrate exactly (ZOH) and agree to ~1e-13; samples travel as float32, so the closed loops
    # agree to float32 resolution of the signals (|x| <~ 2, |u| <= 1.5), not bit for bit.
    np.testing.assert_allclose(fmu.trace.y, builtin.trace.y, rtol=0, atol=1e-5)
    np.testing.assert_allclose(fmu.trace.u, builtin.trace.u, rtol=0, atol=1e-5)


def test_busy_polling_changes_timing_only(pend, can_firmware, cart_fmu):
    common = dict(gains=pend, fmu=cart_fmu, duration=1.0)
    plain = _run(pendulum_scenario(transport=udp_transport(), **common))
    busy = _run(pendulum_scenario(transport={**udp_transport(), "busy_poll_us": 100}, **common))
    assert "--spin-us" in busy.info["controller"]["argv"]
    assert plain.complete and busy.complete
    # Lockstep is deterministic: the same samples give the same commands, however they are waited for.
    assert np.array_equal(plain.trace.u, busy.trace.u) and np.array_equal(plain.trace.y, busy.trace.y)


def _controller_cpus() -> set[int]:
    """CPUs allowed to this process's gainlink_can child (read from the kernel, not from the report)."""
    for path in glob.glob(f"/proc/{os.getpid()}/task/*/children"):
        for pid in open(path).read().split():
            cmdline = open(f"/proc/{pid}/cmdline", "rb").read()
            if b"gainlink_can" in cmdline:
                return os.sched_getaffinity(int(pid))
    raise AssertionError("no gainlink_can child found")


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="needs sched_setaffinity")
def test_lockstep_shares_one_cpu_with_the_controller_and_restores_the_bridge(pend, can_firmware, cart_fmu):
    before = os.sched_getaffinity(0)
    seen: list[tuple[set[int], set[int]]] = []

    def during(done: int, total: int) -> None:
        if 0 < done < total:
            seen.append((os.sched_getaffinity(0), _controller_cpus()))

    common = dict(gains=pend, fmu=cart_fmu, duration=1.0)
    shared = run_scenario(parse_scenario(pendulum_scenario(transport=udp_transport(), **common)), progress=during)
    assert shared.complete and seen
    for bridge, controller in seen:
        assert len(bridge) == 1 and bridge == controller  # one CPU, the same for both sides
    assert shared.metrics["cpu"]["placement"] == "shared"
    assert os.sched_getaffinity(0) == before  # the caller gets its CPUs back

    free = _run(pendulum_scenario(transport=udp_transport(), affinity="none", **common))
    assert free.metrics["cpu"] == {"placement": "none", "bridge_cpus": None, "controller_cpus": None}
    # Placement changes timing only: lockstep traces are identical.
    assert np.array_equal(shared.trace.u, free.trace.u) and np.array_equal(shared.trace.y, free.trace.y)

    if len(before) >= 2:  # two busy-polling peers get a CPU each
        seen.clear()
        busy = run_scenario(
            parse_scenario(pendulum_scenario(transport={**udp_transport(), "busy_poll_us": 100}, **common)),
            progress=during,
        )
        assert busy.metrics["cpu"]["placement"] == "separate"
        for bridge, controller in seen:
            assert len(bridge) == 1 and len(controller) == 1 and bridge != controller


def test_resolve_affinity_picks_a_placement_for_the_run():
    from gainlink.hil.loop.scheduler import resolve_affinity

    assert resolve_affinity("auto", mode="lockstep", busy_poll=False, cpus=[0, 1]) == "shared"
    assert resolve_affinity("auto", mode="lockstep", busy_poll=True, cpus=[0, 1]) == "separate"
    assert resolve_affinity("auto", mode="lockstep", busy_poll=True, cpus=[0]) == "none"  # cannot spin on both
    assert resolve_affinity("auto", mode="realtime", busy_poll=False, cpus=[0, 1]) == "none"
    assert resolve_affinity("separate", mode="realtime", busy_poll=False, cpus=[3]) == "none"
    assert resolve_affinity("shared", mode="realtime", busy_poll=True, cpus=[0, 1]) == "shared"


def test_random_drop_hits_a_seeded_fraction_of_the_window():
    from gainlink.hil.loop.faults import FaultInjector
    from gainlink.hil.loop.scenario import Fault

    fault = Fault(kind="drop", start=1.0, stop=11.0, probability=0.2)

    def hits(seed):
        inj = FaultInjector([fault], Ts=0.01, seed=seed)
        return [k for k in range(1200) if inj.apply(k, ["frame"]) == []]

    a, b, c = hits(5), hits(5), hits(6)
    assert a == b and a != c
    assert all(100 <= k < 1100 for k in a)
    # 1000 Bernoulli(0.2) trials: mean 200, sd 12.6; 5 sd either way
    assert 137 <= len(a) <= 263 and 137 <= len(c) <= 263
    with pytest.raises(Exception, match="probability must be within"):
        parse_scenario(
            {
                "artifact": "g.json",
                "plant": {"kind": "linear"},
                "transport": {},
                "duration": 1.0,
                "faults": [{"kind": "drop", "probability": 1.5}],
            }
        )


def test_reply_port_carries_the_commands_apart_and_changes_nothing_else(pend, can_firmware, cart_fmu):
    common = dict(gains=pend, fmu=cart_fmu, duration=1.0)
    one = udp_transport()
    apart = {**udp_transport(), "reply_port": udp_port()}
    shared = _run(pendulum_scenario(transport=one, **common))
    split = _run(pendulum_scenario(transport=apart, **common))
    node = _run(pendulum_scenario(transport={**udp_transport(), "reply_port": udp_port()}, controller="reference",
                                  **common))  # fmt: skip
    assert shared.complete and split.complete and node.complete
    assert f"--reply-port {apart['reply_port']}" in " ".join(split.info["controller"]["argv"])
    # Lockstep is deterministic: the same samples give the same commands, whichever port they come back on.
    assert np.array_equal(shared.trace.u, split.trace.u) and np.array_equal(shared.trace.y, split.trace.y)
    np.testing.assert_allclose(node.trace.u, split.trace.u, rtol=0, atol=1e-3)
    # On one port the node reads back every command it sent (filtered as not a sample); apart, only samples.
    steps = split.metrics["steps"]
    assert shared.metrics["controller"]["counters"]["filtered"] >= steps
    counters = split.metrics["controller"]["counters"]
    assert counters["filtered"] == 0 and counters["read"] == counters["used"] == steps


@pytest.mark.parametrize(
    ("change", "says"),
    [
        ({"interface": "socketcan", "channel": "vcan0", "reply_port": 40001}, "reply_port is for interface"),
        ({"reply_port": "PORT"}, "reply_port must be a UDP port"),
        ({"reply_port": 70000}, "reply_port must be a UDP port"),
    ],
)
def test_a_bad_reply_port_is_refused_in_one_line(pend, change, says):
    from gainlink.errors import TransportError
    from gainlink.hil.links.config import transport_from_config

    config = {**udp_transport(), **change}
    if config["reply_port"] == "PORT":
        config["reply_port"] = config["port"]
    with pytest.raises(TransportError, match=says) as err:
        transport_from_config(config, artifact=load(pend))
    assert "\n" not in str(err.value)


def test_with_a_reply_port_each_end_hears_the_other_only():
    import select

    import can
    from gainlink.hil.links.can import open_link_buses

    config = {**udp_transport(), "reply_port": udp_port()}
    plant_rx, plant_tx = open_link_buses(config)
    node_rx, node_tx = open_link_buses(config, controller=True)
    try:
        plant_tx.send(can.Message(arbitration_id=0x110, data=b"sample", is_extended_id=False))
        got = node_rx.recv(2.0)
        assert got is not None and bytes(got.data) == b"sample"
        node_tx.send(can.Message(arbitration_id=0x100, data=b"command", is_extended_id=False))
        got = plant_rx.recv(2.0)
        assert got is not None and bytes(got.data) == b"command"
        # nobody got its own frame back, nor the other direction's: the send-only sockets queue nothing at all
        assert plant_rx.recv(0.2) is None and node_rx.recv(0.2) is None
        for bus in (plant_tx, node_tx):
            assert select.select([bus.fileno()], [], [], 0.2)[0] == []
    finally:
        for bus in (plant_rx, plant_tx, node_rx, node_tx):
            bus.shutdown()
