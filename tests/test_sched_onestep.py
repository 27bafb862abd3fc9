"""The scheduled law's one-step check with a float32 bound (gainlink.laws.scheduled.onestep): every step of a trace
of the C against the float64 law from the trace's own state, within what float32 can change in that step.

Oracles: the float64 law (gainlink.laws.scheduled.reference) and the real host C (``gl_sched.c`` through ctypes);
the bound is derived by hand in the module's docstring. A correct C passes on closed-loop records and on wild samples
(sigma at and around the points, held, clipped, rate-limited; saturation; refused samples), with its largest error a
measurable fraction of the bound; a C whose table has one coefficient bent by a relative 1e-4 fails.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
from gainlink.laws import law_of
from gainlink.laws.scheduled.model import ScheduledFloat32Loop
from gainlink.laws.scheduled.onestep import float32_bound_check
from gainlink.laws.scheduled.reference import SIGMA_CLIPPED, SIGMA_HELD, SIGMA_RATE, ScheduledLoop
from gainlink.shipping import artifact as artifact_mod
from gainlink.shipping.artifact import from_dict
from schedule_cases import external_tank, tank_dict
from support.cli import assert_refused, run_cli
from support.designs import designed

# one worker runs the module (23 CPU-s): started first
pytestmark = [pytest.mark.xdist_group("test_sched_onestep"), pytest.mark.slow(cpu=23)]

CASES = {
    "level": lambda: tank_dict(),
    "external": lambda: external_tank(form="current", rate_max=4.0, filter_tau=0.1),
}


@functools.cache
def case_of(which: str):
    """A scheduled tank (on its level; on an external signal, current form, filtered and rate-limited): its artifact
    dict, its artifact and its closed-loop record."""
    data = designed(CASES[which]())
    a = from_dict(data)
    return data, a, *closed_loop(a)


@pytest.fixture(scope="module", params=sorted(CASES))
def case(request):
    """Each case of :func:`case_of`."""
    return case_of(request.param)


def closed_loop(a, N: int = 600):
    """The float64 law around the nonlinear tank: the level's reference climbs across the envelope and back (sigma
    is clipped at both ends), jumps down (the pump saturates); one sample is NaN; an external sigma also jumps past
    its rate limit and is NaN and infinite."""
    rng = np.random.default_rng(3)
    ref = 0.02 + 1.2 * (1 - np.abs(1 - 2 * np.arange(N) / N))
    ref[N // 2 - 60 : N // 2 - 40] = 0.05
    law, e = ScheduledLoop(a), len(a.schedule.external)
    q, h = 0.08, 0.04
    Y, R, S = np.zeros((N, 1)), ref.reshape(N, 1), np.zeros((N, e))
    for k in range(N):
        Y[k, 0] = np.nan if k == 150 else h + 0.002 * rng.standard_normal()
        if e:
            S[k, 0] = (np.nan, np.inf)[k - 200] if k in (200, 201) else h + (0.6 if (k // 60) % 3 == 1 else 0.0)
        u = float(law.step(Y[k], R[k], S[k]).u[0])
        for _ in range(10):  # the tank, Euler at Ts / 10
            q, h = q + a.Ts / 10 * (u - q) / 0.1, max(h + a.Ts / 10 * (q - 0.4 * np.sqrt(max(h, 0.0))), 0.0)
    return Y, R, (S if e else None)


def wild(a, N: int = 1000):
    """Samples anywhere: sigma at the points, a hair either side of them, outside the envelope; references off and
    on; ten refused samples."""
    rng = np.random.default_rng(11)
    pts = a.schedule.points
    near = np.concatenate([pts, pts * (1 + 1e-7), pts * (1 - 1e-7)])
    Y = rng.uniform(-0.2, 1.4, (N, a.p))
    Y[::7, 0] = rng.choice(near, size=Y[::7].shape[0])
    R = rng.uniform(-0.5, 2.0, (N, a.q)) * rng.choice([0.0, 1.0], size=(N, a.q))
    Y[rng.integers(0, N, 10), 0] = np.nan
    e = len(a.schedule.external)
    if not e:
        return Y, R, None
    S = rng.uniform(-0.1, 1.3, (N, e))
    S[::5, 0] = rng.choice(near, size=S[::5].shape[0])
    return Y, R, S


def test_the_host_c_is_within_the_float32_bound_of_the_float64_law(case):
    _, a, Y, R, S = case
    for Yk, Rk, Sk in ((Y, R, S), wild(a)):
        trace = law_of(a).replay(a, "native", Yk, Rk, Sk)
        check = float32_bound_check(a, Yk, Rk, Sk, trace)
        assert check.passed, check.first_failure.describe("native")
    flags = np.bitwise_or.reduce(law_of(a).replay(a, "native", Y, R, S).sigma_flags)
    assert flags & SIGMA_CLIPPED and (not a.schedule.external or flags & SIGMA_HELD)
    assert not a.schedule.rate_max or flags & SIGMA_RATE
    # a bound of what float32 does, not a wide margin: the largest errors are a fair fraction of it
    assert check.worst["u"] > 0.02 and check.worst["state"] > 0.2, check.worst


def test_the_float64_laws_own_trace_is_at_zero(case):
    _, a, Y, R, S = case
    check = float32_bound_check(a, Y, R, S, ScheduledLoop(a).run(Y, R, S))
    assert check.passed and check.worst == {"u": 0.0, "sigma": 0.0, "state": 0.0} and check.max_rel_u == 0.0


COEFFICIENTS = ("Kx", "Ky", "Kz", "F", "G", "Ly", "u_op")


@pytest.mark.parametrize(
    ("which", "name"),
    [("external", name) for name in COEFFICIENTS]
    + [pytest.param("level", name, marks=pytest.mark.matrix) for name in COEFFICIENTS],
)
def test_one_coefficient_of_the_table_bent_by_1e_4_is_caught(which, name):
    """The float32 model is the C bit for bit: bending its table is bending the C's (on the record's first 300
    samples; the level-scheduled tank's under ``make test-matrix``)."""
    _, a, Y, R, S = case_of(which)
    Y, R, S = Y[:300], R[:300], None if S is None else S[:300]
    loop = ScheduledFloat32Loop(a)
    T = loop.t[name]
    if not np.any(T):
        pytest.skip(f"{name} is zero in this law (the predictor form's Ky)")
    i, j = np.unravel_index(np.argmax(np.abs(T)), T.shape)
    T[i, j] = float(np.float32(T[i, j] * (1 + 1e-4)))
    check = float32_bound_check(a, Y, R, S, loop.run(Y, R, S))
    assert not check.passed and check.first_failure.quantity.startswith(("u", "state"))


def test_replay_compare_checks_a_c_trace_file_against_the_float64_law_and_the_model(case, tmp_path):
    """``--compare`` on a trace of the C: within the float32 bound of the float64 law and bit for bit the model (a
    trace of the C given as the comparison file was checked against the float64 law at 1e-12, and always failed)."""
    data, a, Y, R, S = case
    path, inp = tmp_path / "gains.json", tmp_path / "in.csv"
    artifact_mod.write(path, data)
    cols = (
        [f"y{i}" for i in range(a.p)] + [f"r{i}" for i in range(a.q)] + [f"s{i}" for i in range(0 if S is None else 1)]
    )
    rows = np.hstack([Y, R] + ([] if S is None else [S]))
    inp.write_text(",".join(cols) + "\n" + "\n".join(",".join(repr(float(v)) for v in row) for row in rows) + "\n")
    native = tmp_path / "native.csv"
    assert run_cli("replay", path, "--input", inp, "--output", native, "--engine", "native").code == 0
    res = run_cli("replay", path, "--input", inp, "--output", tmp_path / "ref.csv", "--compare", native)
    assert res.code == 0, res.err
    name = f"one-step check of {native}"
    assert f"{name} (float64 law from its own state at each step, within the float32 bound): pass" in res.out
    assert f"{name} (the C's float32 arithmetic, bit for bit, from its own state at each step): pass" in res.out
    lines = native.read_text().splitlines()
    cells = lines[200].split(",")
    cells[0] = repr(float(cells[0]) * (1 + 1e-3))  # u0 of step 198 (after the format line and the header)
    bent = tmp_path / "bent.csv"
    bent.write_text("\n".join([*lines[:200], ",".join(cells), *lines[201:]]) + "\n")
    argv = ("replay", path, "--input", inp, "--output", tmp_path / "o.csv", "--compare", bent)
    assert_refused(argv, f"one-step check failed at step 198: u0 of {bent}")
