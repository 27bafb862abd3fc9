"""The fixed-point spec (``[implementation] numeric``, ``fixed_point_max_error``, ``[limits]`` ranges): what it
accepts, and every bad input refused through the CLI in one line, exit 2, nothing written."""

from __future__ import annotations

import json

import pytest
from support.cli import GOOD_SPEC, assert_refused, run_cli

RANGES = "y_min = [-2.0]\ny_max = [2.0]\nr_min = [-1.0]\nr_max = [1.0]\n"
Q31 = GOOD_SPEC + RANGES + '\n[implementation]\nnumeric = "q31"\n'


def q31_with(old: str, new: str) -> str:
    assert old in Q31, old
    return Q31.replace(old, new, 1)


BAD = [
    ("numeric-unknown", q31_with('numeric = "q31"', 'numeric = "q7"'), "implementation.numeric must be one of"),
    ("max-error-zero", Q31 + "fixed_point_max_error = 0.0\n", "fixed_point_max_error is a fraction"),
    ("max-error-one", Q31 + "fixed_point_max_error = 1.5\n", "fixed_point_max_error is a fraction"),
    ("max-error-string", Q31 + 'fixed_point_max_error = "small"\n', "fixed_point_max_error is a fraction"),
    ("y-ranges-missing", Q31.replace("y_min = [-2.0]\ny_max = [2.0]\n", ""), "needs the samples' ranges"),
    ("r-ranges-missing", Q31.replace("r_min = [-1.0]\nr_max = [1.0]\n", ""), "needs the references' ranges"),
    ("y-max-alone", q31_with("y_min = [-2.0]\n", ""), "limits.y_max is given without limits.y_min"),
    ("y-range-empty", q31_with("y_min = [-2.0]", "y_min = [2.0]"), "limits.y_min must be below limits.y_max"),
    ("y-range-wrong-length", q31_with("y_min = [-2.0]", "y_min = [-2.0, -1.0]"), "limits.y_min has 2 entries"),
    (
        "y-range-excludes-op",
        Q31 + "\n[operating_point]\ny_op = [3.0]\n",
        "excludes the operating point y_op, 3",
    ),
    (
        "r-range-excludes-op",
        q31_with("r_min = [-1.0]", "r_min = [0.5]") + "\n[operating_point]\ny_op = [0.2]\n",
        "excludes the reference at the operating point (Ci y_op), 0.2",
    ),
    (
        "r-range-without-integral",
        Q31.replace("[integral]\noutputs = [0]\nQ_diag = [1.0]\n", ""),
        "range the references, but there is no [integral] table",
    ),
    (
        "anti-windup-none",
        q31_with("u_max = [5.0]\n", 'u_max = [5.0]\nanti_windup = "none"\n'),
        'cannot bound the integrator with anti_windup = "none"',
    ),
    ("q15-max-error-unmet", Q31.replace('"q31"', '"q15"') + "fixed_point_max_error = 1e-9\n", 'use numeric = "q31"'),
    ("q31-max-error-unmet", Q31 + "fixed_point_max_error = 1e-15\n", "narrow the declared ranges"),
]


@pytest.mark.parametrize("case", BAD, ids=[c[0] for c in BAD])
def test_bad_fixed_point_spec_is_refused_without_writing(case, tmp_path):
    _, text, words = case
    spec = tmp_path / "spec.toml"
    spec.write_text(text)
    assert_refused(("design", spec, "--out", tmp_path / "out"), words, tmp_path)


def test_float32_spec_with_ranges_designs_the_same_law(tmp_path):
    """Ranges are declared but unused by a float32 law: the matrices and checks are those of the spec without them
    (only the spec's own hash differs)."""
    plain, ranged = tmp_path / "plain.toml", tmp_path / "ranged.toml"
    plain.write_text(GOOD_SPEC)
    ranged.write_text(GOOD_SPEC + RANGES)
    assert run_cli("design", plain, "--out", tmp_path / "a").code == 0
    assert run_cli("design", ranged, "--out", tmp_path / "b").code == 0
    a, b = (json.loads((tmp_path / d / "gains.json").read_text()) for d in "ab")
    for art in (a, b):
        art.pop("sha256"), art["provenance"].pop("spec_sha256")
    assert a == b
    assert "fixed_point" not in a["checks"]


def test_q31_spec_designs_and_records_its_certificate(tmp_path):
    spec = tmp_path / "spec.toml"
    spec.write_text(Q31)
    res = run_cli("design", spec, "--out", tmp_path / "out", "--json")
    assert res.code == 0, res.err
    fp = json.loads(res.out)["fixed_point"]
    assert fp["numeric"] == "q31"
    assert fp["ranges"] == {"y_min": [-2.0], "y_max": [2.0], "r_min": [-1.0], "r_max": [1.0]}
    assert fp["error"]["max_error"] == 1.0 / 4096  # the default: one step of a 12-bit actuator
    assert max(fp["error"]["fraction_of_span"]) <= 1.0 / 4096
    assert fp["measured"]["within_bound"] and not fp["measured"]["overflow"]
    assert run_cli("validate", tmp_path / "out" / "gains.json").code == 0


def _toml(spec: dict) -> str:
    """A spec dict as TOML (JSON arrays, numbers and strings are TOML values)."""
    lines = [f"{k} = {json.dumps(v)}" for k, v in spec.items() if not isinstance(v, dict)]
    for table, values in spec.items():
        if isinstance(values, dict):
            lines += [f"\n[{table}]"] + [f"{k} = {json.dumps(v)}" for k, v in values.items()]
    return "\n".join(lines) + "\n"


def test_estimator_made_unstable_by_q15_coefficients_is_refused(tmp_path):
    """An unbounded peak gain: this design's F has eigenvalues up to |z| = 0.994 made of entries up to 63 that
    cancel (eigenvector condition number 730); with 16-bit coefficients it leaves the unit circle and no format
    can bound the estimate."""
    from gainlink.synthesis.random_plants import random_spec

    spec = random_spec(11, n=3, m=1, p=1, q=1, anti_windup="backcalc")
    spec["limits"] |= {"y_min": [-2.0], "y_max": [2.0], "r_min": [-1.0], "r_max": [1.0]}
    spec["implementation"] = {"numeric": "q15", "float32_check": False}
    path = tmp_path / "spec.toml"
    path.write_text(_toml(spec))
    res = assert_refused(
        ("design", path, "--out", tmp_path / "out"),
        "with the q15 coefficients the estimate's recursion F is unstable",
        tmp_path,
    )
    assert 'use numeric = "q31"' in res.err
