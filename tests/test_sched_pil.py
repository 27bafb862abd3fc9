"""Processor-in-the-loop of a scheduled artifact: the Cortex-M4F image (firmware/ports/cortex-m/main.c, on
mps2-an386) runs gl_sched_step in closed loop with the nonlinear tank of examples/tank_scheduled.toml, sigma moving
across the whole envelope (and beyond it: clipped). The oracles, recomputed here: the scheduled float32 model
(gainlink.laws.scheduled.model) and the host build of the same C, each fed the very float32 samples the image
received, write its commands, flags and state bit for bit; the float64 scheduled law on a second tank (the
closed-loop twin) stays within float32 rounding of it."""

from __future__ import annotations

import json

import numpy as np
import pytest
from gainlink.firmware.build import replay_image
from gainlink.hil.loop.pil import make_plant, run_pil
from gainlink.laws.image import first_difference
from gainlink.laws.scheduled.law import status_flags
from gainlink.laws.scheduled.model import ScheduledFloat32Loop
from gainlink.laws.scheduled.native import NativeScheduledLoop
from gainlink.laws.scheduled.pil import image_records
from gainlink.laws.scheduled.reference import SIGMA_CLIPPED, SIGMA_HELD, SIGMA_RATE
from gainlink.shipping import artifact as artifact_mod
from gainlink.shipping.artifact import from_dict
from schedule_cases import external_tank, tank_dict
from support.cli import assert_refused, run_cli
from support.designs import designed
from support.status import SIGMA_BITS, scheduled_status

# one worker: the images are built once (the module 15 CPU-s): started first
pytestmark = [pytest.mark.xdist_group("test_sched_pil"), pytest.mark.slow(cpu=15)]

STEPS = 400


@pytest.fixture(scope="module")
def level_data():
    """The example tank scheduled on its measured level: its artifact dict."""
    return designed(tank_dict())


@pytest.fixture(scope="module")
def level(level_data):
    """That artifact, its M4F replay image built once."""
    a = from_dict(level_data)
    replay_image(a, target="cortex-m4", board="mps2-an386")
    return a


@pytest.fixture(scope="module")
def external():
    """The tank on an external sigma, current form, sigma filtered (0.1 s) and rate-limited (4/s); image built."""
    a = from_dict(designed(external_tank(form="current", rate_max=4.0, filter_tau=0.1)))
    replay_image(a, target="cortex-m4", board="mps2-an386")
    return a


def _triangle(N: int) -> np.ndarray:
    """A level reference from 0.02 m up to 1.22 m and back (below, across and above the envelope), with a jump
    down and back up that saturates the pump."""
    ref = 0.02 + 1.2 * (1 - np.abs(1 - 2 * np.arange(N) / N))
    ref[N // 2 - 30 : N // 2 - 10] = 0.05
    return ref.reshape(N, 1)


def _f32_bits(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float32).view(np.uint32)


def test_scheduled_pil_runs_gl_sched_step_bit_for_bit_with_sigma_measured(level):
    """sigma is the tank's level: it sweeps the whole envelope and is clipped below and above it."""
    plant, twin = (make_plant("tank", artifact=level, x0=np.array([0.08, 0.04])) for _ in range(2))
    R = _triangle(STEPS)
    res = run_pil(level, plant=plant, steps=STEPS, reference=R, target="cortex-m4", twin=twin)
    chk = res.checks["scheduled"]
    assert chk.law == "scheduled-float32" and chk.bit_exact_model and chk.bit_exact_host, chk
    # independent of the run's own check: the float32 model on the samples the image got, step by step
    model = ScheduledFloat32Loop(level).run(res.y.astype(np.float32).astype(float), R.astype(np.float32))
    assert np.array_equal(_f32_bits(res.u), _f32_bits(model.u))
    assert np.array_equal(_f32_bits(res.sigma), _f32_bits(model.sigma))
    assert np.array_equal(res.flags, scheduled_status(model.sigma_flags, model.fault))
    assert np.array_equal(res.saturated, model.saturated)
    sch = chk.schedule
    assert sch["source"] == "output" and sch["sigma_min"] == np.float32(0.04) and sch["sigma_max"] == 1.0
    assert sch["clipped_steps"] > 0 and sch["held_steps"] == 0 and res.saturated.any()
    h = res.y[:, 0].astype(np.float32)  # the image clips the float32 level to the float32 envelope
    assert np.array_equal((res.flags & SIGMA_BITS[SIGMA_CLIPPED]) != 0, (h < np.float32(0.04)) | (h > np.float32(1.0)))
    assert res.comparison.worst_du_rel < 1e-4  # the float64 law on a second tank: float32 rounding apart
    assert res.model_twin is not None and np.all(np.isfinite(res.model_twin.y))
    s = res.summary()
    assert s["law"] == "scheduled-float32" and s["scheduled"]["schedule"]["coverage"] >= 0.999


def test_scheduled_pil_with_an_external_sigma_held_clipped_and_rate_limited(external):
    """sigma an external signal that ramps across the envelope, jumps (rate-limited), leaves it (clipped) and is
    NaN or inf on three samples (held); the law is the current form with a filtered sigma."""
    N = 300
    S = np.linspace(0.0, 1.3, N).reshape(N, 1)
    S[100:140] += 0.5
    S[200:203, 0] = (np.nan, np.inf, -np.inf)
    plant, twin = (make_plant("tank", artifact=external, x0=np.array([0.2, 0.25])) for _ in range(2))
    res = run_pil(external, plant=plant, steps=N, reference=[0.5], signals=S, twin=twin)
    chk = res.checks["scheduled"]
    assert chk.bit_exact_model and chk.bit_exact_host, chk
    f = res.flags
    assert np.array_equal(np.flatnonzero(f & SIGMA_BITS[SIGMA_HELD]), [200, 201, 202])
    assert (f & SIGMA_BITS[SIGMA_RATE]).any() and (f & SIGMA_BITS[SIGMA_CLIPPED]).any()
    sch = chk.schedule
    assert sch["held_steps"] == 3 and sch["rate_limited_steps"] > 0 and sch["source"] == "external"
    assert sch["max_rate"] <= 4.0 * (1 + 1e-6)  # the rate limit in the image
    host = NativeScheduledLoop(external).run_raw(res.y, np.full((N, 1), 0.5), S)
    assert np.array_equal(_f32_bits(res.u), _f32_bits(host["u"]))


def test_scheduled_pil_on_the_m0_without_an_fpu_is_bit_for_bit_too(level):
    """The micro:bit's Cortex-M0 computes every fmaf in software (gl_fmaf, rounded once): the same records."""
    N = 200
    plant = make_plant("tank", artifact=level, x0=np.array([0.08, 0.04]))
    res = run_pil(level, plant=plant, steps=N, reference=_triangle(N), board="microbit")
    chk = res.checks["scheduled"]
    assert chk.bit_exact_model and chk.bit_exact_host, chk
    assert chk.schedule["coverage"] > 0.99


def test_the_check_finds_a_record_that_differs(level):
    """The oracle is not vacuous: one flipped bit of a command, or a sigma flag, is found at its step."""
    N = 50
    Y = np.linspace(0.0, 1.2, N, dtype=np.float32).reshape(N, 1)
    R = np.full((N, 1), 0.5, dtype=np.float32)
    S = np.zeros((N, 0), dtype=np.float32)
    model = image_records(level, Y=Y, R=R, S=S, host=False, status_flags=status_flags)
    assert first_difference(image_records(level, Y=Y, R=R, S=S, host=True, status_flags=status_flags), model) is None
    bad = model.copy()
    bad["u"][17] = np.float32(bad["u"][17]) + np.float32(1e-7) * abs(bad["u"][17])
    assert first_difference(bad, model) == {"step": 17, "field": "u"}
    bad = model.copy()
    bad["flags"][30] ^= 0x40  # the record's status flags: sigma rate-limited (docs/design.md's table)
    assert first_difference(bad, model) == {"step": 30, "field": "flags"}


def test_pil_cli_on_a_scheduled_artifact(level_data, level, tmp_path):
    """``gainlink pil run`` of a scheduled artifact runs its scheduled image; pil.json names the law and carries
    sigma's flags, pil.csv sigma per step."""
    path = tmp_path / "gains.json"
    artifact_mod.write(path, level_data)
    out = tmp_path / "pil"
    res = run_cli("pil", "run", path, "--plant", "tank", "--steps", 200, "--reference", 1.2, "--x0", 0.0, 0.0,
                  "--out", out, "--json")  # fmt: skip
    assert res.code == 0, res.err
    summary = json.loads((out / "pil.json").read_text())
    assert summary == json.loads(res.out)
    assert summary["law"] == "scheduled-float32" and summary["scheduled"]["bit_exact_model"]
    assert summary["scheduled"]["bit_exact_host"] and summary["scheduled"]["schedule"]["clipped_steps"] > 0
    assert summary["model_twin"]["warning"] is False
    header, *rows = (out / "pil.csv").read_text().splitlines()
    assert header.split(",")[3:5] == ["flags", "sigma"] and len(rows) == 200
    assert (out / "twin.png").stat().st_size > 0


def test_pil_cli_bad_schedule_signals(level_data, pend, tmp_path):
    """An external sigma without --schedule-signal, an unknown signal, a malformed one, or one for an unscheduled
    artifact: one line, exit 2, nothing written."""
    ext = tmp_path / "ext.json"
    artifact_mod.write(ext, designed(external_tank()))
    lvl = tmp_path / "level.json"
    artifact_mod.write(lvl, level_data)
    out = tmp_path / "out"
    for argv, said in (
        ((ext,), "give --schedule-signal load"),
        ((ext, "--schedule-signal", "speed=1"), "not an external scheduling signal"),
        ((ext, "--schedule-signal", "load=a,b"), "NAME=START"),
        ((lvl, "--schedule-signal", "load=0.5"), "not an external scheduling signal"),
        ((pend, "--schedule-signal", "load=0.5"), "not an external scheduling signal of pendulum (external: none)"),
    ):
        plant = "artifact" if argv[0] == pend else "tank"
        assert_refused(("pil", "run", *argv, "--plant", plant, "--steps", 5, "--out", out), said, tmp_path)
