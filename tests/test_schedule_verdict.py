"""The verdicts' machinery on a scheduled design: the loop's exact polynomial in lambda, the Bernstein hull, the
Lyapunov certificates (frozen, any rate, a rate) re-checked independently, both LMI solvers, and the tank's
records. The spring family and the showcase are in ``test_schedule_rate_proof``."""

from __future__ import annotations

import itertools
from fractions import Fraction

import numpy as np
import pytest
from gainlink.errors import DesignError
from gainlink.laws import design as design_spec
from gainlink.laws.scheduled.certify import Budget, certify_rate, common, prove_frozen, start_pieces
from gainlink.laws.scheduled.hull import LoopHull
from gainlink.laws.scheduled.lpv import bernstein_vertices, loop_polynomial, velocity_loop
from gainlink.shipping.artifact import from_dict
from gainlink.spec import parse_spec
from schedule_cases import external_tank, tank_dict
from support.designs import designed


def _rot(theta: float) -> np.ndarray:
    return np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])


def _elliptic(k: float) -> np.ndarray:
    """0.9 times a quarter turn in the metric diag(1, k^2): stable alone (|z| = 0.9)."""
    D = np.diag([1.0, k])
    return 0.9 * D @ _rot(np.pi / 2) @ np.linalg.inv(D)


def _affine(A0: np.ndarray, A1: np.ndarray) -> LoopHull:
    """The family ``(1 - lam) A0 + lam A1`` on one interval [0, 1], as the certificates see a loop."""
    return LoopHull.of_polynomials([0.0, 1.0], [np.array([A0, A1 - A0])])


def test_common_lyapunov_exists_exactly_when_switching_is_stable():
    """Scaled rotations (and every mix of two) share P = I: a certificate is proved, and the oracle here re-checks
    it on the curve. Two ellipses whose alternation grows (spectral radius of A0 A1 above one) can have no common
    P: none is returned."""
    hull = _affine(0.8 * _rot(0.1), 0.8 * _rot(2.0))
    cert = common(hull, hull.uniform(2))
    assert cert is not None and cert.kind == "common" and cert.margin > 0
    P = cert.P[0]
    for lam in np.linspace(0, 1, 51):
        A = 0.8 * ((1 - lam) * _rot(0.1) + lam * _rot(2.0))
        assert np.linalg.eigvalsh(P - A.T @ P @ A)[0] > 0
    A0, A1 = _elliptic(3.0), _elliptic(1 / 3.0)
    assert max(abs(np.linalg.eigvals(A0 @ A1))) > 1.0  # the oracle: alternating grows
    switching = _affine(A0, A1)
    assert common(switching, switching.uniform(4)) is None


def _shear(t: float, c: float = 1.5) -> np.ndarray:
    """0.5 I plus a nilpotent part that turns with t: every frozen matrix has |z| = 0.5, switching fast grows."""
    return 0.5 * np.eye(2) + c * np.array([[-t, 1.0], [-t * t, t]])


def _p_at(cert, s: float) -> np.ndarray:
    """The certificate's P(s), linear between its nodes (interpolated here)."""
    nodes = [float(v) for v in cert.nodes]
    N = cert.P[0].shape[0]
    return np.array([np.interp(s, nodes, [P[i, j] for P in cert.P]) for i in range(N) for j in range(N)]).reshape(N, N)


def test_rate_certificate_covers_what_its_rate_allows():
    """A family stable frozen (|z| = 0.5 everywhere) whose alternation between its ends grows: no common P, but a
    P(sigma) proves a rate. Re-checked here on the curve itself (not the hull) at 400 random pairs |s' - s| <= Ts
    rate; every hold-and-ramp path at the rate (multiplied out here) decays; switching end to end every step grows
    and needs a rate above the certified one."""
    c = 1.5
    mono = np.array([0.5 * np.eye(2) + c * np.array([[0.0, 1.0], [0.0, 0.0]]), c * np.diag([-1.0, 1.0]),
                     c * np.array([[0.0, 0.0], [-1.0, 0.0]])])  # fmt: skip
    hull = LoopHull.of_polynomials([0.0, 1.0], [mono])
    assert np.allclose(sum(0.3**k * m for k, m in enumerate(mono)), _shear(0.3))
    assert max(abs(np.linalg.eigvals(_shear(0.0) @ _shear(1.0)))) > 1.0
    budget = Budget(60.0)
    pieces, _ = prove_frozen(hull, budget, sigma="s")
    assert common(hull, pieces) is None
    Ts = 0.1
    search = certify_rate(hull, start_pieces(hull, pieces), Ts=Ts, hi=1.0 / Ts, budget=budget)
    cert = search.certificate
    assert cert is not None and 0.0 < cert.rate < 1.0 / Ts and search.unproved > cert.rate
    rng = np.random.default_rng(2)
    for _ in range(400):
        s = rng.uniform(0, 1)
        s2 = float(np.clip(s + rng.uniform(-1, 1) * cert.rate * Ts, 0, 1))
        P, P2, A = _p_at(cert, s), _p_at(cert, s2), _shear(s)
        assert np.linalg.eigvalsh(P)[0] > 0 and np.linalg.eigvalsh(P - A.T @ P2 @ A)[0] > 0
    step = cert.rate * Ts
    for a, b in itertools.combinations(np.linspace(0, 1, 5), 2):
        up = list(np.arange(a + step, b, step))
        for d1, d2 in itertools.product((1, 3, 9), repeat=2):
            path = [a] * d1 + up + [b] * d2 + up[::-1]
            M = np.linalg.multi_dot([_shear(s) for s in path[::-1]] + [np.eye(2)])
            assert max(abs(np.linalg.eigvals(M))) < 1.0


def test_both_solvers_agree_on_the_conventions():
    """Clarabel and SCS (each through its own triangle order) return matrices that satisfy the LMI, and the same
    margin mu."""
    from gainlink.synthesis import lmi

    verts = [0.8 * _rot(t) @ np.diag([1.0, 0.5]) for t in (0.1, 0.7)]
    fam = lmi.LmiFamily(N=2, nodes=1, cap=100.0)
    for V in verts:
        fam.decrease(np.ones(1), np.ones(1), V)
    A, b, c, cones = fam._standard_form()
    mus = []
    for run in (lmi._clarabel, lmi._scs):
        _status, x, _z = run(A, b, c, cones=cones, N=2)
        P, mu = lmi.smat(x[:3], 2), x[-1]
        assert np.linalg.eigvalsh(P)[0] > 0.99 and np.linalg.eigvalsh(P)[-1] < 100.01
        assert all(np.linalg.eigvalsh(P - V.T @ P @ V)[0] > mu - 1e-4 for V in verts) and mu > 0
        mus.append(mu)
    assert mus[0] == pytest.approx(mus[1], rel=1e-3)


def test_bernstein_hull_holds_the_curve():
    """Every matrix of a cubic in lambda on a piece lies in the convex hull of its Bernstein vertices there
    (checked through separating functionals: no random direction sees the curve beyond the vertices)."""
    rng = np.random.default_rng(0)
    C = rng.normal(size=(4, 3, 3))
    fn = lambda t: C[0] + t * C[1] + t**2 * C[2] + t**3 * C[3]  # noqa: E731
    a, b = Fraction(1, 4), Fraction(5, 8)
    V = bernstein_vertices(C, a, b)
    assert np.allclose(V[0], fn(0.25)) and np.allclose(V[-1], fn(0.625))
    for _ in range(200):
        W = rng.normal(size=(3, 3))
        top = max(float(np.sum(W * v)) for v in V)
        assert all(float(np.sum(W * fn(t))) <= top + 1e-12 for t in np.linspace(0.25, 0.625, 51))


def _exact_loop(S, Ci, i: int, lam: Fraction) -> list[list[Fraction]]:
    """The velocity loop at ``lam`` of interval ``i`` in rational arithmetic (Python's Fraction), from the
    artifact's float64 per-point matrices: the oracle of the ball polynomial."""

    def M(a) -> list[list[Fraction]]:
        return [[Fraction(float(v)) for v in row] for row in np.atleast_2d(a)]

    def mul(X, Y):
        return [[sum((X[r][k] * Y[k][col] for k in range(len(Y))), Fraction(0)) for col in range(len(Y[0]))]
                for r in range(len(X))]  # fmt: skip

    def lin(st):
        lo, hi = M(st[i]), M(st[i + 1])
        return [[lo[r][c] + lam * (hi[r][c] - lo[r][c]) for c in range(len(lo[0]))] for r in range(len(lo))]

    def add(*Xs):
        return [[sum((X[r][c] for X in Xs), Fraction(0)) for c in range(len(Xs[0][0]))] for r in range(len(Xs[0]))]

    def neg(X):
        return [[-v for v in row] for row in X]

    Ad, Bd, Cd, Dd = (lin(S.design[k]) for k in ("Ad", "Bd", "Cd", "Dd"))
    c = {k: lin(v) for k, v in S.coef.items()}
    n, m, p, q = len(Ad), len(Bd[0]), len(Cd), Ci.shape[0]
    sizes = np.cumsum([0, n, n, m, p, q])
    sel = [M(np.eye(sizes[-1])[sizes[k] : sizes[k + 1]]) for k in range(5)]
    X, D, Up, Yp, Ep = sel
    du = add(neg(mul(c["Kx"], D)), neg(mul(c["Ky"], add(mul(Cd, X), neg(Yp)))), neg(mul(c["Kz"], Ep)))
    U = add(Up, du)
    Y = add(mul(Cd, X), mul(Dd, U))
    rows = [add(mul(Ad, X), mul(Bd, U)), add(mul(c["F"], D), mul(c["G"], du), mul(c["Ly"], add(Y, neg(Yp)))), U, Y,
            neg(mul(M(Ci), Y))]  # fmt: skip
    return [r for block in rows for r in block]


def test_the_loop_polynomial_is_formed_exactly():
    """The current form's loop (products of up to three interpolated matrices: Bd Ky Cd). Its ball polynomial,
    evaluated at lam = 1/3 in ball arithmetic, contains the loop computed in rational arithmetic here from the same
    float64 matrices, with radii
    below 1e-60 (the margin covers no fit: the old polynomial was fitted, accepted at 1e-8); the float64 polynomial
    is within 1e-13 of the law's own matrices at 0.37."""
    from flint import arb, ctx

    art = from_dict(designed(external_tank(form="current", rate_max=4.0, filter_tau=0.1)))
    S, lam = art.schedule, Fraction(1, 3)
    balls = loop_polynomial(S, art.Ci, 0, balls=True)
    assert 2 <= len(balls) <= 4
    exact = _exact_loop(S, art.Ci, 0, lam)
    with ctx.workprec(256):
        value = sum((arb(lam.numerator) / lam.denominator) ** k * c for k, c in enumerate(balls))
        for row_b, row_e in zip(value, exact):
            for b, e in zip(row_b, row_e):
                assert b.contains(arb(e.numerator) / e.denominator) and float(b.rad()) < 1e-60
    mono = loop_polynomial(S, art.Ci, 0)
    sigma = S.points[0] + 0.37 * (S.points[1] - S.points[0])
    want = velocity_loop(S.plant_at(sigma), S.coefficients_at(sigma), Ci=art.Ci)
    assert np.abs(sum(0.37**k * c for k, c in enumerate(mono)) - want).max() < 1e-13 * max(1.0, np.abs(want).max())


@pytest.fixture(scope="module")
def tank():
    return from_dict(designed(tank_dict()))


def _reduced(A: np.ndarray, art) -> np.ndarray:
    """The loop on [x; delta; u_prev; y_prev] with e_prev = -Ci y_prev (its state after the first step, r = 0)."""
    q = art.Ci.shape[0]
    r = A.shape[0] - q
    E = np.vstack([np.eye(r), np.hstack([np.zeros((q, r - art.p)), -art.Ci])])
    return A[:r] @ E


def test_tank_certificate_rechecked_on_a_dense_grid(tank):
    """The recorded common P makes x' P x decrease for the velocity loop at every sigma of a dense grid (not only
    at the hull's vertices), and under random jumps of sigma the law's state contracts in that metric."""
    var = tank.checks["schedule"]["variation"]
    assert var["common_lyapunov"] and var["rate_max"] is None and var["rate_certified"]
    assert tank.schedule.rate_certified and tank.schedule.rate_max is None
    P = np.array(var["certificate"]["P"][0])
    S = tank.schedule
    for sigma in np.linspace(S.points[0], S.points[-1], 301):
        A = _reduced(velocity_loop(S.plant_at(sigma), S.coefficients_at(sigma), Ci=tank.Ci), tank)
        assert np.linalg.eigvalsh(P - A.T @ P @ A)[0] > 0
    rng = np.random.default_rng(1)
    x = rng.normal(size=P.shape[0])
    for _ in range(200):
        sigma = rng.uniform(S.points[0], S.points[-1])
        x_next = _reduced(velocity_loop(S.plant_at(sigma), S.coefficients_at(sigma), Ci=tank.Ci), tank) @ x
        assert x_next @ P @ x_next < x @ P @ x
        x = x_next


def test_grid_and_points_recorded(tank):
    """Every point's own checks and the grid's (>= 10 per interval, stable, margins) are in checks.schedule, and
    the frozen proof between the points."""
    sch = tank.checks["schedule"]
    assert [p["sigma"] for p in sch["points"]] == [0.04, 0.25, 1.0]
    assert all(p["spectral_radius"] < 1 for p in sch["points"])
    assert sch["grid"]["per_interval"] >= 10 and sch["grid"]["sigma_count"] == 21 and sch["grid"]["stable"]
    assert sch["grid"]["min_phase_margin_deg"] > 30
    frozen = sch["variation"]["frozen"]
    assert frozen["certified"] and frozen["pieces"] >= 2
    ends = [(c["nodes"][0], c["nodes"][-1]) for c in frozen["certificates"]]
    assert ends[0][0] == 0.04 and ends[-1][1] == 1.0 and all(a[1] == b[0] for a, b in itertools.pairwise(ends))
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
        design_spec(parse_spec(data))


def test_spec_rate_max_is_kept_and_recorded():
    """A spec's rate_max is what the law enforces when the verdict allows any rate, and it is certified."""
    art = from_dict(designed(external_tank(rate_max=0.3)))
    assert art.schedule.rate_max == 0.3 and art.schedule.rate_certified
    assert art.checks["schedule"]["variation"]["rate_source"].startswith("the spec's; any rate is certified")
