"""Campaign blocks: runs stepped together give each run what it gets alone, bit for bit.

Oracles: the plant alone (a batch of one) against the same plant in a block of hundreds with other parameters;
scipy's ``solve_ivp`` (a tight adaptive integrator) for the kernel's accuracy.
"""

from __future__ import annotations

import numpy as np
import pytest
from gainlink.hil.plants.models import CartPendulum, OdeBatch, QuadrotorLateral, batchable
from gainlink.hil.plants.tank import Tank
from scipy.integrate import solve_ivp


def _draws(cls, count: int, rng: np.random.Generator, **fixed) -> list:
    """``count`` plants of ``cls`` with each default parameter scaled by a factor in [0.7, 1.3]."""
    plants = []
    for _ in range(count):
        params = {k: v * rng.uniform(0.7, 1.3) for k, v in cls.defaults.items()}
        plants.append(cls(parameters=params, **fixed))
    return plants


@pytest.mark.parametrize(
    "cls, start, command",
    [
        (CartPendulum, {"x": 1.0, "theta": 0.3}, 2.0),
        (QuadrotorLateral, {"phi": 0.2, "y": 1.0}, 0.01),
        (Tank, {"h": 0.5}, 0.3),
    ],
)
def test_a_block_steps_each_plant_as_it_steps_alone_bit_for_bit(cls, start, command):
    rng = np.random.default_rng(7)
    block, alone = _draws(cls, 300, rng, step=0.004), []
    for p in block:
        p.reset(initial=start)
    for p in block[::37]:  # the same parameters, stepped alone
        q = cls(parameters=p.params, step=0.004)
        q.reset(initial=start)
        alone.append(q)
    assert batchable(block)
    batch = OdeBatch(block)
    U = command * rng.standard_normal((60, len(block), 1))
    for k in range(60):
        Y = batch.outputs()
        for j, q in enumerate(alone):
            assert np.array_equal(Y[37 * j], q.outputs())  # bit for bit, not close
            q.advance(u=U[k, 37 * j], dt=0.01)
        assert not batch.advance(U[k], dt=0.01).any()
    for j, q in enumerate(alone):
        assert np.array_equal(batch.X[37 * j], q.state())


def test_the_kernel_integrates_the_pendulum_as_an_adaptive_solver_does():
    p = CartPendulum(parameters={"M": 1.2, "m": 0.15, "l": 0.45}, step=0.002)
    p.reset(initial={"theta": 0.4, "x": 0.5})
    x0 = p.state()
    for _ in range(50):
        p.advance(u=np.array([1.5]), dt=0.01)
    ref = solve_ivp(lambda t, x: _pendulum(x, 1.5, 1.2, 0.15, 0.45, 9.81), (0.0, 0.5), x0, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(p.state(), ref.y[:, -1], rtol=0, atol=1e-9)


def _pendulum(x, F, M, m, l, g):
    """The cart pendulum's equations written out by hand (CartPendulum's docstring)."""
    s, c, w = np.sin(x[2]), np.cos(x[2]), x[3]
    D = M + m * s**2
    return [
        x[1],
        (F + m * l * w**2 * s - m * g * s * c) / D,
        w,
        ((M + m) * g * s - c * (F + m * l * w**2 * s)) / (l * D),
    ]


def test_a_row_that_blows_up_fails_alone_and_keeps_its_last_state():
    plants = [CartPendulum(step=0.005) for _ in range(3)]
    for p in plants:
        p.reset(initial={"theta": 0.1})
    batch = OdeBatch(plants)
    before = batch.X.copy()
    failed = batch.advance(np.array([[0.0], [1e308], [0.0]]), dt=0.01)
    assert failed.tolist() == [False, True, False]
    assert np.array_equal(batch.X[1], before[1])
    assert np.isfinite(batch.X).all()


def test_plants_of_other_kinds_or_steps_are_not_one_batch():
    assert not batchable([CartPendulum(step=0.005), CartPendulum(step=0.001)])
    assert not batchable([CartPendulum(), QuadrotorLateral()])


@pytest.mark.parametrize("numeric", ["float32", "q31"])
def test_one_c_call_steps_each_instance_as_its_own_native_step(numeric):
    """Row i of the block's answer equals instance i's own host C step (the per-run path's controller), bit for bit,
    through saturation and NaN samples (a FAULT)."""
    from gainlink.laws import law_of
    from support.fixed import example

    a = example("pendulum", numeric)
    law = law_of(a)
    count, steps = 7, 40
    rng = np.random.default_rng(3)
    Y = rng.normal(0.0, 0.6, (steps, count, a.p))
    Y[10, 2, 0] = np.nan
    Y[20:23, 5] = 40.0  # far out: saturates
    R = rng.normal(0.0, 0.2, (steps, count, a.q))
    S = np.zeros((steps, count, 0))
    block = law.native_block(a, count)
    alone = [law.native(a, library=block.host.library) for _ in range(count)]
    seen = set()
    for k in range(steps):
        got = block.step(Y[k], R[k], S[k])
        for i, c in enumerate(alone):
            want = c.step(Y[k, i], R[k, i], S[k, i])
            assert np.array_equal(got.u[i], want.u)
            assert (got.flags[i], got.sat[i]) == (want.flags, want.sat)
            seen |= {("fault", bool(want.flags & 1)), ("sat", bool(want.sat))}
    assert seen == {("fault", True), ("fault", False), ("sat", True), ("sat", False)}
