"""The law interface (gainlink.laws): which law an artifact runs, and every pair's three controllers — the float64
law, the bit-exact model of its C and the host C itself — behind one step, with the same status flags.

Oracles: the model against the C bit for bit (commands, flags, saturation, sigma) on samples that set every flag
the law can set; the float64 law against the model within float32 rounding on in-range samples; flag bits against
docs/design.md's table written out here (not imported from the code under test).
"""

from __future__ import annotations

import numpy as np
import pytest
from gainlink.errors import LawError
from gainlink.laws import CELLS, Capabilities, law_for, law_of, pairs
from gainlink.laws import flags as law_flags
from gainlink.shipping.artifact import from_dict, load
from schedule_cases import tank_dict
from support.designs import designed
from support.fixed import example
from support.paths import EXAMPLES

#: docs/design.md's status flags, written out (the oracle).
DOC_FLAGS = {"FAULT": 0x01, "WATCHDOG": 0x02, "CLIPPED": 0x04, "OVERFLOW": 0x08, "SIGMA_HELD": 0x10,
             "SIGMA_CLIPPED": 0x20, "SIGMA_RATE": 0x40, "RESET": 0x80, "CAPPED": 0x100}  # fmt: skip


@pytest.fixture(scope="module")
def artifacts(tmp_path_factory):
    from gainlink.api import design

    out = tmp_path_factory.mktemp("laws")
    pendulum = design(EXAMPLES / "pendulum.toml")
    pendulum.save(out / "pendulum.json")
    return {
        "lq/float32": load(out / "pendulum.json"),
        "lq/q31": example("pendulum", "q31"),
        "lq/q15": example("wood_berry", "q15"),
        "scheduled/float32": from_dict(designed(tank_dict())),
        "mpc/float32": from_dict(designed(_short_mpc())),
    }


def _short_mpc() -> dict:
    """examples/pendulum_mpc.toml over 5 steps (its float32 model is Python: a short horizon keeps it cheap)."""
    import tomllib

    data = tomllib.loads((EXAMPLES / "pendulum_mpc.toml").read_text())
    data["mpc"]["horizon"] = 5
    return data


def test_law_of_names_each_pair_from_the_artifacts_content(artifacts):
    assert sorted(pairs()) == sorted(artifacts)
    for name, a in artifacts.items():
        assert law_of(a).name == name


def test_a_scheduled_law_on_integers_is_refused_in_one_line_saying_why():
    with pytest.raises(LawError, match=r"^no scheduled law in q31: a scheduled law on integers is time-varying"):
        law_for("scheduled", "q31")
    with pytest.raises(LawError, match=r"unknown law structure 'pid'"):
        law_for("pid")


def test_a_declared_incapacity_is_one_generated_line():
    law = law_for("lq")
    law.__class__.capabilities = property(lambda self: Capabilities(cannot={"pil": "no image fits"}))
    try:
        with pytest.raises(LawError, match=r"^pil run is not available for the float32 law: no image fits$"):
            law.refuse("pil", what="pil run")
        law.refuse("sil")  # declared: nothing raised
    finally:
        del law.__class__.capabilities
    with pytest.raises(ValueError, match="unknown cell"):
        Capabilities(cannot={"teleport": "no"})
    assert len(set(CELLS)) == len(CELLS)


def test_each_law_gives_the_command_that_holds_its_operating_point(artifacts):
    """``Law.u_op``: the artifact's stored ``u_op`` (the lq laws), each point's stored ``u_op`` at that point and by
    default the first (the scheduled law), read here from the artifact's JSON, not from the law's code."""
    for pair, a in artifacts.items():
        law = law_of(a)
        if "schedule" in a.data:
            sched = a.data["schedule"]
            assert np.array_equal(law.u_op(a), sched["point"][0]["u_op"])
            for sigma, point in zip(sched["points"], sched["point"], strict=True):
                np.testing.assert_allclose(law.u_op(a, sigma=sigma), point["u_op"], rtol=0, atol=1e-12)
        else:
            assert np.array_equal(law.u_op(a), a.data.get("u_op", np.zeros(a.m))), pair


def test_the_flag_table_is_the_documented_one_and_its_c_header_defines_each_bit_once():
    assert {f.name: f.bit for f in law_flags.FLAGS} == DOC_FLAGS
    header = law_flags.c_header()
    for name, bit in DOC_FLAGS.items():
        assert header.count(f"#define GL_FLAG_{name} 0x{bit:02x}u") == 1


def _samples(a, rng, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """k samples around the trim, some far out (saturation, clipping), one NaN."""
    law = law_of(a)
    e = len(law.externals(a))
    y_op = a.y_op if a.schedule is None else a.schedule.trim_at(a.schedule.points[0])[1]
    Y = y_op + rng.normal(0.0, 0.2, (k, a.p))
    Y[k // 3] *= 50.0  # far out of range: saturates (and clips a fixed-point law's sample)
    Y[k // 2, 0] = np.nan  # refused: FAULT
    R = np.tile(law.r_op(a), (k, 1)) + rng.normal(0.0, 0.05, (k, a.q))
    return Y, R, np.zeros((k, e))


@pytest.mark.parametrize("name", ["lq/float32", "lq/q31", "lq/q15", "scheduled/float32", "mpc/float32"])
def test_model_and_host_c_give_the_same_steps_bit_for_bit_and_the_reference_is_within_rounding(artifacts, name):
    a = artifacts[name]
    law = law_of(a)
    Y, R, S = _samples(a, np.random.default_rng(7), 40)
    ref, model, native = law.reference(a), law.model(a), law.native(a)
    seen = 0
    for k in range(Y.shape[0]):
        want, got, r64 = model.step(Y[k], R[k], S[k]), native.step(Y[k], R[k], S[k]), ref.step(Y[k], R[k], S[k])
        assert np.array_equal(want.u, got.u), (k, want.u, got.u)
        assert (want.flags, want.sat) == (got.flags, got.sat), k
        assert (want.word is None) == (got.word is None)
        if want.word is not None:
            assert np.array_equal(want.word, got.word), k
        assert np.isnan(want.sigma) == np.isnan(got.sigma) and (np.isnan(want.sigma) or want.sigma == got.sigma)
        seen |= got.flags
        if k < Y.shape[0] // 3:  # in range, before the far sample: float32 (or integer) rounding only
            assert np.allclose(r64.u, got.u, rtol=1e-3, atol=1e-3 * (a.u_max - a.u_min).max()), k
    assert seen & DOC_FLAGS["FAULT"]
    if law.numeric != "float32":
        assert seen & DOC_FLAGS["CLIPPED"]
