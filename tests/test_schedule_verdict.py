"""The verdicts on a scheduled design: the Lyapunov certificates re-checked independently, the rate certificate
against switching sequences it must (and need not) cover, the simulated rate, the grid, the artifact."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from gainlink.errors import DesignError
from gainlink.shipping.artifact import from_dict
from gainlink.spec import parse_spec
from gainlink.synthesis import synthesize
from gainlink.synthesis.lpv import bernstein_vertices, velocity_loop
from gainlink.synthesis.lyapunov import common_lyapunov, rate_certificate
from gainlink.synthesis.schedule_rate import RATE_GRID, monodromy_radius, trajectories
from schedule_cases import external_tank, tank_dict
from support.designs import designed


def _rot(theta: float) -> np.ndarray:
    return np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])


def _elliptic(k: float) -> np.ndarray:
    """0.9 times a quarter turn in the metric diag(1, k^2): stable alone (|z| = 0.9)."""
    D = np.diag([1.0, k])
    return 0.9 * D @ _rot(np.pi / 2) @ np.linalg.inv(D)


def test_common_lyapunov_exists_exactly_when_switching_is_stable():
    """Scaled rotations share P = I: a certificate is found and re-checks. Two ellipses whose alternation grows
    (spectral radius of A0 A1 above one) can have no common P: none is returned."""
    verts = [0.8 * _rot(t) for t in (0.1, 0.7, 2.0)]
    cert = common_lyapunov(verts)
    assert cert is not None and cert.rate is None
    P = cert.P[0]
    assert all(np.linalg.eigvalsh(P - V.T @ P @ V)[0] > 0 for V in verts)
    A0, A1 = _elliptic(3.0), _elliptic(1 / 3.0)
    assert max(abs(np.linalg.eigvals(A0 @ A1))) > 1.0  # the oracle: alternating grows
    assert common_lyapunov([A0, A1]) is None


def _shear(t: float, c: float = 1.5) -> np.ndarray:
    """0.5 I plus a nilpotent part that turns with t: every frozen matrix has |z| = 0.5, switching fast grows."""
    return 0.5 * np.eye(2) + c * np.array([[-t, 1.0], [-t * t, t]])


def test_rate_certificate_covers_what_its_rate_allows():
    """A family stable frozen (|z| = 0.5 everywhere) whose alternation between its ends grows: no common P, but a
    P(sigma) certifies a rate. Every sigma trajectory within that rate that the scan tries is stable (their
    monodromy matrices, multiplied out here from the family itself); switching end to end every step is not, and
    needs a rate above the certified one."""
    assert max(abs(np.linalg.eigvals(_shear(0.0) @ _shear(1.0)))) > 1.0
    nodes = np.linspace(0.0, 1.0, 9)
    pieces = [bernstein_vertices(lambda t, a=a, b=b: _shear(a + (b - a) * t)) for a, b in itertools.pairwise(nodes)]
    assert common_lyapunov([v for p in pieces for v in p]) is None
    Ts = 0.1
    cert = rate_certificate(nodes, pieces, Ts=Ts, rate_hi=1.0 / Ts)
    assert cert is not None and 0.0 < cert.rate < 1.0 / Ts
    for traj in trajectories(np.array([0.0, 0.5, 1.0]), cert.rate * Ts):
        mats = np.array([_shear(s) for s in traj])
        assert monodromy_radius(lambda _s, mats=mats: mats, traj) < 1.0
    # and the certificate itself, re-checked on the curve (not the hull) at pairs |s' - s| <= Ts rate
    rng = np.random.default_rng(2)
    for _ in range(300):
        s = rng.uniform(0, 1)
        s2 = float(np.clip(s + rng.uniform(-1, 1) * cert.rate * Ts, 0, 1))
        P, P2, A = _p_at(cert, s), _p_at(cert, s2), _shear(s)
        assert np.linalg.eigvalsh(P - A.T @ P2 @ A)[0] > 0


def _p_at(cert, s: float) -> np.ndarray:
    return np.array([np.interp(s, cert.nodes, [P[i, j] for P in cert.P]) for i in range(2) for j in range(2)]).reshape(
        2, 2
    )


def test_both_solvers_agree_on_the_conventions():
    """Clarabel and SCS (each through its own triangle order) return matrices that satisfy the LMI."""
    from gainlink.synthesis import lmi

    verts = [0.8 * _rot(t) @ np.diag([1.0, 0.5]) for t in (0.1, 0.7)]
    for run in (lmi._clarabel, lmi._scs):
        fam = lmi.LmiFamily(N=2, nodes=1)
        for V in verts:
            fam.decrease(np.ones(1), np.ones(1), V)
        fam._bounds()
        A = lmi.sp.csc_matrix(np.vstack(fam.rows))
        c = np.zeros(A.shape[1])
        c[-1] = 1.0
        status, x = run(A, np.concatenate(fam.rhs), c, cones=len(fam.rows), N=2)
        P = lmi.smat(x[:3], 2)
        assert status == "solved"
        assert np.linalg.eigvalsh(P)[0] > 0.99 and all(np.linalg.eigvalsh(P - V.T @ P @ V)[0] > 0.99 for V in verts)


def test_bernstein_hull_holds_the_curve():
    """Every matrix of a cubic in lambda lies in the convex hull of its Bernstein vertices (checked through a
    separating functional: no random direction sees the curve beyond the vertices)."""
    rng = np.random.default_rng(0)
    C = rng.normal(size=(4, 3, 3))
    fn = lambda t: C[0] + t * C[1] + t**2 * C[2] + t**3 * C[3]  # noqa: E731
    V = bernstein_vertices(fn)
    assert np.allclose(V[0], fn(0.0)) and np.allclose(V[-1], fn(1.0))
    for _ in range(200):
        W = rng.normal(size=(3, 3))
        top = max(float(np.sum(W * v)) for v in V)
        assert all(float(np.sum(W * fn(t))) <= top + 1e-12 for t in np.linspace(0, 1, 51))


@pytest.fixture(scope="module")
def tank():
    return from_dict(designed(tank_dict()))


def test_tank_certificate_rechecked_on_a_dense_grid(tank):
    """The recorded common P makes x' P x decrease for the velocity loop at every sigma of a dense grid (not only
    at the hull's vertices), and under random jumps of sigma the law's state contracts in that metric."""
    var = tank.checks["schedule"]["variation"]
    assert var["common_lyapunov"] and var["rate_max"] is None
    P = np.array(var["certificate"]["P"][0])
    S = tank.schedule
    for sigma in np.linspace(S.points[0], S.points[-1], 301):
        A = velocity_loop(S.plant_at(sigma), S.coefficients_at(sigma), Ci=tank.Ci)
        assert np.linalg.eigvalsh(P - A.T @ P @ A)[0] > 0
    rng = np.random.default_rng(1)
    x = rng.normal(size=P.shape[0])
    for _ in range(200):
        sigma = rng.uniform(S.points[0], S.points[-1])
        x_next = velocity_loop(S.plant_at(sigma), S.coefficients_at(sigma), Ci=tank.Ci) @ x
        assert x_next @ P @ x_next < x @ P @ x
        x = x_next


def test_grid_and_points_recorded(tank):
    """Every point's own checks and the grid's (>= 10 per interval, stable, margins) are in checks.schedule."""
    sch = tank.checks["schedule"]
    assert [p["sigma"] for p in sch["points"]] == [0.04, 0.25, 1.0]
    assert all(p["spectral_radius"] < 1 for p in sch["points"])
    assert sch["grid"]["per_interval"] >= 10 and sch["grid"]["sigma_count"] == 21 and sch["grid"]["stable"]
    assert sch["grid"]["min_phase_margin_deg"] > 30
    assert tank.data["schema_version"] == 2 and tank.anti_windup == "velocity"
    assert set(tank.data["schedule"]["varying"]) >= {"Kx", "F", "u_op"}


def test_unstable_between_points_is_refused():
    """Two points whose interpolated law is unstable in the middle (the plant's gain flips sign between them
    while each point is designed for its own): refused, naming where."""
    data = external_tank()
    data["schedule"]["points"] = [0.0, 1.0]
    entries = data["schedule"]["plant"]
    entries[1]["B"] = [[-10.0], [0.0]]
    data["schedule"]["plant"] = [entries[0], entries[1]]
    with pytest.raises(DesignError, match="unstable frozen at sigma"):
        synthesize(parse_spec(data))


def test_spec_rate_max_is_kept_and_recorded():
    """A spec's rate_max is what the law enforces when the verdict allows any rate."""
    art = from_dict(designed(external_tank(rate_max=0.3)))
    assert art.schedule.rate_max == 0.3
    assert art.checks["schedule"]["variation"]["rate_max_source"].startswith("spec")


def _growth(art, sigma: np.ndarray, periods: int = 6) -> tuple[float, float]:
    """The scheduled law itself around the interpolated spring, sigma repeating one period ``sigma``: the plant
    state's norm after the first period and after the last."""
    from gainlink.proof.scheduled_reference import ScheduledLoop

    S = art.schedule
    loop, x, norms = ScheduledLoop(art), np.array([1e-3, 0.0]), []
    for s in np.tile(sigma, periods):
        Ad, Bd, Cd, _ = S.plant_at(s)
        u = loop.step(Cd @ x, [0.0], [s]).u
        x = Ad @ x + Bd @ u
        norms.append(float(np.linalg.norm(x)))
    return norms[sigma.size - 1], norms[-1]


def test_without_a_certificate_the_simulated_rate_is_rate_max_and_holds():
    """No common P and no certified rate: the simulated stable rate becomes rate_max (with the warning). The law
    run at that rate across the envelope decays; the same law without the limit, at the next rate the scan tried,
    grows on the sweep of the verdict's set the scan found worst (a sub-range: across the whole envelope it is
    still stable there)."""
    from gainlink.shipping.artifact import seal
    from gainlink.synthesis.schedule_variation import loops_at
    from schedule_cases import spring

    result = synthesize(parse_spec(spring()))
    art = from_dict(result.artifact)
    v = art.checks["schedule"]["variation"]
    assert not v["common_lyapunov"] and v["certified_rate"] is None
    assert v["rate_max"] == v["simulated_stable_rate"] == art.schedule.rate_max > 0
    assert v["rate_max_source"].startswith("simulation") and any("no common Lyapunov" in w for w in result.warnings)
    first, last = _growth(art, trajectories(art.schedule.points, art.schedule.rate_max * art.Ts)[0])
    assert last < 1e-2 * first
    free = from_dict(seal(dict(result.artifact, schedule=dict(result.artifact["schedule"], rate_max=None))))
    faster = art.schedule.rate_max * 10 ** (4 / (RATE_GRID - 1))  # the scan's next rate (four decades)
    L, sweeps = loops_at(art.schedule, art.Ci), trajectories(art.schedule.points, faster * art.Ts)
    worst = max(sweeps, key=lambda t: monodromy_radius(L, t))
    first, last = _growth(free, worst, periods=100)
    assert last > 10 * first
    first, last = _growth(free, sweeps[0])
    assert last < 1e-2 * first
