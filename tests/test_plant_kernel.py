"""The built-in plants' compiled RK4 (hil/plants/native/ode.c) against the numpy kernel it replaced.

Oracle: :func:`gainlink.hil.plants.models.rk4` over each model's numpy ``rates`` (the readable definition), which
the C follows operation for operation but for sin and cos (SLEEF's deterministic cinz u10 functions, within an ulp
of numpy's): a stated tolerance. test_campaign_blocks.py holds the scalar Python RK4 (math.sin: libm) and the
batch-of-one against block checks; here a row's bits are checked against the batch it is stepped in.
"""

from __future__ import annotations

import numpy as np
import pytest
from gainlink.errors import PlantError, ToolchainError
from gainlink.firmware import build, c_kernel
from gainlink.hil.plants import kernel
from gainlink.hil.plants.models import CartPendulum, OdeBatch, QuadrotorLateral, columns, rk4
from gainlink.hil.plants.tank import Tank
from support.cli import assert_refused
from support.hil import udp_transport, write_scenario

CASES = [
    (CartPendulum, {"x": (0.0, 1.0), "x_dot": (0.0, 1.0), "theta": (0.0, 0.8), "theta_dot": (0.0, 2.0)}, 8.0),
    (QuadrotorLateral, {"phi": (0.0, 0.3), "p": (0.0, 1.0), "v": (0.0, 1.0), "y": (0.0, 1.0)}, 0.02),
    (Tank, {"q": (0.3, 0.2), "h": (0.4, 0.3)}, 0.4),  # levels below zero: the clamp and the orifice's max(h, 0)
]


@pytest.mark.parametrize("cls, start, command", CASES)
def test_the_compiled_kernel_steps_as_the_numpy_kernel_it_replaced(cls, start, command):
    """300 rows of random parameters, states and commands, 30 samples of 3 sub-steps: every figure as numpy's RK4
    over the model's ``rates`` gives, within 1e-12 relative (atol 1e-15) over the 30 samples. Both evaluate each
    product and sum in the same order; the pendulum's sin and cos are SLEEF's in the kernel and differ from numpy's
    by an ulp on a few per cent of arguments (measured: 768 of the pendulum's 36,000 figures differ, by at most
    2.2e-14 relative), tan and sqrt are libm's in both."""
    rng = np.random.default_rng(3)
    plants = [cls(parameters={k: v * rng.uniform(0.7, 1.3) for k, v in cls.defaults.items()}, step=0.004)
              for _ in range(300)]  # fmt: skip
    for p in plants:
        p.reset(initial={k: float(rng.normal(m, s)) for k, (m, s) in start.items()})
    batch = OdeBatch(plants)
    X = np.stack([p.state() for p in plants])
    P = columns(cls, {k: np.array([p.params[k] for p in plants]) for k in cls.defaults})
    model = plants[0]
    for _ in range(30):
        U = command * rng.standard_normal((len(plants), 1))
        assert not batch.advance(U, dt=0.01).any()
        X = model.clamp(rk4(model.rates, X, U, P, dt=0.01, h=0.004))
        np.testing.assert_allclose(batch.X, X, rtol=1e-12, atol=1e-15)


def test_a_plant_alone_fails_at_the_sample_its_row_fails_and_keeps_its_state():
    """The kernel's failure is the numpy path's: a plant alone raises at the sample whose state is not finite and
    keeps its last finite state; the same command in a block fails that row alone, and the rows beside it (in the
    same group of SIMD lanes) step as they step alone."""
    alone = Tank(step=0.01)
    alone.reset(initial={"h": 0.5})
    alone.advance(u=np.array([0.2]), dt=0.1)
    before = alone.state()
    with pytest.raises(PlantError, match="plant tank: state became non-finite"):
        alone.advance(u=np.array([np.inf]), dt=0.1)
    assert np.array_equal(alone.state(), before)
    plants = [Tank(step=0.01) for _ in range(3)]
    for p in plants:
        p.reset(initial={"h": 0.5})
    batch = OdeBatch(plants)
    assert batch.advance(np.array([[0.2], [0.2], [0.2]]), dt=0.1).tolist() == [False, False, False]
    assert batch.advance(np.array([[0.2], [np.nan], [0.2]]), dt=0.1).tolist() == [False, True, False]
    assert np.array_equal(batch.X[1], before) and np.isfinite(batch.X).all()
    other = Tank(step=0.01)
    other.reset(initial={"h": 0.5})
    for _ in range(2):
        other.advance(u=np.array([0.2]), dt=0.1)
    assert np.array_equal(batch.X[0], other.state()) and np.array_equal(batch.X[2], other.state())


def test_a_row_steps_to_the_same_bits_in_a_batch_of_any_size():
    """1,000 pendulum rows (large swings: theta up to 40 rad, so sin and cos reduce their arguments; RK4 steps of
    20 ms, so an ulp of a rate reaches the state) stepped as one batch of 1,000, and their first 120 in batches of
    1, 3, 8 and 9 (each row at other places in its group of 8 lanes, in full and partial groups): every row ends
    with the same bits, and fails or not alike, however its batch was cut."""
    rng = np.random.default_rng(21)
    plants = [CartPendulum(parameters={k: v * rng.uniform(0.7, 1.3) for k, v in CartPendulum.defaults.items()},
                           step=0.02) for _ in range(1000)]  # fmt: skip
    for p in plants:
        p.reset(initial={"theta": float(rng.uniform(-40.0, 40.0)), "theta_dot": float(rng.normal(0.0, 5.0))})
    U = rng.normal(0.0, 20.0, (100, len(plants), 1))

    def stepped(rows: slice) -> tuple[np.ndarray, np.ndarray]:
        batch, failed = OdeBatch(plants[rows]), np.zeros(rows.stop - rows.start, dtype=bool)
        for k in range(len(U)):
            failed |= batch.advance(U[k, rows], dt=0.02)
        return batch.X, failed

    whole, whole_failed = stepped(slice(0, 1000))
    assert np.abs(whole[:, 2] - np.array([p.state()[2] for p in plants])).max() > 1.0  # they swung
    for size in (1, 3, 8, 9):
        parts = [stepped(slice(r, min(r + size, 120))) for r in range(0, 120, size)]
        X, failed = np.concatenate([x for x, _ in parts]), np.concatenate([f for _, f in parts])
        assert X.tobytes() == whole[:120].tobytes() and np.array_equal(failed, whole_failed[:120]), size


@pytest.fixture
def own_cache(tmp_path, monkeypatch):
    """The kernel's build cache in ``tmp_path / "cache"``, the process's lookups of the library forgotten before and
    after."""
    monkeypatch.setattr(build, "cache_root", lambda: tmp_path / "cache")
    c_kernel._library.cache_clear()
    yield tmp_path / "cache"
    c_kernel._library.cache_clear()


def test_the_kernel_is_built_once_into_the_cache_and_a_compiler_failure_is_one_line(own_cache, tmp_path, monkeypatch):
    cache = own_cache
    broken = tmp_path / "cc"
    broken.write_text("#!/bin/sh\necho 'ode.c:1:1: error: no such compiler today' >&2\nexit 1\n")
    broken.chmod(0o755)
    monkeypatch.setenv("CC", str(broken))
    with pytest.raises(ToolchainError) as err:
        kernel.library()
    assert "no such compiler today" in str(err.value) and "\n" not in str(err.value)
    assert [p.name for p in cache.rglob("*") if p.is_file()] == [".lock"]  # no library, no temporary file
    monkeypatch.delenv("CC")
    lib = kernel.library()
    assert lib.parent.parent == cache and lib.is_file()
    built = lib.stat().st_mtime_ns
    c_kernel._library.cache_clear()  # as another process finds it
    assert kernel.library() == lib and lib.stat().st_mtime_ns == built  # found, not built again
    assert sorted(p.name for p in lib.parent.iterdir()) == [".lock", lib.name]


def test_a_missing_sleef_is_one_line_naming_the_package_and_leaves_nothing(own_cache, tmp_path, monkeypatch):
    """The compiler's own words when SLEEF's header is not installed (gcc 12's, replayed by a stand-in compiler: this
    machine has SLEEF) become one line naming the Debian package; no library or temporary file is left."""
    cc = tmp_path / "cc"
    cc.write_text("#!/bin/sh\necho 'ode.c:29:10: fatal error: sleef.h: No such file or directory' >&2\n"
                  "echo 'compilation terminated.' >&2\nexit 1\n")  # fmt: skip
    cc.chmod(0o755)
    monkeypatch.setenv("CC", str(cc))
    with pytest.raises(ToolchainError) as err:
        kernel.library()
    assert "libsleef-dev" in str(err.value) and "\n" not in str(err.value)
    assert [p.name for p in own_cache.rglob("*") if p.is_file()] == [".lock"]


def test_the_vector_extension_is_the_widest_this_machine_has(tmp_path):
    """From the CPU's flags as Linux lists them: AVX-512F over AVX, none without either or without the file."""
    info = tmp_path / "cpuinfo"
    for flags, want in (("fpu sse2 avx avx2 fma avx512f", ("-mavx512f",)), ("fpu sse2 avx avx2", ("-mavx",)),
                        ("fpu sse2", ())):  # fmt: skip
        info.write_text(f"processor\t: 0\nflags\t\t: {flags}\n\nprocessor\t: 1\nflags\t\t: {flags}\n")
        assert kernel.vector_flags(info) == want
    assert kernel.vector_flags(tmp_path / "absent") == ()


def test_a_missing_compiler_stops_a_run_in_one_line(example_artifacts, own_cache, tmp_path, monkeypatch):
    monkeypatch.setenv("CC", "gainlink-no-such-cc")
    scenario = write_scenario(tmp_path / "s.toml", {
        "artifact": str(example_artifacts["pendulum"]), "duration": 0.1, "controller": "reference",
        "transport": udp_transport(), "plant": {"kind": "cart_pendulum", "outputs": ["x", "theta"]},
    })  # fmt: skip
    argv = ["hil", "run", scenario, "--report", tmp_path / "report", "--no-progress"]
    assert_refused(argv, "C compiler gainlink-no-such-cc not found", tmp_path)  # own_cache is under it
