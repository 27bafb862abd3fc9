"""The fixed-point certificate: the examples certify (the pendulum, with its integrator, in q31 within the default
error), the estimate's range bound is reached by the worst-case inputs (tight), the artifact carries what rebuilds
the integers, and an unbounded peak gain is refused in one line."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest
from gainlink.errors import DesignError
from gainlink.fileio import read_toml
from gainlink.laws import design as design_spec
from gainlink.laws.fixed.certificate import certify
from gainlink.laws.fixed.model import FixedPointLoop, gains_from_artifact
from gainlink.laws.fixed.qformat import quantise
from gainlink.shipping.artifact import from_dict, seal
from gainlink.spec import parse_spec
from support.designs import designed
from support.paths import EXAMPLES


def _example(name: str, numeric: str, **implementation) -> dict:
    data, _ = read_toml(EXAMPLES / f"{name}.toml", what="spec", error=ValueError)
    data = copy.deepcopy(data)
    data["implementation"] = data.get("implementation", {}) | {"numeric": numeric, **implementation}
    return data


@pytest.fixture(scope="module")
def pendulum_q31():
    return design_spec(parse_spec(_example("pendulum", "q31")))


def test_pendulum_certifies_in_q31_with_its_integrator(pendulum_q31):
    """docs/design.md: an integrator or an unstable compensator is not a reason to refuse; the pendulum must certify."""
    r = pendulum_q31
    fp = r.artifact["checks"]["fixed_point"]
    assert fp["numeric"] == "q31" and fp["case"].startswith("closed_loop")
    assert max(fp["error"]["fraction_of_span"]) <= 1.0 / 4096
    assert fp["measured"]["within_bound"] and fp["measured"]["overflow"] == []
    assert fp["measured"]["unsaturated_steps"] >= 100  # the measurement covers the certified case
    assert "float32" not in r.artifact["checks"]  # the float check is not what runs
    from_dict(r.artifact)  # schema and hash


def test_artifact_rebuilds_the_certified_integers(pendulum_q31):
    a = from_dict(pendulum_q31.artifact)
    cert = pendulum_q31.fixed_point
    g, h = gains_from_artifact(a), cert.quantised.gains
    for name in ("KX", "KY", "KZ", "TR", "TY", "KAW", "F", "G", "LY"):
        assert np.array_equal(getattr(g, name).C, getattr(h, name).C), name
        assert np.array_equal(getattr(g, name).E, getattr(h, name).E), name
    assert a.checks["fixed_point"]["signature"] == cert.signature
    table = json.loads(json.dumps(g.integers()))  # what the C step takes: plain integers
    for name in ("KX", "KY", "KZ", "TR", "TY", "KAW", "F", "G", "LY"):
        assert np.abs(np.array(table[name])).max(initial=0) < 2**31 and np.min(table[f"{name}_shift"], initial=0) >= 0


@pytest.mark.parametrize("name", ["pendulum", "quadrotor_lateral", "wood_berry"])
def test_examples_certify_in_q31_within_the_default_error(name):
    """The certificate the design recorded (shared: the run designs each example in q31 once, support.designs)."""
    error = designed(_example(name, "q31"))["checks"]["fixed_point"]["error"]
    assert np.all(np.array(error["fraction_of_span"]) <= 1.0 / 4096)


def _worst_case_drive(cert, i: int) -> float:
    """Drive du and dy at the sign pattern of the certificate's own impulse response to estimate i, from rest,
    through the integer law's estimate update; returns the estimate reached."""
    qz = cert.quantised
    g, b = qz.gains, qz.bounds
    law, fm = g.ideal, g.formats
    m, p = law.m, law.p
    T = b.gain.terms
    H = [b.columns]
    for _ in range(T - 1):
        H.append(law.F @ H[-1])
    y_hi, y_lo = quantise(law.y_max, fm.frac("y")) - g.YOP, quantise(law.y_min, fm.frac("y")) - g.YOP
    u_hi, u_lo = g.HI_U - g.UOP_U, g.LO_U - g.UOP_U
    loop = FixedPointLoop(g)
    XH = [0] * law.n
    for t in range(T):
        row = H[T - 1 - t][i]
        dU = np.where(row[1 : 1 + m] >= 0, u_hi, u_lo)
        dY = np.where(row[1 + m : 1 + m + p] >= 0, y_hi, y_lo)
        XH = loop.estimate_update(XH, dU, dY)
    return XH[i] * 2.0 ** -int(fm.frac("xh")[i])


def test_estimate_bound_is_reached_by_the_worst_case_inputs(pendulum_q31):
    """Tight, not vacuous: the pendulum's ranges are symmetric about the operating point, so the bound is the
    l1 norm the worst-case sign pattern achieves (up to the tail and the estimate's own rounding)."""
    cert = pendulum_q31.fixed_point
    bound = cert.quantised.bounds.xh
    for i in range(bound.size):
        reached = _worst_case_drive(cert, i)
        assert 0.999 * bound[i] <= reached <= bound[i]


def test_estimate_bound_is_reached_off_centre():
    """A random design with an operating point off the ranges' centres: the worst-case sign pattern still
    reaches the bound within a small factor (the centre's own response is bounded by its absolute sum)."""
    from gainlink.synthesis.random_plants import random_spec

    spec = random_spec(5, n=3, m=1, p=1, q=1, form="current", anti_windup="clamp")
    spec["operating_point"] = {"u_op": [0.3], "y_op": [0.5]}
    a = from_dict(design_spec(parse_spec(spec)).artifact)
    cert = certify(a, {"y_min": [-1.0], "y_max": [3.0], "r_min": [-1.0], "r_max": [2.0]}, numeric="q15",
                   max_error=1.0)  # fmt: skip
    bound = cert.quantised.bounds.xh
    for i in range(bound.size):
        assert 0.5 * bound[i] <= _worst_case_drive(cert, i) <= bound[i]


def test_unstable_estimator_is_refused_in_one_line(pendulum_q31):
    """An unstable F (observer error dynamics) has an unbounded peak gain: no format can hold the estimate."""
    data = copy.deepcopy(pendulum_q31.artifact)
    data["L"] = [[0.0, 0.0] for _ in data["L"]]  # F = Ad: the pendulum's own unstable dynamics
    a = from_dict(seal(data))
    ranges = data["checks"]["fixed_point"]["ranges"]
    with pytest.raises(DesignError, match="unbounded") as exc:
        certify(a, ranges, numeric="q31", max_error=1.0)
    assert "\n" not in str(exc.value) and "F" in str(exc.value)


def test_q15_keeps_states_32_bit_and_samples_16():
    cert = design_spec(parse_spec(_example("wood_berry", "q15"))).fixed_point
    fm = cert.quantised.gains.formats
    assert {f.word for f in fm.y + fm.r + fm.u} == {16} and {f.word for f in fm.xh + fm.z + fm.v} == {32}
    for name in ("KX", "F", "G", "LY", "KAW"):
        C = getattr(cert.quantised.gains, name).C
        assert np.abs(C).max() < 2**15


def test_the_artifacts_integers_are_used_as_stored(pendulum_q31):
    """The C is rendered from the integers the design certified, never from a recomputation (a BLAS could round
    a derived coefficient differently): an edited mantissa is what the law then runs; a shift that no longer
    matches its formats is refused."""
    from gainlink.errors import ArtifactError

    data = copy.deepcopy(pendulum_q31.artifact)
    data["checks"]["fixed_point"]["integers"]["KX"][0][0] += 1
    assert FixedPointLoop(from_dict(seal(data))).g.KX.C[0, 0] == pendulum_q31.fixed_point.quantised.gains.KX.C[0, 0] + 1
    data["checks"]["fixed_point"]["integers"]["shift_v"][0] += 1
    with pytest.raises(ArtifactError, match="integers is inconsistent"):
        gains_from_artifact(from_dict(seal(data)))


@pytest.mark.parametrize("name", ["pendulum", "quadrotor_lateral"])
def test_q15_examples_are_refused_naming_the_remedy(name):
    """The headline in operation of the pendulum and the quadrotor in q15 is above the default 1/4096 of the span
    (1.8e-3 and 7.4e-3): refused in one line that names the figure, its parts and the remedies."""
    with pytest.raises(DesignError) as exc:
        design_spec(parse_spec(_example(name, "q15")))
    text = str(exc.value)
    assert "\n" not in text and "certified deviation in operation" in text and "from rest" in text
    for remedy in ('use numeric = "q31"', "narrow the declared ranges", "raise fixed_point_max_error"):
        assert remedy in text


def test_wood_berry_declares_what_it_accepts_in_q15():
    """wood_berry's spec accepts 1/1024 of a flow's span (its q15 headline is 3.7e-4 of it); q31 is far within."""
    for numeric, within in (("q15", 1 / 1024), ("q31", 1e-6)):
        err = designed(_example("wood_berry", numeric))["checks"]["fixed_point"]["error"]
        assert err["max_error"] == 1 / 1024 and max(err["fraction_of_span"]) <= within
