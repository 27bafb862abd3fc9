"""No hidden coupling (docs/design.md, scheduled law): the scheduled law on the nonlinear tank, scheduled on its own
measured level, linearised numerically about an equilibrium between the points, is the frozen-point design there
(its eigenvalues are those of the velocity loop with the tank's exact linearisation and the coefficients at that
level, plus zeros). The positional form with interpolated trims is not (the contrast that shows the test can
fail). A moving sigma never steps the command."""

from __future__ import annotations

import control as ct
import numpy as np
import pytest
from gainlink.laws.scheduled.lpv import velocity_loop
from gainlink.laws.scheduled.reference import ScheduledLoop
from gainlink.shipping.artifact import from_dict
from schedule_cases import external_tank, tank_dict
from support.designs import designed

C_ORIFICE, TAU_PUMP = 0.4, 0.1  # examples/tank_scheduled.toml's model


def _tank_step(x: np.ndarray, u: float, Ts: float, substeps: int = 200) -> np.ndarray:
    """The nonlinear tank over one sample, RK4 with a held command: dq/dt = (u - q)/tau, dh/dt = q - c sqrt(h)."""
    f = lambda s: np.array([(u - s[0]) / TAU_PUMP, s[0] - C_ORIFICE * np.sqrt(s[1])])  # noqa: E731
    h = Ts / substeps
    for _ in range(substeps):
        k1 = f(x)
        k2 = f(x + h / 2 * k1)
        k3 = f(x + h / 2 * k2)
        k4 = f(x + h * k3)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


@pytest.fixture(scope="module")
def tank():
    return from_dict(designed(tank_dict()))


def _closed_loop_map(art, h0: float):
    """The map (plant state, law state) -> next, at the reference r = h0, with the law's state packed as
    [delta, u_prev, y_prev, e_prev] (sigma follows the level each step: no filter, no rate limit)."""
    n = art.n

    def step(X: np.ndarray) -> np.ndarray:
        loop = ScheduledLoop(art)
        st = loop.state
        x = X[:2]
        st.delta, st.u_prev, st.y_prev, st.e_prev = X[2 : 2 + n].copy(), X[4:5].copy(), X[5:6].copy(), X[6:7].copy()
        st.sigma = st.sigma_f = float(X[5])
        st.started = True
        u = loop.step([x[1]], [h0]).u
        return np.concatenate([_tank_step(x, float(u[0]), art.Ts), st.delta, st.u_prev, st.y_prev, st.e_prev])

    return step


def _jacobian(fn, X0: np.ndarray, eps: float = 1e-7) -> np.ndarray:
    cols = []
    for j in range(X0.size):
        e = np.zeros(X0.size)
        e[j] = eps * max(1.0, abs(X0[j]))
        cols.append((fn(X0 + e) - fn(X0 - e)) / (2 * e[j]))
    return np.array(cols).T


def _exact_linearisation(h0: float, Ts: float):
    A = np.array([[-1 / TAU_PUMP, 0.0], [1.0, -C_ORIFICE / (2 * np.sqrt(h0))]])
    sysd = ct.c2d(ct.ss(A, [[1 / TAU_PUMP], [0.0]], [[0.0, 1.0]], [[0.0]]), Ts)
    return tuple(np.asarray(M, float) for M in (sysd.A, sysd.B, sysd.C, sysd.D))


@pytest.mark.parametrize("h0", [0.1, 0.25, 0.6])
def test_linearised_about_an_equilibrium_the_law_is_the_frozen_design(tank, h0):
    q0 = C_ORIFICE * np.sqrt(h0)
    X0 = np.array([q0, h0, 0.0, 0.0, q0, h0, 0.0])
    step = _closed_loop_map(tank, h0)
    assert np.allclose(step(X0), X0, atol=1e-12)  # an equilibrium of the closed loop
    got = np.linalg.eigvals(_jacobian(step, X0))
    frozen = velocity_loop(_exact_linearisation(h0, tank.Ts), tank.schedule.coefficients_at(h0), Ci=tank.Ci)
    want = np.linalg.eigvals(frozen)
    assert _match(got, want, 1e-5), (np.sort_complex(got), np.sort_complex(want))


def test_positional_form_with_interpolated_trims_is_not(tank):
    """The contrast: the positional law u = u_op(s) - K xh - Ki z with y - y_op(s) fed to the observer, s = y,
    linearised the same way, has eigenvalues the frozen design does not have."""
    h0, S, Ts = 0.6, tank.schedule, tank.Ts
    q0 = C_ORIFICE * np.sqrt(h0)
    d = S.design

    def step(X):
        x, xh, z = X[:2], X[2:4], X[4:5]
        y = x[1]
        i = min(int(np.searchsorted(S.points, y, side="right")) - 1, len(S.points) - 2)
        lam = (y - S.points[i]) / (S.points[i + 1] - S.points[i])
        at = lambda M: M[i] + lam * (M[i + 1] - M[i])  # noqa: E731
        u_op, y_op = at(S.u_op), at(S.y_op)
        u = u_op - at(d["K"]) @ xh - at(d["Ki"]) @ z
        xh_next = at(d["Ad"]) @ xh + at(d["Bd"]) @ (u - u_op) + at(d["L"]) @ (np.array([y]) - y_op - at(d["Cd"]) @ xh)
        return np.concatenate([_tank_step(x, float(u[0]), Ts), xh_next, z + Ts * (h0 - y)])

    X0 = np.concatenate([[q0, h0], _positional_equilibrium(S, h0, q0)])
    assert np.allclose(step(X0), X0, atol=1e-12)
    got = np.linalg.eigvals(_jacobian(step, X0))
    c = S.coefficients_at(h0)
    frozen = np.linalg.eigvals(velocity_loop(_exact_linearisation(h0, Ts), c, Ci=tank.Ci))
    frozen = frozen[np.abs(frozen) > 1e-9]  # without the velocity form's zeros: the positional loop's own
    assert not _match(got, frozen, 1e-3)


def _positional_equilibrium(S, h0: float, q0: float) -> np.ndarray:
    """xh and z where that law holds the tank at h0: y_op(h0) = h0 (the points' y_op are the points), so the
    observer sees only the trim error du = q0 - u_op(h0): (I - Ad + L Cd) xh = Bd du, Ki z = u_op - q0 - K xh."""
    i = min(int(np.searchsorted(S.points, h0, side="right")) - 1, len(S.points) - 2)
    lam = (h0 - S.points[i]) / (S.points[i + 1] - S.points[i])
    at = lambda M: M[i] + lam * (M[i + 1] - M[i])  # noqa: E731
    d = S.design
    du = q0 - at(S.u_op)
    xh = np.linalg.solve(np.eye(2) - at(d["Ad"]) + at(d["L"]) @ at(d["Cd"]), at(d["Bd"]) @ du)
    z = np.linalg.solve(at(d["Ki"]), at(S.u_op) - q0 - at(d["K"]) @ xh)
    return np.concatenate([xh, z])


def _match(a, b, tol) -> bool:
    a, b = list(np.asarray(a)), list(np.asarray(b))
    if len(a) != len(b):
        return False
    for z in a:
        j = int(np.argmin([abs(z - w) for w in b]))
        if abs(z - b[j]) > tol:
            return False
        b.pop(j)
    return True


def test_a_moving_sigma_never_steps_the_command():
    """At rest, sigma jumping across the whole envelope leaves the command exactly where it was."""
    art = from_dict(designed(external_tank()))
    loop = ScheduledLoop(art)
    u0 = loop.step([0.25], [0.25], [0.04]).u
    for s in (1.0, 0.04, 0.5, 0.9, 0.04):
        out = loop.step([0.25], [0.25], [s])
        assert np.array_equal(out.u, u0) and out.sigma == s
