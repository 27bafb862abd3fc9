"""Every cell for every law (issue 30): each pair of gainlink.laws runs each thing a user reaches for, through the
one closed loop, or refuses it in the one line its declaration generates.

The cells are gainlink.laws.CELLS; the pairs gainlink.laws.pairs(). `make test` runs one representative per cell
(``REPRESENTATIVE``: the pair the cell was broken or refused for before the one loop, else the cheapest that has no
other test); `make test-matrix` (``-m matrix``) the whole product. Each pair runs on the design's own model of its
plant (the lq pairs: ``kind = "linear"``; the tank scheduled on an external signal, rate-limited: its built-in
nonlinear plant), short runs, designs and builds shared with the other tests (support.designs, the firmware cache by
sha256).

Oracles, none taken from the loop under test:

- a C implementation (the host library in process, a host app or the Cortex-M image on a link) is the law's bit-exact
  model (its ``model``: the float32 arithmetic or the integer law, each checked against the C elsewhere) fed the
  samples the controller received, in the order it received them: command bits, status flags, saturation and the
  sigma a scheduled law used;
- the order is written out here from the fault kinds' definitions (scenario docstring: drop never sent, duplicate
  sent twice at once, reorder sent after the next sample, delay sent after the sample ``delay_steps`` later), and a
  CAN node skips a sample whose sequence number is not ahead of the last it answered while a MAVLink node steps on
  every sample it gets (firmware/apps/can/gl_can_node.c, firmware/apps/mavlink/gl_mav_node.c);
- the Python reference node is the law's float64 reference on float32 samples, its command carried as float32.
"""

from __future__ import annotations

import numpy as np
import pytest
from gainlink.hil import run as hil_run
from gainlink.laws import CELLS, flags, law_of, pairs
from schedule_cases import external_tank
from support.designs import designed
from support.fixed import example
from support.hil import udp_transport
from support.mpc import mpc_pendulum
from support.net import tcp_port, udp_port
from support.status import FAULT

# one worker runs the module (39 CPU-s): started first
pytestmark = [
    pytest.mark.usefixtures("quiet_design_warnings"),
    pytest.mark.xdist_group("test_law_cells"),
    pytest.mark.slow(cpu=39),
]

PAIRS = tuple(pairs())

#: Per pair: the plant it runs against, its start and a reference that moves (absolute).
PLANTS = {
    "lq/float32": ({"kind": "linear"}, {"theta": 0.02}, {"r_x": {"kind": "step", "at": 0.2, "value": 0.1}}),
    "lq/q31": ({"kind": "linear"}, {"theta": 0.02}, {"r_x": {"kind": "step", "at": 0.2, "value": 0.1}}),
    "lq/q15": ({"kind": "linear"}, {}, {"r_x_D": {"kind": "step", "at": 1.0, "value": 0.5}}),
    "mpc/float32": ({"kind": "linear"}, {"x": 0.5}, {"r_x": {"kind": "step", "at": 0.2, "value": 0.1}}),
    "scheduled/float32": (
        {"kind": "tank", "step": 0.005},
        {"q": 0.08, "h": 0.04},
        {"r_h": {"kind": "sweep", "low": 0.04, "high": 1.0, "rate": 0.4, "start": 0.2}},
    ),
}
#: A scheduled law's external signal: swept faster than its rate limit, so that the sigma a step uses depends on
#: every sample the law stepped on before (the order a node stepped in shows in it).
SIGNALS = {"scheduled/float32": {"load": {"kind": "sweep", "low": 0.0, "high": 1.2, "rate": 0.6, "start": 0.1}}}
#: Steps of a run (what the cell needs, kept short: the suite runs every representative).
STEPS = 40


@pytest.fixture(scope="module")
def artifacts(example_artifacts):
    """Each pair's artifact: the examples (pendulum float32 and q31, the Wood-Berry column in q15) and the
    scheduled tank, designed once per test run."""
    from gainlink.shipping.artifact import from_dict, load

    out = {
        "lq/float32": load(example_artifacts["pendulum"]),
        "lq/q31": example("pendulum", "q31"),
        "lq/q15": example("wood_berry", "q15"),
        "scheduled/float32": from_dict(designed(external_tank(rate_max=0.05))),
        "mpc/float32": from_dict(designed(mpc_pendulum(horizon=5, box=2.5))),
    }
    assert sorted(out) == sorted(PAIRS)
    for pair, a in out.items():
        assert law_of(a).name == pair
    return out


def scenario(pair: str, a, *, steps: int = STEPS, transport=None, **extra) -> dict:
    """A run of ``pair``'s artifact on its plant: ``steps`` samples, lockstep, in process without a transport."""
    plant, initial, reference = PLANTS[pair]
    data = {
        "name": f"cell_{pair.replace('/', '_')}",
        "artifact": "unused.json",
        "duration": steps * a.Ts,
        "controller": "firmware",
        "plant": plant,
        "initial_state": initial,
        "reference": reference,
        "transport": {} if transport is None else transport,
        "step_timeout": 2.0,
        "peer_timeout": 4.0,
        "twin": False,
        "model_twin": False,
    }
    if pair in SIGNALS:
        data["schedule_signal"] = SIGNALS[pair]
    return data | extra


# -- the order a node steps on the samples (the oracle of every link run) ---------------------------------------------


def _fault_at(k: int, Ts: float, faults: list[dict]) -> dict | None:
    """The frame fault that hits sample ``k`` (its window and ``every``; probability 1), else None."""
    for f in faults:
        start, stop = f.get("start", 0.0), f.get("stop", 1e300)
        first = round(start / Ts)
        if f["kind"] in ("drop", "delay", "duplicate", "reorder") and start <= k * Ts < stop:
            if (k - first) % f.get("every", 1) == 0:
                return f
    return None


def node_order(N: int, Ts: float, faults: list[dict], *, dedupe: bool) -> list[int]:
    """The samples a node steps on, in the order it steps on them (module docstring)."""
    held: list[tuple[int, int]] = []  # (sent at step, sample)
    order: list[int] = []
    for k in range(N):
        f = _fault_at(k, Ts, faults)
        out = [k]
        if f is not None:
            out = {"drop": [], "duplicate": [k, k], "reorder": [], "delay": []}[f["kind"]]
            if f["kind"] in ("reorder", "delay"):
                held.append((k + (1 if f["kind"] == "reorder" else f.get("delay_steps", 1)), k))
        out += [j for at, j in held if at <= k]
        held = [h for h in held if h[0] > k]
        order += out
    if not dedupe:
        return order
    stepped, last = [], None
    for j in order:
        if last is None or 0 < (j - last) % 65536 < 0x8000:
            stepped.append(j)
            last = j
    return stepped


def assert_law_ran(a, res, *, order: list[int] | None = None, like: str = "model") -> None:
    """Every answered step of ``res`` is the law's ``like`` (its bit-exact model, or the float64 reference on float32
    samples) at the first time the controller stepped on that sample, the controller having stepped on the samples
    in ``order`` (default: each once, in turn)."""
    tr = res.trace
    N = tr.t.size
    law = law_of(a)
    ctl = law.model(a) if like == "model" else law.reference(a)
    Y = np.where(tr.nan_sent[:, None], np.nan, tr.y).astype(np.float32).astype(np.float64)
    R, S = tr.r.astype(np.float32).astype(np.float64), tr.s.astype(np.float32).astype(np.float64)
    first = {}
    for j in range(N) if order is None else order:
        step = ctl.step(Y[j], R[j], S[j])
        first.setdefault(j, step)
    got = np.flatnonzero(tr.got)
    assert got.size, "no step was answered"
    want = [first[k] for k in got]
    u = np.array([s.u for s in want], dtype=np.float32).reshape(got.size, a.m)
    np.testing.assert_array_equal(tr.u[got].astype(np.float32).view(np.uint32), u.view(np.uint32))
    transport = res.info["transport"]
    # CAN: the bits its header carries (classic 0-11, FD 0-15: CAPPED either way)
    carried = flags.can_header(transport["fd"]).status_mask if transport["kind"] == "can" else ~0
    np.testing.assert_array_equal(tr.flags[got], [s.flags & carried for s in want])
    np.testing.assert_array_equal(tr.sat[got], [s.saturated for s in want])
    np.testing.assert_array_equal(tr.sigma[got], [s.sigma for s in want])


# -- the cells --------------------------------------------------------------------------------------------------------


def cell_sil(pair, a, tmp_path):
    """In process: the host C of the law (``Law.native``), bit for bit its model."""
    res = hil_run(scenario(pair, a), artifact=a)
    assert res.complete and res.metrics["mode"] == "sil" and res.trace.got.all()
    assert_law_ran(a, res)


def cell_twins(pair, a, tmp_path):
    """The closed-loop twin (the float64 reference around a second plant) and the model twin (the reference around
    the design's own model) are there, and the twin is the reference stepped beside the run (here, by hand)."""
    res = hil_run(scenario(pair, a, twin=True, model_twin=True), artifact=a)
    tr = res.trace
    assert res.complete and tr.has_twin and tr.has_model_twin and "twin" in res.metrics
    from gainlink.hil.plants.config import plant_from_config

    plant = plant_from_config(PLANTS[pair][0], artifact=a)
    plant.reset(initial=PLANTS[pair][1])
    ref = law_of(a).reference(a)
    for k in range(tr.t.size):
        y = plant.outputs()  # no noise in these runs
        assert np.array_equal(tr.twin_y[k], y), k
        step = ref.step(y, tr.r[k], tr.s[k])
        assert np.array_equal(tr.twin_u[k], step.u), k
        plant.advance(u=step.u, dt=a.Ts)


def cell_hil_can(pair, a, tmp_path):
    """Over CAN (udp_multicast) to the firmware's host CAN node on the law."""
    res = hil_run(scenario(pair, a, transport=udp_transport(fd=False)), artifact=a)
    assert res.complete and res.trace.got.all() and res.metrics["lost"] == 0
    assert_law_ran(a, res)


def cell_hil_mavlink(pair, a, tmp_path):
    """Over MAVLink (UDP) to the firmware's host MAVLink app on the law."""
    res = hil_run(scenario(pair, a, transport={"kind": "mavlink", "port": udp_port()}), artifact=a)
    assert res.complete and res.trace.got.all() and res.info["transport"]["kind"] == "mavlink"
    assert_law_ran(a, res)


def cell_reference_over_a_link(pair, a, tmp_path):
    """``controller = "reference"`` over a link is the Python reference node of the law (it ran in process for a
    scheduled law, silently): the float64 reference on the float32 samples."""
    res = hil_run(scenario(pair, a, transport=udp_transport(fd=False), controller="reference"), artifact=a)
    assert res.complete and "python reference" in res.info["controller"]["ready"]
    assert "gainlink.hil.links.can_node" in res.info["controller"]["argv"]
    assert_law_ran(a, res, like="reference")


def _fault_run(pair, a, faults, *, transport=None, **extra):
    transport = transport or udp_transport(fd=False)
    return hil_run(scenario(pair, a, transport=transport, faults=faults, **extra), artifact=a)


def _frame_fault(kind: str):
    def cell(pair, a, tmp_path):
        f = {"kind": kind, "start": 0.3 * STEPS * a.Ts, "stop": 0.6 * STEPS * a.Ts, "every": 3, "delay_steps": 2}
        for transport, dedupe in ((udp_transport(fd=False), True), ({"kind": "mavlink", "port": udp_port()}, False)):
            res = _fault_run(pair, a, [f], transport=transport, step_timeout=0.5)
            m = res.metrics
            assert res.complete and m["faults_injected"][kind] == 4, m["faults_injected"]
            assert_law_ran(a, res, order=node_order(STEPS, a.Ts, [f], dedupe=dedupe))

    cell.__doc__ = f"A {kind} fault on the frames over CAN and MAVLink: the node steps in the order it receives."
    return cell


def cell_fault_nan(pair, a, tmp_path):
    """A nan fault (the sample's outputs sent as NaN): in process and over CAN, the law refuses the sample with its
    fault flag (every law; it ran with a scheduled law over its link only)."""
    f = {"kind": "nan", "start": 0.3 * STEPS * a.Ts, "stop": 0.45 * STEPS * a.Ts}
    for transport in (None, udp_transport(fd=False)):
        res = (
            _fault_run(pair, a, [f], transport=transport)
            if transport
            else hil_run(scenario(pair, a, faults=[f]), artifact=a)
        )
        tr = res.trace
        assert res.complete and tr.nan_sent.sum() == res.metrics["faults_injected"]["nan"] > 0
        assert np.all(tr.flags[tr.nan_sent] & FAULT) and res.metrics["refused_steps"] == tr.nan_sent.sum()
        assert_law_ran(a, res)


def _process_fault(kind: str, words: str):
    def cell(pair, a, tmp_path):
        f = {"kind": kind, "start": 0.5 * STEPS * a.Ts}
        res = _fault_run(pair, a, [f], step_timeout=0.2, peer_timeout=0.5)
        assert not res.complete and words in res.reason, res.reason
        assert res.trace.t.size > STEPS // 2 - 1 and res.trace.got[: STEPS // 2].all()
        assert_law_ran(a, res)

    cell.__doc__ = f"A {kind} controller ends the run with the reason; the steps before are the law's."
    return cell


def cell_realtime_host(pair, a, tmp_path):
    """Real time against the host CAN node: paced, each command due by the next tick; the answered steps are the
    law's on the samples sent (ticks missed in a stall send none)."""
    res = hil_run(scenario(pair, a, transport=udp_transport(fd=False), mode="realtime"), artifact=a)
    tr, m = res.trace, res.metrics
    assert res.complete and m["mode"] == "realtime" and np.all(np.isfinite(tr.deadline_ns))
    sent = np.flatnonzero(np.isfinite(tr.tick_ns))
    assert_law_ran(a, res, order=list(sent))


def cell_realtime_qemu(pair, a, tmp_path):
    """Real time against the Cortex-M image's MAVLink node on its UART in QEMU (refused for a scheduled law)."""
    url = f"tcp:127.0.0.1:{tcp_port()}"
    period = max(a.Ts, 0.02)  # the emulated UART's ~300 round trips/s (FIELD-NOTES)
    res = hil_run(scenario(pair, a, steps=20, transport={"kind": "mavlink", "url": url}, controller="qemu",
                           mode="realtime", period=period), artifact=a)  # fmt: skip
    tr = res.trace
    assert res.complete and res.metrics["mode"] == "realtime" and res.info["controller"]["board"] == "mps2-an386"
    assert tr.got.sum() >= 15, f"{tr.got.sum()} of 20 answered in time"
    sent = np.flatnonzero(np.isfinite(tr.tick_ns))
    assert_law_ran(a, res, order=list(sent))


def cell_slcan(pair, a, tmp_path):
    """The Cortex-M image's slcan node on its UART in QEMU, lockstep."""
    slcan = {"interface": "slcan", "channel": f"socket://127.0.0.1:{tcp_port()}"}
    res = hil_run(scenario(pair, a, steps=20, transport=slcan, controller="qemu"), artifact=a)
    assert res.complete and res.trace.got.all() and "uart" in res.metrics
    assert_law_ran(a, res)


def _campaign(pair, a, kind: str) -> dict:
    data = scenario(pair, a, transport=udp_transport(fd=False) if kind == "hil" else None)
    for key in ("name", "artifact"):
        data.pop(key)
    return {"name": f"cells_{kind}", "kind": kind, "seed": 1, "scenario": data}


def _campaign_cell(kind: str):
    def cell(pair, a, tmp_path):
        import json

        from gainlink.hil.campaign.config import parse_campaign
        from gainlink.hil.campaign.plan import plan_campaign
        from gainlink.hil.campaign.worker import execute

        path = tmp_path / "gains.json"
        a.save(path)
        plan = plan_campaign(parse_campaign(_campaign(pair, a, kind) | {"artifact": str(path)}, path=None))
        (point,) = plan.runs
        record = execute(kind, plan.artifacts[point.artifact_sha256], point.scenario, point.seed, plan.blobs)
        assert record["status"] == "done" and record["complete"], record.get("reason")
        assert json.loads(json.dumps(record["metrics"]))["steps"] == STEPS

    cell.__doc__ = f"One {kind.upper()} campaign run: planned on the client (preflight), run as a worker runs it."
    return cell


def _samples(pair, a, steps: int = STEPS):
    """A closed-loop record of the law (``gl.simulate``: its float64 reference around the artifact's own model),
    with a moving reference (and a scheduled law's swept signal)."""
    import gainlink as gl

    S = None
    if pair in SIGNALS:
        S = np.linspace(0.0, 1.2, steps)[:, None]
    r = law_of(a).r_op(a, sigma=float("nan") if S is None else float(np.clip(S[0, 0], 0.04, 1.0))) * 1.1
    return gl.simulate(a, steps=steps, reference=r, noise_std=1e-4, seed=3, signals=S)


def cell_design(pair, a, tmp_path):
    """The design: its artifact validates and names its law (law_of)."""
    from support.cli import run_cli

    a.save(tmp_path / "gains.json")
    assert run_cli("validate", tmp_path / "gains.json").code == 0
    assert law_of(a).name == pair


def cell_codegen(pair, a, tmp_path):
    """The C rendering: every generated file names the artifact it came from."""
    from support.cli import run_cli

    a.save(tmp_path / "gains.json")
    res = run_cli("export", tmp_path / "gains.json", "--out", tmp_path / "c")
    assert res.code == 0, res.err
    sources = [f for f in (tmp_path / "c").iterdir() if f.suffix == ".c"]
    assert sources and all(f"sha256:{a.sha256}" in f.read_text() for f in sources)


def cell_simulate(pair, a, tmp_path):
    """``gl.simulate`` runs every law (a scheduled law around its points' model): the record replays through the
    float64 reference to the same commands."""
    import gainlink as gl

    sim = _samples(pair, a)
    tr = gl.replay(a, sim.y, sim.r, s=sim.s)
    assert np.array_equal(tr.u, sim.u) and np.all(np.isfinite(sim.y))


def _engine(engine: str):
    def cell(pair, a, tmp_path):
        import gainlink as gl

        sim = _samples(pair, a)
        tr = gl.replay(a, sim.y, sim.r, s=sim.s, engine=engine)
        model = law_of(a).model(a)
        S = np.zeros((sim.t.size, 0)) if sim.s is None else sim.s
        want = [model.step(sim.y[k], sim.r[k], S[k]) for k in range(sim.t.size)]
        u = np.array([w.u for w in want], dtype=np.float32)
        np.testing.assert_array_equal(tr.u.astype(np.float32).view(np.uint32), u.view(np.uint32))

    cell.__doc__ = f"Replay through the {engine} engine: bit for bit the law's model."
    return cell


def _replay_csv(pair, a, tmp_path):
    from gainlink.proof.simulation import samples_csv
    from support.cli import run_cli

    a.save(tmp_path / "gains.json")
    (tmp_path / "in.csv").write_text(samples_csv(_samples(pair, a)))
    for engine in ("reference", "native"):
        argv = ("replay", tmp_path / "gains.json", "--input", tmp_path / "in.csv", "--engine", engine)
        res = run_cli(*argv, "--output", tmp_path / f"{engine}.csv")
        assert res.code == 0, res.err
    return tmp_path / "gains.json"


def cell_replay(pair, a, tmp_path):
    """``gainlink replay`` of a recorded CSV through the float64 law and the host C."""
    _replay_csv(pair, a, tmp_path)
    rows = [ln for ln in (tmp_path / "native.csv").read_text().splitlines() if not ln.startswith("#")]  # a numeric
    assert len(rows) == STEPS + 1  # the header and one row per sample


def cell_one_step(pair, a, tmp_path):
    """``replay --compare``: the host C's trace checked one step at a time from its own state (against the float64
    law and its bound, or a fixed-point law's words against its integer law), beside the float64 law's."""
    from support.cli import run_cli

    gains = _replay_csv(pair, a, tmp_path)
    argv = ("replay", gains, "--input", tmp_path / "in.csv", "--engine", "reference", "--output", tmp_path / "o.csv")
    res = run_cli(*argv, "--compare", tmp_path / "native.csv")
    assert res.code == 0, res.out + res.err
    assert "one-step check" in res.out


def cell_fidelity(pair, a, tmp_path):
    """The design-time fidelity record of the law's arithmetic (the float32 check; a fixed-point law's certificate
    and its measured headline)."""
    checks = a.checks
    if "fixed_point" in checks:
        fp = checks["fixed_point"]
        assert fp["numeric"] == pair.split("/")[1] and fp["error"]["certified"]
    else:
        assert checks["float32"]["max_rel_u"] <= checks["float32"]["threshold"]


def cell_pil(pair, a, tmp_path):
    """PIL: the law's image in QEMU against the artifact's own model, bit for bit its model, with its twin."""
    from gainlink.hil.loop.pil import make_plant, run_pil

    sim = _samples(pair, a, steps=60)
    plant, twin = (make_plant("artifact", artifact=a) for _ in range(2))
    res = run_pil(a, plant=plant, steps=60, reference=sim.r, signals=sim.s, twin=twin)
    assert res.law == law_of(a).label and res.comparison is not None
    model = law_of(a).model(a)
    S = np.zeros((60, 0)) if sim.s is None else sim.s
    want = [model.step(res.y[k].astype(np.float32).astype(float), sim.r[k], S[k]) for k in range(60)]
    np.testing.assert_array_equal(res.u.view(np.uint32), np.array([w.u for w in want], np.float32).view(np.uint32))
    np.testing.assert_array_equal(res.flags, [w.flags for w in want])


def cell_firmware_run(pair, a, tmp_path):
    """``gainlink firmware run --input``: the host executable of the law replays a CSV."""
    from gainlink.proof.simulation import samples_csv
    from support.cli import run_cli

    a.save(tmp_path / "gains.json")
    (tmp_path / "in.csv").write_text(samples_csv(_samples(pair, a)))
    res = run_cli("firmware", "run", tmp_path / "gains.json", "--input", tmp_path / "in.csv", "--output",
                  tmp_path / "out.csv")  # fmt: skip
    assert res.code == 0, res.err


def cell_cost(pair, a, tmp_path):
    """The instructions of one step of the law's C on the Cortex-M4 image (callees included)."""
    sim = _samples(pair, a, steps=20)
    S = np.zeros((20, 0)) if sim.s is None else sim.s
    cost = law_of(a).cost(a, target="cortex-m4", board="mps2-an386", Y=sim.y, R=sim.r, S=S)
    assert cost.calls == 20 and 0 < cost.cheapest <= cost.dearest


def _upload(where: str):
    def cell(pair, a, tmp_path):
        from gainlink.mavlink.upload import upload

        if where == "host":
            from gainlink.firmware.mavlink_app import mavlink_executable
            from support.mavlink import start_firmware

            fw, port = start_firmware(mavlink_executable(a), None)
            url, stop = f"udpout:127.0.0.1:{port}", fw.stop
        else:
            from gainlink.firmware.build import build
            from gainlink.firmware.uart import QemuUart

            elf = build(a, target="cortex-m4", board="mps2-an386").files["elf"]
            image = QemuUart(elf, board="mps2-an386", protocol="mavlink", port=tcp_port(), lifetime_s=120).start()
            url, stop = image.url, image.stop
        try:
            res = upload(a, connect=url)
        finally:
            stop()
        assert res.changes == () and res.unchanged > 0, "the node's whole table reads back as the artifact's"

    cell.__doc__ = f"The parameter protocol of the law's MAVLink node ({where}): its table is the artifact's."
    return cell


def cell_fuzz(pair, a, tmp_path):
    """The firmware's fuzz harnesses build on the law and a short run finds nothing."""
    from gainlink.firmware import fuzz

    exes = fuzz.build_harnesses(a)
    for name, exe in exes.items():
        fuzz.write_seeds(name, a, tmp_path / name)
        r = fuzz.run(name, exe, tmp_path / name, runs=2000, artifacts=tmp_path / "crashes")
        assert r.crashes == () and r.exit_code == 0, name


CELL_RUNS = {
    "design": cell_design,
    "codegen": cell_codegen,
    "engine.native": _engine("native"),
    "engine.qemu": _engine("qemu"),
    "one_step": cell_one_step,
    "replay": cell_replay,
    "simulate": cell_simulate,
    "fidelity": cell_fidelity,
    "pil": cell_pil,
    "upload.host": _upload("host"),
    "upload.image": _upload("image"),
    "firmware_run": cell_firmware_run,
    "fuzz": cell_fuzz,
    "cost": cell_cost,
    "sil": cell_sil,
    "twins": cell_twins,
    "hil.can": cell_hil_can,
    "hil.mavlink": cell_hil_mavlink,
    "fault.drop": _frame_fault("drop"),
    "fault.delay": _frame_fault("delay"),
    "fault.duplicate": _frame_fault("duplicate"),
    "fault.reorder": _frame_fault("reorder"),
    "fault.nan": cell_fault_nan,
    "fault.silent": _process_fault("silent", "controller silent for 0.5 s"),
    "fault.crash": _process_fault("crash", "controller exited with status -9"),
    "realtime.host": cell_realtime_host,
    "realtime.qemu": cell_realtime_qemu,
    "slcan": cell_slcan,
    "campaign.sil": _campaign_cell("sil"),
    "campaign.hil": _campaign_cell("hil"),
}

#: The cell's representative in `make test`: the pair it was broken or refused for, else one no other test covers.
REPRESENTATIVE = {
    "design": "scheduled/float32",
    "codegen": "lq/q15",
    "engine.native": "lq/q15",
    "engine.qemu": "scheduled/float32",
    "one_step": "lq/q15",
    "replay": "lq/q31",
    "simulate": "scheduled/float32",
    "fidelity": "mpc/float32",
    "pil": "lq/q15",
    "upload.host": "lq/q15",
    "upload.image": "scheduled/float32",
    "firmware_run": "scheduled/float32",
    "fuzz": "scheduled/float32",
    "cost": "lq/q15",
    "sil": "lq/q15",
    "twins": "scheduled/float32",
    "hil.can": "lq/q15",
    "hil.mavlink": "mpc/float32",
    "fault.drop": "lq/q31",
    "fault.delay": "scheduled/float32",
    "fault.duplicate": "scheduled/float32",
    "fault.reorder": "scheduled/float32",
    "fault.nan": "lq/q31",
    "fault.silent": "scheduled/float32",
    "fault.crash": "scheduled/float32",
    "realtime.host": "lq/q31",
    "realtime.qemu": "scheduled/float32",
    "slcan": "lq/q15",
    "campaign.sil": "mpc/float32",
    "campaign.hil": "scheduled/float32",
}


def _check(cell: str, pair: str, artifacts, tmp_path) -> None:
    a = artifacts[pair]
    law = law_of(a)
    reason = law.capabilities.cannot.get(cell)
    if reason is not None:  # declared: the one generated line, and nothing run
        with pytest.raises(Exception, match=f"^{cell} is not available for the {law.label} law: "):
            law.refuse(cell)
        return
    CELL_RUNS[cell](pair, a, tmp_path)


@pytest.mark.parametrize("cell", sorted(CELL_RUNS))
def test_a_representative_of_each_cell_runs(cell, artifacts, tmp_path):
    _check(cell, REPRESENTATIVE[cell], artifacts, tmp_path)


@pytest.mark.matrix
@pytest.mark.parametrize("pair", PAIRS)
@pytest.mark.parametrize("cell", sorted(CELL_RUNS))
def test_every_cell_for_every_law(cell, pair, artifacts, tmp_path):
    _check(cell, pair, artifacts, tmp_path)


def test_a_reference_controller_over_a_link_runs_the_laws_python_node(artifacts, tmp_path):
    cell_reference_over_a_link("scheduled/float32", artifacts["scheduled/float32"], tmp_path)


def test_the_layers_below_the_laws_refuse_from_the_pairs_declaration(artifacts):
    """One declaration per pair (shipping.law_c.CANNOT): the law's refusal and the firmware tooling's (below the
    laws) are the same generated line; the fuzz harnesses refuse each law that declares it cannot fuzz, before
    anything is built, and a float32 lq artifact passes."""
    from gainlink.errors import LawError
    from gainlink.firmware import fuzz
    from gainlink.shipping import law_c

    refused = []
    for pair, a in artifacts.items():
        law = law_of(a)
        for cell in CELLS:
            reason = law_c.CANNOT[pair].get(cell)
            if reason is None:
                law_c.refuse(a, cell)  # nothing to say
                continue
            line = f"{cell} is not available for the {law.label} law: {reason}"
            with pytest.raises(LawError) as below:
                law_c.refuse(a, cell)
            with pytest.raises(LawError) as above:
                law.refuse(cell)
            assert str(below.value) == str(above.value) == line
            refused.append((pair, cell))
    assert sorted(refused) == [
        ("lq/q15", "fuzz"),
        ("lq/q31", "fuzz"),
        ("mpc/float32", "fidelity"),
        ("scheduled/float32", "fuzz"),
    ]
    for pair in ("scheduled/float32", "lq/q31"):
        with pytest.raises(LawError, match=f"^fuzzing is not available for the {law_of(artifacts[pair]).label} law"):
            fuzz.build_harnesses(artifacts[pair])


def test_every_cell_is_in_the_table_and_only_scheduled_on_integers_is_not_a_pair():
    from gainlink.errors import LawError
    from gainlink.laws import law_for

    assert set(REPRESENTATIVE) == set(CELL_RUNS) == set(CELLS)
    for numeric in ("q31", "q15"):
        with pytest.raises(LawError, match="a scheduled law on integers is time-varying"):
            law_for("scheduled", numeric)


def test_a_scheduled_hil_campaign_is_checked_on_the_client_before_anything_is_built(artifacts, tmp_path):
    """Its run's plan (the law's trim, its external signals) is made in the campaign's preflight: a missing
    ``[schedule_signal]`` is one line there, not an error in every run after the firmware was built."""
    from gainlink.hil.campaign.config import CampaignError, parse_campaign
    from gainlink.hil.campaign.plan import plan_campaign

    pair = "scheduled/float32"
    a = artifacts[pair]
    a.save(tmp_path / "gains.json")
    data = _campaign(pair, a, "hil") | {"artifact": str(tmp_path / "gains.json")}
    del data["scenario"]["schedule_signal"]
    with pytest.raises(CampaignError, match=r"the artifact is scheduled on load: give \[schedule_signal.NAME\]"):
        plan_campaign(parse_campaign(data))
