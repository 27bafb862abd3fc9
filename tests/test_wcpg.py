"""The worst-case peak gain against independent sums: brute force over a long horizon, scipy's impulse response for
the tail, and closed forms."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal
from gainlink.errors import DesignError
from gainlink.synthesis.wcpg import decay_certificate, wcpg


def _stable(rng, n: int, radius: float) -> np.ndarray:
    A = rng.standard_normal((n, n))
    return A * (radius / np.max(np.abs(np.linalg.eigvals(A))))


def _brute(A, B, C, D, terms: int) -> np.ndarray:
    X, S = B.copy(), np.abs(D).astype(float)
    for _ in range(terms):
        S += np.abs(C @ X)
        X = A @ X
    return S


@pytest.mark.parametrize("seed,n,radius", [(0, 1, 0.5), (1, 2, 0.9), (2, 3, 0.97), (3, 5, 0.95), (4, 4, 0.995)])
def test_wcpg_brackets_the_long_horizon_sum(seed, n, radius):
    rng = np.random.default_rng(seed)
    A, B, C, D = (
        _stable(rng, n, radius),
        rng.standard_normal((n, 2)),
        rng.standard_normal((3, n)),
        rng.standard_normal((3, 2)),
    )
    g = wcpg(A, B, C, D)
    # the horizon leaves a remainder below radius^k / (1 - radius) times the basis scale: far below 1e-9 here
    brute = _brute(A, B, C, D, terms=int(np.log(1e-15) / np.log(radius)) + 200)
    assert np.all(g.lower <= brute) and np.all(brute <= g.upper)
    assert np.max((g.upper - brute) / brute) < 1e-6  # tight: the rigour costs nothing visible
    assert g.converged and g.method == "eigen"


def test_scalar_tail_bound_is_the_closed_form():
    a, b, c = 0.9, 2.0, -3.0
    cert = decay_certificate(np.array([[a]]), np.array([[b]]), np.array([[c]]))
    for N in (0, 10, 100):
        exact = abs(b * c) * a**N / (1 - a)
        assert cert.tail(N)[0, 0] == pytest.approx(exact, rel=1e-8)  # inflated by 1e-9 for its own rounding
        assert cert.tail(N)[0, 0] >= exact * (1 - 1e-15)


@pytest.mark.parametrize("seed,n", [(5, 2), (6, 3), (7, 4)])
def test_tail_bound_against_scipys_impulse_response(seed, n):
    rng = np.random.default_rng(seed)
    A, B, C = _stable(rng, n, 0.9), rng.standard_normal((n, 1)), rng.standard_normal((1, n))
    cert = decay_certificate(A, B, C)
    N, horizon = 40, 600
    _, (h,) = scipy.signal.dimpulse((A, B, C, np.zeros((1, 1)), 1.0), n=N + 1 + horizon)
    exact_tail = np.abs(h[N + 1 :, 0]).sum()  # h[k] = C A^(k-1) B for k >= 1
    bound = cert.tail(N)[0, 0]
    assert exact_tail <= bound <= 20 * exact_tail  # valid, and not vacuous


def test_defective_matrix_uses_a_lyapunov_certificate():
    """A Jordan block: the eigenvalues cannot be isolated, a verified P with A' P A <= gamma^2 P bounds the tail."""
    A = np.array([[0.9, 1.0], [0.0, 0.9]])
    B, C = np.eye(2), np.eye(2)
    g = wcpg(A, B, C)
    brute = _brute(A, B, C, np.zeros((2, 2)), terms=600)
    assert g.method == "lyapunov"
    assert np.all(g.lower <= brute + 1e-12) and np.all(brute <= g.upper)
    assert np.allclose(g.upper, [[10.0, 100.0], [0.0, 10.0]], rtol=1e-6, atol=1e-6)  # 1/(1-a), 1/(1-a)^2


def test_deadbeat_system_sums_its_finite_response():
    A = np.array([[0.0, 1.0], [0.0, 0.0]])  # nilpotent: A^2 = 0
    B, C = np.array([[1.0], [2.0]]), np.array([[1.0, 1.0]])
    g = wcpg(A, B, C)
    assert g.upper[0, 0] == pytest.approx(3.0 + 2.0, rel=1e-8)  # |C B| + |C A B|


@pytest.mark.parametrize("A", [[[1.0]], [[0.5, 0.0], [0.0, -1.01]]], ids=["marginal", "unstable"])
def test_unbounded_peak_gain_is_refused_in_one_line(A):
    with pytest.raises(DesignError, match="the peak gain of the estimate is unbounded") as exc:
        wcpg(np.array(A), np.ones((len(A), 1)), np.ones((1, len(A))), what="the estimate")
    assert "\n" not in str(exc.value)


def test_the_closed_loop_bound_covers_the_rounding_of_forming_its_matrices():
    """A law whose closed loop has an entry formed with cancellation: ``a = F + G Kx`` of floats near 1e8 cancel
    to about 0.999, which float64 rounds by up to half a unit of 1e8 (7e-9), moving the peak gain
    ``|Kx| / (1 - a)`` by 7e-6 of itself, far past what the WCPG's own margin (1e-9) holds. The certificate's
    closed-loop bound is at least the exact peak gain (in rationals, an independent closed form)."""
    from dataclasses import fields
    from fractions import Fraction

    from gainlink.laws.fixed.error import closed_loop_bound
    from gainlink.laws.fixed.ranges import Rounding
    from gainlink.proof.derived_law import DerivedLaw

    G, Kx = 1e4 + 3 * 2.0**-39, -(1e4 + 5 * 2.0**-39)
    F = 1e8 + 0.999
    a_exact = Fraction(F) + Fraction(G) * Fraction(Kx)
    assert F + G * Kx < a_exact  # float64 forming rounds it down: a smaller peak gain
    law = DerivedLaw(
        F=np.array([[F]]), G=np.array([[G]]), Ly=np.zeros((1, 1)), Kx=np.array([[Kx]]), Ky=np.zeros((1, 1)),
        Kz=np.zeros((1, 0)), Tr=np.zeros(0), Ty=np.zeros((0, 1)), Kaw=np.zeros((0, 1)), u_op=np.zeros(1),
        y_op=np.zeros(1), lo=np.full(1, -1e9), hi=np.full(1, 1e9), xh0=np.zeros(1), z0=np.zeros(0),
        anti_windup="none",
    )  # fmt: skip
    plant = (np.array([[0.5]]), np.array([[1e-4]]), np.array([[1.0]]), np.zeros((1, 1)))
    sizes = {"y": 1, "r": 0, "v": 1, "u": 1, "z": 0, "x": 1, "c": 1}
    h = Rounding(**{f.name: np.zeros(sizes[f.name]) for f in fields(Rounding)})
    h = Rounding(**{f.name: getattr(h, f.name) for f in fields(Rounding)} | {"x": np.ones(1)})
    # only xh's rounding drives the loop; the command is Kx xh, and xh+ = a xh + rho (Ly = 0: the plant is not seen)
    exact = abs(Fraction(Kx)) / (1 - a_exact)
    bound = closed_loop_bound(law, plant, h)[0]
    assert Fraction(bound) >= exact
    assert Fraction(bound) <= exact * (1 + Fraction(1, 10**6))  # and no looser than it needs to be
