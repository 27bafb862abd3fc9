"""The scheduled law (velocity form) against independent oracles: python-control at each frozen point, a
hand-derived interpolation, and the law's own state-space form checked against its step map."""

from __future__ import annotations

import control as ct
import numpy as np
import pytest
from gainlink.laws import design as design_spec
from gainlink.laws.scheduled.lpv import velocity_loop
from gainlink.laws.scheduled.reference import SIGMA_CLIPPED, SIGMA_HELD, SIGMA_RATE, ScheduledLoop
from gainlink.proof.sampled_plant import SampledPlant
from gainlink.shipping.artifact import from_dict
from gainlink.spec import parse_spec
from schedule_cases import external_tank
from support.designs import designed

# One worker runs this module (make test: --dist loadgroup): the scheduled designs, made once.
# one worker runs the module (8 CPU-s: the per-point oracles designed once per form): started first
pytestmark = [pytest.mark.xdist_group("test_schedule_law"), pytest.mark.slow(cpu=8)]


@pytest.fixture(scope="module", params=["predictor", "current"])
def scheduled(request):
    """(spec, artifact) of the external-sigma tank in each observer form (designed once per run: the predictor form is
    the tank six other modules use)."""
    data = external_tank(form=request.param)
    return parse_spec(data), from_dict(designed(data))


def _hand_coefficients(art_i, Ts: float) -> dict:
    """The positional law's coefficients of one unscheduled artifact, derived here from Ad Bd Cd Dd K L M Ki."""
    n = art_i.n
    if art_i.observer_form == "current":
        X = np.eye(n) - art_i.M @ art_i.Cd
        return {"F": art_i.Ad @ X, "G": art_i.Bd, "Ly": art_i.Ad @ art_i.M, "Kx": art_i.K @ X,
                "Ky": art_i.K @ art_i.M, "Ki": art_i.Ki}  # fmt: skip
    return {"F": art_i.Ad - art_i.L @ art_i.Cd, "G": art_i.Bd - art_i.L @ art_i.Dd, "Ly": art_i.L, "Kx": art_i.K,
            "Ky": np.zeros((art_i.m, art_i.p)), "Ki": art_i.Ki}  # fmt: skip


_POINTS: dict[str, list] = {}  # spec name/observer form -> its points' artifacts


def _points(spec):
    """Each point designed on its own (schema 1, today's pipeline) with the same per-point settings (once per
    observer form: twelve tests of each form compare against them)."""
    key = f"{spec.name}/{spec.observer.form}"
    if key not in _POINTS:
        _POINTS[key] = _design_points(spec)
    return _POINTS[key]


def _design_points(spec):
    from dataclasses import replace

    out = []
    for i in range(spec.schedule.size):
        p = spec.at_point(i)
        p = replace(p, limits=replace(p.limits, anti_windup="clamp"),
                    implementation=replace(p.implementation, float32_check=False))  # fmt: skip
        out.append(from_dict(design_spec(p).artifact))
    return out


def _frozen_oracle(spec, arts, sigma: float):
    """python-control's closed loop at a frozen sigma: the plant and the positional law, each interpolated by hand
    between the two points around sigma (lam = (sigma - s_i) / (s_i+1 - s_i)), as discrete StateSpace systems."""
    pts = spec.schedule.points
    i = min(int(np.searchsorted(pts, sigma, side="right")) - 1, len(pts) - 2)
    lam = (sigma - pts[i]) / (pts[i + 1] - pts[i])
    mix = lambda a, b: (1 - lam) * a + lam * b  # noqa: E731
    a0, a1 = arts[i], arts[i + 1]
    c0, c1 = _hand_coefficients(a0, spec.Ts), _hand_coefficients(a1, spec.Ts)
    c = {k: mix(c0[k], c1[k]) for k in c0}
    plant = [mix(getattr(a0, k), getattr(a1, k)) for k in ("Ad", "Bd", "Cd", "Dd")]
    n, q, Ts, Ci = a0.n, a0.q, spec.Ts, a0.Ci
    # law from [dy; dr] to du on [xh; z]: du = -Kx xh - Ky dy - Ki z; xh+ = F xh + G du + Ly dy; z+ = z + Ts(dr - Ci dy)
    A = np.block([[c["F"] - c["G"] @ c["Kx"], -c["G"] @ c["Ki"]], [np.zeros((q, n)), np.eye(q)]])
    B = np.block([[c["Ly"] - c["G"] @ c["Ky"], np.zeros((n, q))], [-Ts * Ci, Ts * np.eye(q)]])
    law = ct.ss(A, B, np.hstack([-c["Kx"], -c["Ki"]]), np.hstack([-c["Ky"], np.zeros((a0.m, q))]), Ts,
                inputs=["y", "r"], outputs=["u"], states=n + q)  # fmt: skip
    sysp = ct.ss(*plant, Ts, inputs=["u"], outputs=["y"])
    return ct.interconnect([sysp, law], inplist=["r"], outlist=["y", "u"], inputs=["r"], outputs=["y", "u"]), plant


@pytest.mark.parametrize("where", [0.0, 0.3, 0.5, 1.0, 1.5, 1.85, 2.0])
def test_frozen_eigenvalues_are_the_design_plus_zeros(scheduled, where):
    """At a fixed sigma (points and between), the velocity loop's eigenvalues are python-control's closed loop of
    the frozen design there plus m + p at z = 0."""
    spec, art = scheduled
    arts = _points(spec)
    pts = spec.schedule.points
    k = int(min(where, len(pts) - 1.001))
    sigma = pts[k] + (where - k) * (pts[min(k + 1, len(pts) - 1)] - pts[k])
    oracle, plant = _frozen_oracle(spec, arts, sigma)
    want = np.concatenate([ct.poles(oracle), np.zeros(art.m + art.p)])
    got = np.linalg.eigvals(velocity_loop(tuple(plant), art.schedule.coefficients_at(sigma), Ci=art.Ci))
    assert _multiset_close(got, want, 1e-7)


def _multiset_close(a, b, tol) -> bool:
    rest = list(b)
    for z in a:
        j = int(np.argmin([abs(z - w) for w in rest]))
        if abs(z - rest[j]) > tol:
            return False
        rest.pop(j)
    return not rest


@pytest.mark.parametrize("sigma", [0.04, 0.1, 0.25, 0.7, 1.0])
def test_small_step_response_equals_the_frozen_design(scheduled, sigma):
    """From the equilibrium at a frozen sigma, a small reference step through the scheduled law (float64, the
    velocity form, stepping the interpolated plant) gives python-control's response of the frozen design."""
    spec, art = scheduled
    oracle, plant = _frozen_oracle(spec, _points(spec), sigma)
    u_op, y_op = art.schedule.trim_at(sigma)
    sim = SampledPlant(*plant, u_op=u_op, y_op=y_op)
    loop = ScheduledLoop(art)
    N, dr = 400, 1e-3
    r = np.full((N, 1), art.Ci @ y_op + dr)
    r[0] = art.Ci @ y_op  # the first step starts the law at rest
    Y, U = [], []
    for k in range(N):
        y = sim.outputs()
        u = loop.step(y, r[k], [sigma]).u
        Y.append(y - y_op)
        U.append(u - u_op)
        sim.advance(u)
    resp = ct.forced_response(oracle, T=np.arange(N) * spec.Ts, U=(r - art.Ci @ y_op).T)
    assert not loop.step(sim.outputs(), r[-1], [sigma]).saturated.any()
    assert np.max(np.abs(np.array(Y)[:, 0] - resp.outputs[0])) < 1e-10 * dr
    assert np.max(np.abs(np.array(U)[:, 0] - resp.outputs[1])) < 1e-10 * dr
    assert abs(np.array(Y)[-1, 0] - dr) < 0.05 * dr  # and it tracked the step


def test_coefficients_interpolate_linearly_by_hand(scheduled):
    """Between points the coefficients are (1 - lam) X_i + lam X_i+1 of the hand-derived per-point ones, and the
    velocity loop's matrix is built from those (not from Ad, L, Cd interpolated separately)."""
    spec, art = scheduled
    arts = _points(spec)
    pts = spec.schedule.points
    for sigma in (0.04, 0.1, 0.2499, 0.25, 0.6, 1.0, 5.0, -1.0):
        s = min(max(sigma, pts[0]), pts[-1])
        i = min(int(np.searchsorted(pts, s, side="right")) - 1, len(pts) - 2)
        lam = (s - pts[i]) / (pts[i + 1] - pts[i])
        c0, c1 = _hand_coefficients(arts[i], spec.Ts), _hand_coefficients(arts[i + 1], spec.Ts)
        got = art.schedule.coefficients_at(sigma)
        for k in ("F", "G", "Ly", "Kx", "Ky"):
            assert np.allclose(got[k], (1 - lam) * c0[k] + lam * c1[k], rtol=1e-12, atol=1e-14), (sigma, k)
        assert np.allclose(got["Kz"], spec.Ts * ((1 - lam) * c0["Ki"] + lam * c1["Ki"]), rtol=1e-12, atol=1e-14)


def test_velocity_loop_is_the_step_map_of_the_law(scheduled):
    """The matrix the Lyapunov and rate checks analyse is the law's own step, unsaturated: stepping ScheduledLoop
    and a plant from random states equals velocity_loop times the state, sigma moving each step."""
    _, art = scheduled
    rng = np.random.default_rng(3)
    S = art.schedule
    loop = ScheduledLoop(art)
    n, m, p, q = art.n, art.m, art.p, art.q
    for _ in range(20):
        sigma = float(rng.uniform(S.points[0], S.points[-1]))
        # small increments about a command mid-range: nothing saturates, and the step map is linear in all of it
        x, delta, yp, ep = (0.01 * rng.normal(size=k) for k in (n, n, p, q))
        up = 0.5 + 0.01 * rng.normal(size=m)
        st = loop.state
        st.delta, st.u_prev, st.y_prev, st.e_prev = delta.copy(), up.copy(), yp.copy(), ep.copy()
        st.sigma = st.sigma_f = sigma
        st.started = True
        Ad, Bd, Cd, Dd = S.plant_at(sigma)
        y = Cd @ x  # Dd = 0 here (the examples are strictly proper, sampled with a hold)
        u = loop.step(y, np.zeros(q), [sigma]).u
        after = np.concatenate([Ad @ x + Bd @ u, st.delta, st.u_prev, st.y_prev, st.e_prev])
        A = velocity_loop((Ad, Bd, Cd, Dd), S.coefficients_at(sigma), Ci=art.Ci)
        assert np.allclose(after, A @ np.concatenate([x, delta, up, yp, ep]), rtol=1e-12, atol=1e-12)


def test_sigma_hold_clip_rate_and_filter():
    """Sigma non-finite: held and flagged; outside the envelope: clipped and flagged; its change limited to
    Ts * rate_max; filtered first (alpha = 1 - exp(-Ts / tau))."""
    art = from_dict(designed(external_tank(rate_max=0.5, filter_tau=0.2)))
    loop, Ts = ScheduledLoop(art), art.Ts
    y0 = np.array([0.25])
    first = loop.step(y0, [0.25], [0.25])
    assert first.sigma == 0.25 and first.sigma_flags == 0
    held = loop.step(y0, [0.25], [np.nan])
    assert held.sigma == 0.25 and held.sigma_flags == SIGMA_HELD and not held.fault
    alpha = 1 - np.exp(-Ts / 0.2)
    moved = loop.step(y0, [0.25], [3.0])  # clipped to 1.0, filtered, then rate-limited
    assert moved.sigma_flags == SIGMA_CLIPPED | SIGMA_RATE
    assert moved.sigma == pytest.approx(0.25 + Ts * 0.5, rel=1e-15)
    assert loop.state.sigma_f == pytest.approx(0.25 + alpha * (1.0 - 0.25), rel=1e-15)
    small = ScheduledLoop(art)
    small.step(y0, [0.25], [0.25])
    nudge = small.step(y0, [0.25], [0.26])
    assert nudge.sigma_flags == 0 and nudge.sigma == pytest.approx(0.25 + alpha * 0.01, rel=1e-12)


def test_fault_leaves_state_and_sends_safe_command(scheduled):
    """A non-finite sample changes no state (sigma included) and sends u_op at the held sigma, clamped; the law
    then goes on as if the sample had not come."""
    _, art = scheduled
    a, b = ScheduledLoop(art), ScheduledLoop(art)
    ys = [0.25, 0.26, 0.27, 0.27]
    for y in ys[:2]:
        a.step([y], [0.3], [0.5])
        b.step([y], [0.3], [0.5])
    before = a.state.vector()
    bad = a.step([np.nan], [0.3], [0.9])
    assert bad.fault and np.array_equal(a.state.vector(), before)
    assert np.array_equal(bad.u, np.clip(art.schedule.trim_at(a.state.sigma)[0], art.u_min, art.u_max))
    assert np.array_equal(a.step([ys[2]], [0.3], [0.5]).u, b.step([ys[2]], [0.3], [0.5]).u)


def test_reset_starts_without_a_kick(scheduled):
    """The first valid sample after a reset sets y_prev to it: the command is u_op there, whatever y is."""
    _, art = scheduled
    loop = ScheduledLoop(art)
    assert loop.step([np.inf], [0.3], [0.5]).fault
    out = loop.step([0.31], [0.3], [0.5])
    assert np.array_equal(out.u, np.clip(art.schedule.trim_at(0.5)[0], art.u_min, art.u_max))
    assert loop.state.started and np.array_equal(loop.state.y_prev, [0.31])
