"""What gl_sched_step keeps between steps to cost less (firmware/src/gl_sched.c): the interval entered with its
differences, the coefficients of a standing sigma, and the coefficients it does not interpolate because they are the
same at every point (GL_SCHED_FIXED_* of the export). None of it may change a bit: the host build against the
float32 model on sigma sequences aimed at each of them, and on tables changed in place (gl_sched_retable) so that
a coefficient the export fixed varies."""

from __future__ import annotations

import ctypes

import numpy as np
import pytest
from gainlink.laws.scheduled.codegen import fixed_masks, tables
from gainlink.laws.scheduled.model import ScheduledFloat32Loop
from gainlink.laws.scheduled.native import NativeScheduledLoop
from gainlink.shipping.artifact import from_dict
from gainlink.shipping.export_c import render_export
from schedule_cases import external_tank
from support.designs import designed

pytestmark = pytest.mark.xdist_group("test_sched_step_cache")


@pytest.fixture(scope="module")
def ext():
    """The tank scheduled on an external sigma (predictor form, no filter, no rate limit: sigma is what it is given)."""
    return from_dict(designed(external_tank()))


def _sigmas(a) -> np.ndarray:
    """Sigma standing (at a point, between points, clipped), moving inside an interval, onto a point and just off it
    on both sides, jumping across intervals and back, held on NaN."""
    S = a.schedule.points.astype(np.float32)
    up, down = (np.nextafter(S, np.float32(np.inf)), np.nextafter(S, np.float32(-np.inf)))
    mid = (S[:-1] + S[1:]) / 2
    seq = [S[0]] * 3 + [mid[0]] * 4 + list(np.linspace(mid[0], S[1], 5)) + [S[1], S[1], down[1], S[1], up[1]]
    seq += [down[1], down[1], up[1], S[-1], S[-1], 2 * S[-1], 2 * S[-1], np.nan, mid[-1], np.nan, np.nan, S[0]]
    seq += [mid[0], mid[-1], mid[0], S[-1], down[-1], down[-1], S[0], -1.0, up[0], up[0], mid[-1]]
    return np.array(seq, dtype=np.float64)


def _run(a, sig: np.ndarray, c_loop, model):
    N = sig.size
    Y = 0.3 + 0.01 * np.sin(np.arange(N)).reshape(N, 1)
    R = np.where(np.arange(N) % 9 < 4, 0.3, 0.6).reshape(N, 1)
    return c_loop.run(Y, R, sig.reshape(N, 1)), model.run(Y, R, sig.reshape(N, 1))


def _same(c, m) -> None:
    for name in ("u", "sigma", "state"):
        got, want = getattr(c, name).astype(np.float32), getattr(m, name).astype(np.float32)
        assert np.array_equal(got.view(np.uint32), want.view(np.uint32)), name
    for name in ("saturated", "fault", "sigma_flags"):
        assert np.array_equal(getattr(c, name), getattr(m, name)), name


def test_the_export_fixes_the_coefficients_equal_at_every_point(ext):
    """The tank's F[0] and G[0] (the pump's own lag, the same at every level) are fixed; none of Kx, Kz, Ly is."""
    masks = fixed_masks(ext)
    assert masks["F"] & 1 and masks["G"] & 1 and not masks["Kx"] and not masks["Kz"] and not masks["Ly"]
    t = tables(ext)
    for name, mask in masks.items():
        for k in range(min(32, t[name].shape[1])):
            col = t[name][:, k]
            assert bool(mask >> k & 1) == bool(np.all(col == col[0]) and not (col[0] == 0 and np.signbit(col[0])))
    assert f"#define GL_SCHED_FIXED_F {masks['F']:#010x}u" in render_export(ext)["gl_gains.h"]


def test_sigma_standing_moving_and_crossing_points_is_the_model_bit_for_bit(ext):
    """Every cache path (entered interval, a sigma just below, on and above a point, standing then moving, held)
    gives the float32 model's bits."""
    sig = _sigmas(ext)
    c, m = _run(ext, sig, NativeScheduledLoop(ext), ScheduledFloat32Loop(ext))
    _same(c, m)
    assert np.sum(np.diff(c.sigma) == 0) >= 10  # sigma stood on many steps


def test_tables_changed_in_place_are_run_as_changed_even_where_the_export_fixed_a_coefficient(ext):
    """gl_sched_init on tables in RAM, then those tables changed in place and gl_sched_retable: F[0] (fixed by the
    export) now varies between the points, and every step after it is the model's on the changed tables."""
    c = NativeScheduledLoop(ext)
    m = ScheduledFloat32Loop(ext)
    t = tables(ext)
    buf = np.concatenate([np.asarray(v, np.float32).reshape(-1) for v in t.values()])
    lib = c._lib
    assert lib.gl_sched_init(c._loop, buf.ctypes.data_as(ctypes.c_void_p)) == 0
    sig = _sigmas(ext)
    half = sig.size // 2
    _same(*_run(ext, sig[:half], c, m))
    npts = ext.schedule.points.size
    F = np.asarray(t["F"], np.float32).copy()
    F[:, 0] = F[:, 0] * np.linspace(1.0, 0.9, npts, dtype=np.float32)  # F[0] now moves with sigma
    offset = sum(np.asarray(t[k]).size for k in ("S", "Kx", "Ky", "Kz"))
    buf[offset : offset + F.size] = F.reshape(-1)
    lib.gl_sched_retable.argtypes = [ctypes.c_void_p]
    lib.gl_sched_retable(c._loop)
    m.t["F"] = F.astype(np.float64)
    _same(*_run(ext, sig[half:], c, m))


def test_the_cortex_m4f_runs_every_cache_path_as_the_host(ext):
    """The same sigma sequence through the Cortex-M4F image in QEMU (where the step takes its shortest path for a
    sigma that moves inside the cached interval): bit for bit the host build."""
    from gainlink.laws.scheduled import qemu as sched_qemu

    sig = _sigmas(ext)
    N = sig.size
    Y = 0.3 + 0.01 * np.sin(np.arange(N)).reshape(N, 1)
    R = np.where(np.arange(N) % 9 < 4, 0.3, 0.6).reshape(N, 1)
    host = NativeScheduledLoop(ext).run(Y, R, sig.reshape(N, 1))
    m4 = sched_qemu.run(ext, Y, R, sig.reshape(N, 1))
    _same(m4, host)
