"""The rate a scheduled law ships is a certified one (issue 29, part 1), checked against an oracle of the tests'
own (``support.sched_paths``: the velocity loop written out from the law's step on the artifact's numbers, and
periodic sigma paths searched there: holds, jumps and ramps between levels of the envelope).

The spring of ``schedule_cases`` scheduled 1 -> 65 shipped ``rate_max: null`` ("stable at every rate tried") before:
jumping between its ends with dwells of 18 and 16 samples grows 1.0068 per step. Now it ships a rate certified by a
sigma-dependent Lyapunov function (2.71/s measured), which no path the oracle tries at that rate breaks, and the
falsifier reports a path that grows above it. The showcase ships certified (2.78/s measured). The spring scheduled
1 -> 400 certifies no rate within the default refinements: refused in one line, unless its spec declares a rate
uncertified, which every place the rate appears then says.
"""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest
from gainlink.laws import design as design_spec
from gainlink.shipping.artifact import from_dict, seal
from gainlink.spec import load_spec, parse_spec
from schedule_cases import external_tank, spring
from support.cli import assert_refused, run_cli
from support.designs import designed
from support.paths import EXAMPLES
from support.sched_paths import LoopModel, adversarial, hold_ramp_hold
from support.shared import once_per_run, shared_lmi_solves

pytestmark = pytest.mark.usefixtures("quiet_design_warnings")
# The spring 1 -> 65 designed with its certificate (16 CPU-s), by one worker for its three tests: on three at once,
# two would wait for the first
ON_SPRING65 = pytest.mark.xdist_group("spring65")


def _spring65() -> dict:
    """The spring 1 -> 65 with a spec rate_max above what certifies (the design ships the certified one)."""
    data = spring(65.0)
    data["schedule"]["rate_max"] = 10.0
    return data


def _uncertified() -> dict:
    """The spring 1 -> 400 with its rate declared uncertified (0.5/s, the old simulated verdict)."""
    data = spring(400.0)
    data["schedule"].update(rate_max=0.5, rate_certified=False)
    return data


@pytest.fixture(scope="module")
def spring65():
    return designed(_spring65())


def _reduced_matrix(model: LoopModel, sigma: float, Ci: np.ndarray) -> np.ndarray:
    """The oracle's loop on [x; delta; u_prev; y_prev] (e_prev = -Ci y_prev after the first step)."""
    A = model.step_matrix(sigma)
    q, p = Ci.shape
    r = A.shape[0] - q
    E = np.vstack([np.eye(r), np.hstack([np.zeros((q, r - p)), -Ci])])
    return A[:r] @ E


@pytest.mark.slow(cpu=16)
@ON_SPRING65
def test_the_spring_ships_a_certified_rate_that_no_path_within_it_breaks(spring65):
    """rate_max is certified, below the spec's 10/s (said in a warning's words in the record), and the oracle's
    worst hold/jump/ramp path at that rate decays; the recorded P(sigma) makes x' P x decrease at 300 random pairs
    of sigmas within one step of each other on the loop itself."""
    art = from_dict(spring65)
    S, v = art.schedule, art.checks["schedule"]["variation"]
    assert S.rate_certified and 0.0 < S.rate_max < 10.0 and v["certified_rate"] == S.rate_max
    assert v["rate_source"] == (
        "the fastest rate a sigma-dependent Lyapunov function proves, rounded down; the spec's 10/s is above it"
    )
    assert not v["common_lyapunov"]
    model = LoopModel(spring65)
    growth, _path = adversarial(model, S.rate_max * art.Ts)
    assert growth < 1.0
    cert = v["certificate"]
    nodes, Ps = np.array(cert["nodes"]), np.array(cert["P"])
    P_at = lambda s: np.array([[np.interp(s, nodes, Ps[:, i, j]) for j in range(Ps.shape[2])]  # noqa: E731
                               for i in range(Ps.shape[1])])  # fmt: skip
    rng = np.random.default_rng(3)
    h = S.rate_max * art.Ts
    for _ in range(300):
        s = rng.uniform(0.0, 1.0)
        s2 = float(np.clip(s + rng.uniform(-h, h), 0.0, 1.0))
        A = _reduced_matrix(model, s, art.Ci)
        assert np.linalg.eigvalsh(P_at(s) - A.T @ P_at(s2) @ A)[0] > 0


@pytest.mark.slow(cpu=16)
@ON_SPRING65
def test_the_old_verdict_is_broken_and_the_falsifier_finds_a_growing_path(spring65):
    """The old verdict (rate_max null, "confirmed by simulation"): jumping between the ends with dwells of 18 and
    16 samples grows 1.0068 per step (the oracle). The falsifier now reports a growing path above the certified
    rate, which the oracle reproduces from the record, and the path it found worst at rate_max, which decays."""
    art = from_dict(spring65)
    model = LoopModel(spring65)
    assert model.growth(np.concatenate([np.full(18, 0.0), np.full(16, 1.0)])) == pytest.approx(1.0068, abs=1e-4)
    f = art.checks["schedule"]["variation"]["falsifier"]
    assert f["first_growing_rate"] > art.schedule.rate_max
    w = f["worst"]
    path = hold_ramp_hold(w["low"], w["high"], w["dwell_low"], w["dwell_high"], w["rate"] * art.Ts)
    assert w["shape"] == "dwell" and w["growth_per_step"] > 1.0
    assert model.growth(path) == pytest.approx(w["growth_per_step"], rel=1e-9)
    at = f["at_rate_max"]
    assert at["rate"] == art.schedule.rate_max and at["growth_per_step"] < 1.0


@pytest.mark.slow(cpu=16)
@ON_SPRING65
def test_the_reference_law_with_its_rate_limit_holds_under_jumping_sigma(spring65):
    """The float64 law itself, sigma jumping 0 <-> 1 with dwells of 18 and 16 samples (the path that grows
    unlimited): its rate limit flags the jumps and the plant, interpolated at the sigma the law uses, decays from
    1e-3 (it grew to 1e8 in 100 periods with the old rate_max, none)."""
    from gainlink.laws.scheduled.reference import SIGMA_RATE, ScheduledLoop

    art = from_dict(spring65)
    S = art.schedule
    loop, x, flags, norms = ScheduledLoop(art), np.array([1e-3, 0.0]), 0, []
    raw = np.tile(np.concatenate([np.full(18, 0.0), np.full(16, 1.0)]), 100)
    Cd = S.design["Cd"][0]  # the spring measures its position at every stiffness
    assert np.all(S.design["Cd"] == Cd)
    for s in raw:
        step = loop.step(Cd @ x, [0.0], [s])
        flags |= step.sigma_flags
        Ad, Bd, _, _ = S.plant_at(step.sigma)
        x = Ad @ x + Bd @ step.u
        norms.append(float(np.linalg.norm(x)))
    assert flags & SIGMA_RATE and max(norms[-340:]) < 1e-9


def _designed(factory):
    """examples/tank_showcase_load.toml designed, its certificate's LMI solves shared with the showcase's tank."""
    with shared_lmi_solves(factory):
        return design_spec(load_spec(EXAMPLES / "tank_showcase_load.toml")).artifact


@pytest.fixture(scope="module")
def showcase(tmp_path_factory):
    """examples/tank_showcase_load.toml (the showcase's law, sigma external) designed once per test run."""
    return once_per_run(tmp_path_factory, "tank_showcase_load", lambda: _designed(tmp_path_factory))


@pytest.mark.slow(cpu=31)  # with the example campaign of test_sched_campaign_example, which reads the same design
@pytest.mark.xdist_group("tank_showcase_load")
def test_the_showcase_ships_certified(showcase):
    """The showcase's rate_max is certified (2.78/s measured; the old one, 2.8/s, was simulated) and the oracle's
    worst path at it decays."""
    art = from_dict(showcase)
    S, v = art.schedule, art.checks["schedule"]["variation"]
    assert S.rate_certified and S.rate_max >= 2.5 and v["certified_rate"] == S.rate_max
    growth, _ = adversarial(LoopModel(showcase), S.rate_max * art.Ts)
    assert growth < 1.0


def _toml(data: dict) -> str:
    from gainlink.hil.plants import toml_write

    return toml_write.dumps(data, header="test spec")


def test_no_certified_rate_is_refused_in_one_line_naming_where(tmp_path):
    """The spring 1 -> 400 (frozen stable everywhere, proved) certifies no rate within the default refinements:
    one line naming the interval where the search binds, exit 2, nothing written (it shipped a simulated 0.5/s)."""
    spec = tmp_path / "spec.toml"
    spec.write_text(_toml(spring(400.0)))
    res = assert_refused(
        ["design", spec, "--out", tmp_path / "out"], "no Lyapunov function certifies any rate of k", tmp_path
    )
    assert "k in [" in res.err and "rate_certified = false" in res.err


@pytest.mark.slow(cpu=7)
def test_a_declared_uncertified_rate_ships_and_says_so_wherever_it_appears(tmp_path):
    """rate_max 0.5 with rate_certified = false: the artifact, the design's (JSON and lines) and analyze's output,
    the warnings, the exported header and a run's report all say "not certified"; nothing claims a proof of the
    rate (the old design warned "stability is proved only for a slowly moving k" with nothing proved)."""
    from gainlink.laws.scheduled.design import describe_schedule
    from gainlink.laws.scheduled.run import schedule_lines
    from gainlink.shipping.artifact import load
    from gainlink.shipping.export_c import render_export

    spec = tmp_path / "spec.toml"
    spec.write_text(_toml(_uncertified()))
    design = run_cli("design", spec, "--out", tmp_path / "out", "--json")
    assert design.code == 0, design
    printed = json.loads(design.out)
    assert printed["rate_max"] == 0.5 and printed["rate_certified"] is False
    warnings = printed["warnings"]
    assert any("not certified" in w for w in warnings) and not any("proved" in w for w in warnings)
    art = load(tmp_path / "out" / "gains.json")
    assert art.schedule.rate_max == 0.5 and not art.schedule.rate_certified
    v = art.checks["schedule"]["variation"]
    assert v["rate_max"] == 0.5 and not v["rate_certified"] and v["certified_rate"] is None
    lines = describe_schedule(art.checks["schedule"])  # what `gainlink design` prints
    assert "rate_max the law enforces on k: 0.5/s, not certified (the spec's, declared not certified" in lines[-1]
    assert any(line.startswith("moving k: no rate certified") for line in lines)
    analyze = run_cli("analyze", spec)
    assert analyze.code == 0 and "0.5/s, not certified" in analyze.out
    assert "rate_max 0.5/s, NOT certified" in render_export(art)["gl_gains.h"]
    line = schedule_lines({"sigma": "k", "source": "external", "points": [0.0, 1.0], "rate_max": 0.5,
                           "rate_certified": False, "sigma_min": 0.0, "sigma_max": 1.0, "coverage": 1.0,
                           "max_rate": 0.5, "held_steps": 0, "clipped_steps": 0, "rate_limited_steps": 3})  # fmt: skip
    assert "rate_max 0.5/s, not certified" in line[0]


def test_an_artifact_from_before_rate_certified_loads_as_not_certified(tmp_path):
    """A schema-2 artifact without schedule.rate_certified (written before it) loads, and its rate counts as not
    certified: nothing in it was proved to the standard a certified rate now needs."""
    data = designed(external_tank(rate_max=2.0))
    old = copy.deepcopy(data)
    del old["schedule"]["rate_certified"]
    art = from_dict(seal(old))
    assert art.schedule.rate_max == 2.0 and art.schedule.rate_certified is False
    assert from_dict(data).schedule.rate_certified is True


def test_a_path_growing_within_a_certified_rate_stops_the_design(monkeypatch):
    """The falsifier finding a path that grows at or below a certified rate contradicts the certificate: an
    internal error, never an artifact (made to happen here: the tank's common Lyapunov function against a scan
    that reports growth)."""
    from gainlink.laws.scheduled import variation as V
    from gainlink.laws.scheduled.rate import Path, RateScan

    def growing(_loops, points, Ts, dwells):
        path = Path(float(points[0]), float(points[-1]), 3, 3, 1.0, 10, 2.0)
        return RateScan(np.array([1.0]), np.array([path.growth]), path, dwells)

    monkeypatch.setattr(V, "scan_rates", growing)
    with pytest.raises(V.CertificateContradiction, match="common Lyapunov function was proved"):
        design_spec(parse_spec(external_tank()))


def test_a_certified_rate_too_slow_to_cross_the_envelope_warns_with_the_time():
    """crossing_warning: sigma needing longer than 100 closed-loop time constants to cross the envelope at the
    certified rate is said, with the time; a faster one, an uncertified one or no limit is not."""
    from types import SimpleNamespace

    from gainlink.laws.scheduled.variation import crossing_warning

    slow = SimpleNamespace(rate_certified=True, rate_max=0.001)
    text = crossing_warning(slow, span=1.0, Ts=0.02, tau_samples=19.0, sigma="k")
    assert text is not None and "1000 s to cross the envelope" in text and "38 s" in text
    for v in (SimpleNamespace(rate_certified=True, rate_max=1.0), SimpleNamespace(rate_certified=False,
              rate_max=0.001), SimpleNamespace(rate_certified=True, rate_max=None)):  # fmt: skip
        assert crossing_warning(v, span=1.0, Ts=0.02, tau_samples=19.0, sigma="k") is None


SPRINGS = [(45.0, "predictor"), (75.0, "predictor"), (85.0, "predictor"), (65.0, "current")]


@pytest.mark.matrix
@pytest.mark.parametrize(("k_end", "form"), SPRINGS)
def test_the_spring_family_ships_rates_no_path_breaks(k_end, form):
    """Every spring 1 -> 45 ... 85 (and the current-form observer) ships a certified rate at which the oracle's
    worst path decays; the rate the old verdict shipped for 1 -> 85 (15.8/s, simulated) grows along hold 14,
    ramp at it, hold 12, ramp back (1.0208 per step measured)."""
    data = spring(k_end)
    data["observer"]["form"] = form
    art_data = designed(data)
    art = from_dict(art_data)
    assert art.schedule.rate_certified and art.schedule.rate_max is not None
    model = LoopModel(art_data)
    growth, _ = adversarial(model, art.schedule.rate_max * art.Ts)
    assert growth < 1.0
    if k_end == 85.0 and form == "predictor":
        old = 50.0 * 10 ** (-0.5)  # the scan's grid rate the old verdict shipped
        assert model.growth(hold_ramp_hold(0.0, 1.0, 14, 12, old * art.Ts)) > 1.02
        assert art.schedule.rate_max < old
