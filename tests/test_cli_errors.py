"""The catalogue of bad inputs: one line naming the problem, exit status 2, nothing written."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from support.cli import GOOD_SPEC, assert_refused, run_cli


def spec_with(old: str, new: str) -> str:
    assert old in GOOD_SPEC, old
    return GOOD_SPEC.replace(old, new, 1)


# (id, spec text, expected words in the message)
BAD_SPECS = [
    ("malformed-toml", GOOD_SPEC.replace("Ts = 0.01", "Ts = = 0.01"), "not valid TOML"),
    (
        "missing-plant",
        GOOD_SPEC.replace('[plant]\nkind = "continuous"\n', "[plant_]\n"),
        "unknown key 'plant_' (did you mean 'plant'?)",
    ),
    (
        "A-not-square",
        spec_with("A = [[0.0, 1.0], [0.0, -2.0]]", "A = [[0.0, 1.0, 0.0], [0.0, -2.0, 0.0]]"),
        "must be square",
    ),
    ("B-wrong-rows", spec_with("B = [[0.0], [4.0]]", "B = [[0.0], [4.0], [1.0]]"), "plant.B has 3 rows"),
    ("C-wrong-columns", spec_with("C = [[1.0, 0.0]]", "C = [[1.0, 0.0, 0.0]]"), "plant.C has 3 columns"),
    ("D-wrong-dims", spec_with("C = [[1.0, 0.0]]", "C = [[1.0, 0.0]]\nD = [[0.0, 0.0]]"), "plant.D is 1x2"),
    ("ragged-matrix", spec_with("A = [[0.0, 1.0], [0.0, -2.0]]", "A = [[0.0, 1.0], [0.0]]"), "different lengths"),
    ("nan-entry", spec_with("A = [[0.0, 1.0], [0.0, -2.0]]", "A = [[0.0, 1.0], [nan, -2.0]]"), "NaN or infinite"),
    ("inf-entry", spec_with("B = [[0.0], [4.0]]", "B = [[0.0], [inf]]"), "NaN or infinite"),
    ("non-numeric", spec_with("B = [[0.0], [4.0]]", 'B = [[0.0], ["four"]]'), "non-numeric"),
    ("Ts-zero", spec_with("Ts = 0.01", "Ts = 0.0"), "Ts must be a finite number > 0"),
    ("Ts-negative", spec_with("Ts = 0.01", "Ts = -0.01"), "Ts must be a finite number > 0"),
    ("Ts-string", spec_with("Ts = 0.01", 'Ts = "fast"'), "Ts must be a number"),
    ("Q-not-psd", spec_with("Q_diag = [10.0, 0.1]", "Q_diag = [10.0, -0.1]"), "not positive semi-definite"),
    ("Q-not-symmetric", spec_with("Q_diag = [10.0, 0.1]", "Q = [[1.0, 0.5], [0.0, 1.0]]"), "not symmetric"),
    ("R-not-pd", spec_with("R_diag = [1.0]", "R_diag = [0.0]"), "not positive definite"),
    ("V-not-pd", spec_with("V_diag = [1e-4]", "V_diag = [-1e-4]"), "not positive definite"),
    (
        "unstabilizable",
        spec_with("B = [[0.0], [4.0]]", "B = [[0.0], [0.0]]").replace(
            "A = [[0.0, 1.0], [0.0, -2.0]]", "A = [[0.5, 0.0], [0.0, -2.0]]"
        ),
        "not stabilizable",
    ),
    (
        "undetectable",
        spec_with("A = [[0.0, 1.0], [0.0, -2.0]]", "A = [[-1.0, 0.0], [0.0, 0.5]]").replace(
            "B = [[0.0], [4.0]]", "B = [[1.0], [1.0]]"
        ),
        "not detectable",
    ),
    (
        "current-with-D",
        spec_with("C = [[1.0, 0.0]]", "C = [[1.0, 0.0]]\nD = [[0.5]]").replace(
            'method = "kalman"', 'method = "kalman"\nform = "current"'
        ),
        "requires a plant without feedthrough",
    ),
    ("unknown-top-key", GOOD_SPEC + 'colour = "blue"\n', "unknown key 'colour'"),
    (
        "unknown-controller-key",
        spec_with("R_diag = [1.0]", "R_diag = [1.0]\nQdiag = [1.0, 1.0]"),
        "unknown key 'Qdiag' (did you mean 'Q_diag'?)",
    ),
    ("u-min-above-max", spec_with("u_min = [-5.0]", "u_min = [6.0]"), "u_min must be below"),
    ("u-max-wrong-length", spec_with("u_max = [5.0]", "u_max = [5.0, 5.0]"), "has 2 entries, expected 1"),
    ("integral-unknown-output", spec_with("outputs = [0]", 'outputs = ["speed"]'), "not an output"),
    ("bad-anti-windup", spec_with("u_max = [5.0]", 'u_max = [5.0]\nanti_windup = "sometimes"'), "anti_windup must be"),
    (
        "two-Q-forms",
        spec_with("Q_diag = [10.0, 0.1]", "Q_diag = [10.0, 0.1]\nbryson_x_max = [1.0, 1.0]"),
        "only one of",
    ),
    ("bryson-zero", spec_with("Q_diag = [10.0, 0.1]", "bryson_x_max = [1.0, 0.0]"), "must be > 0"),
    (
        "luenberger-pole-count",
        spec_with(
            'method = "kalman"\nW_diag = [1e-4, 1e-2]\nV_diag = [1e-4]', 'method = "luenberger"\npoles = [-10.0]'
        ),
        "gives 1 poles, expected 2",
    ),
    (
        "unstable-requested-pole",
        spec_with(
            'method = "lqr"\nQ_diag = [10.0, 0.1]\nR_diag = [1.0]', 'method = "place"\npoles = [-1.0, -2.0, 3.0]'
        ),
        "every pole must be stable",
    ),
    ("velocity-sensor-undetectable", spec_with("C = [[1.0, 0.0]]", "C = [[0.0, 1.0]]"), "not detectable"),
    # G(s) = 1/(s+1) - 2/(s+2) = -s/((s+1)(s+2)): a zero at s = 0, so no integrator can hold its output
    (
        "integral-infeasible",
        spec_with("A = [[0.0, 1.0], [0.0, -2.0]]", "A = [[-1.0, 0.0], [0.0, -2.0]]")
        .replace("B = [[0.0], [4.0]]", "B = [[1.0], [1.0]]")
        .replace("C = [[1.0, 0.0]]", "C = [[1.0, -2.0]]"),
        "integral action is not feasible",
    ),
    ("bad-name", spec_with('name = "servo"', 'name = "9 lives"'), "'name' must be an identifier"),
    (
        "op-not-a-table",
        GOOD_SPEC.replace('name = "servo"', 'name = "servo"\noperating_point = 3.0'),
        "'operating_point' must be a table",
    ),
    (
        "op-unknown-key",
        GOOD_SPEC + "[operating_point]\nu_opp = [1.0]\n",
        "unknown key 'u_opp' (did you mean 'u_op'?) in operating_point",
    ),
    (
        "op-u-wrong-length",
        GOOD_SPEC + "[operating_point]\nu_op = [1.0, 2.0]\n",
        "operating_point.u_op has 2 entries, expected 1",
    ),
    (
        "op-x-wrong-length",
        GOOD_SPEC + "[operating_point]\nx_op = [1.0]\n",
        "operating_point.x_op has 1 entries, expected 2",
    ),
    ("op-y-nan", GOOD_SPEC + "[operating_point]\ny_op = [nan]\n", "operating_point.y_op holds a NaN or infinite"),
    (
        "op-y-unknown-output",
        GOOD_SPEC + "[operating_point]\ny_op = { speed = 1.0 }\n",
        "operating_point.y_op names 'speed', which is not a plant output",
    ),
    (
        "op-by-name-inf",
        GOOD_SPEC + "[operating_point]\nu_op = { u0 = inf }\n",
        "operating_point.u_op.u0 must be a finite",
    ),
    ("op-by-name-string", GOOD_SPEC + '[operating_point]\nx_op = { x1 = "fast" }\n', "x_op.x1 must be a finite number"),
    ("op-u-outside-limits", GOOD_SPEC + "[operating_point]\nu_op = [7.5]\n", "outside the limits [-5, 5]"),
    (
        "improper-tf",
        """name = "tf"\nTs = 0.1\n[plant]\nkind = "transfer_function"\nnum = [[[1.0, 0.0, 1.0]]]
den = [[[1.0, 1.0]]]\n[controller]\nQ_diag = [1.0]\nR_diag = [1.0]\n[observer]\nW_diag = [1.0]\nV_diag = [1.0]
[limits]\nu_min = [-1.0]\nu_max = [1.0]\n""",
        "improper",
    ),
]


@pytest.mark.parametrize("case", BAD_SPECS, ids=[c[0] for c in BAD_SPECS])
def test_bad_spec_is_refused_without_writing(case, tmp_path):
    _, text, words = case
    spec = tmp_path / "spec.toml"
    spec.write_text(text)
    assert_refused(("design", spec, "--out", tmp_path / "out"), words, tmp_path)
    if "TOML" not in words:  # analyze reads the same spec and refuses it the same way (or reports it)
        res = run_cli("analyze", spec)
        assert res.code in (0, 2)


def test_good_spec_designs(tmp_path):
    spec = tmp_path / "spec.toml"
    spec.write_text(GOOD_SPEC)
    assert run_cli("design", spec, "--out", tmp_path / "out").code == 0
    assert run_cli("validate", tmp_path / "out" / "gains.json").code == 0


def _tamper(path, fn):
    data = json.loads(path.read_text())
    fn(data)
    path.write_text(json.dumps(data))


BAD_ARTIFACTS = [
    ("sha-mismatch", lambda d: d["K"][0].__setitem__(0, d["K"][0][0] * 1.01), "sha256 mismatch"),
    ("unknown-key", lambda d: d.__setitem__("Kd", [[1.0]]), "Additional properties are not allowed"),
    ("missing-key", lambda d: d.pop("L"), "'L' is a required property"),
    ("bad-anti-windup", lambda d: d.__setitem__("anti_windup", "maybe"), "anti_windup"),
    ("wrong-dims", lambda d: d.__setitem__("K", [[1.0, 2.0]]), "matrix K is 1x2, expected 1x4"),
    ("u-op-wrong-length", lambda d: d.__setitem__("u_op", [1.0, 2.0]), "vector u_op has length 2, expected 1"),
    ("y-op-not-numbers", lambda d: d.__setitem__("y_op", [0.0, "up"]), "y_op/1: 'up' is not of type 'number'"),
]


@pytest.mark.parametrize("case", BAD_ARTIFACTS, ids=[c[0] for c in BAD_ARTIFACTS])
def test_bad_artifact_is_refused(case, pendulum_artifact, tmp_path):
    _, fn, words = case
    _tamper(pendulum_artifact, fn)
    if words != "sha256 mismatch":  # fix the hash so the structural check is what fires
        from gainlink.shipping.artifact import seal

        data = json.loads(pendulum_artifact.read_text())
        pendulum_artifact.write_text(json.dumps(seal(data)))
    assert_refused(("validate", pendulum_artifact), words, tmp_path)
    assert_refused(("simulate", pendulum_artifact, "--out", tmp_path / "o.csv"), words, tmp_path)


def test_artifact_not_json_and_nan_constant(tmp_path):
    p = tmp_path / "gains.json"
    p.write_text("{not json")
    assert_refused(("validate", p), "not valid JSON", tmp_path)
    p.write_text('{"K": NaN}')
    assert_refused(("validate", p), "non-finite constant NaN", tmp_path)
    assert_refused(("validate", tmp_path / "absent.json"), "not found", tmp_path)


def test_bad_replay_inputs(pendulum_artifact, tmp_path):
    out = tmp_path / "out.csv"
    cases = [
        ("y0,r0\n1.0,0.0\n", "lacks column(s) y1"),
        ("y0,y1,r0,extra\n1,2,3,4\n", "unknown column 'extra'"),
        ("y0,y1,r0\n1.0,abc,0.0\n", "line 2, column y1: 'abc' is not a number"),
        ("y0,y1,r0\n1.0,2.0\n", "line 2 has 2 fields, expected 3"),
        ("y0,y1,r0\n", "no samples"),
    ]
    for i, (text, words) in enumerate(cases):
        inp = tmp_path / f"in{i}.csv"
        inp.write_text(text)
        assert_refused(("replay", pendulum_artifact, "--input", inp, "--output", out), words, tmp_path)
    inp = tmp_path / "ok.csv"
    inp.write_text("y0,y1,r0\n0.1,0.0,0.0\n")
    assert_refused(
        ("replay", pendulum_artifact, "--input", inp, "--output", out, "--engine", "abacus"),
        "unknown engine 'abacus'",
        tmp_path,
    )
    assert_refused(
        ("replay", pendulum_artifact, "--input", inp, "--output", tmp_path / "nodir" / "o.csv"),
        "does not exist",
        tmp_path,
    )


def test_output_path_that_is_a_file(tmp_path):
    from support.paths import EXAMPLES

    f = tmp_path / "taken"
    f.write_text("keep me")
    assert_refused(("design", EXAMPLES / "pendulum.toml", "--out", f), "is not a directory", tmp_path)


def test_usage_errors_are_one_line_too(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # where a command would write by default
    assert_refused(("design",), "required", tmp_path)
    assert_refused(("frobnicate",), "invalid choice", tmp_path)


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["desing"], "invalid choice: 'desing' (did you mean 'design'?)"),
        (["firmware", "build", "g.json", "--target", "cortex-m44"], "'cortex-m44' (did you mean 'cortex-m4'?)"),
        (["hil", "run", "pendulum_fmx"], "nor a built-in scenario (did you mean 'pendulum_fmu'?)"),
        (["hil", "study", "--study", "saturation_kik"], "study 'saturation_kik' (did you mean 'saturation_kick'?)"),
    ],
)
def test_a_misspelt_name_gets_the_closest_one_suggested(argv, words, tmp_path):
    assert_refused((*argv, "--report" if argv[0] == "hil" else "--out", tmp_path / "out"), words, tmp_path)


def test_a_built_in_scenario_without_an_artifact_asks_for_one(tmp_path):
    # its artifact = "gains.json" is a placeholder: it was read beside the package's scenario file
    argv = ("hil", "run", "pendulum_fmu", "--report", tmp_path / "out")
    phrase = "the built-in scenario pendulum_fmu runs an artifact of yours: give it (--artifact"
    res = assert_refused(argv, phrase, tmp_path)
    assert "scenarios/gains.json" not in res.err


def test_the_help_says_hil_runs_over_can_and_mavlink():
    res = run_cli("--help")
    assert res.code == 0
    assert "hardware-in-the-loop bridge over CAN or MAVLink" in " ".join(res.out.split())
    assert "130  interrupted (Ctrl-C" in res.out


def test_real_console_script_exit_status(tmp_path):
    spec = tmp_path / "bad.toml"
    spec.write_text(spec_with("Ts = 0.01", "Ts = -1.0"))
    script = Path(sys.executable).parent / "gainlink"  # the installed console script
    res = assert_refused(
        [script, "design", spec, "--out", tmp_path / "o"], "Ts must be a finite number", tmp_path, process=True
    )
    assert res.err == "gainlink: error: Ts must be a finite number > 0, got -1.0\n"


@pytest.mark.parametrize("rows", [29, 51], ids=["fewer-rows", "more-rows"])
def test_replay_compare_with_a_different_number_of_rows_is_one_line(rows, pendulum_artifact, tmp_path):
    """A comparison file of another length (a truncated recording, another input) is refused before the
    replay writes anything: one line naming both lengths, exit 2 (was: an IndexError traceback)."""
    inp, ref, out = tmp_path / "in.csv", tmp_path / "ref.csv", tmp_path / "out.csv"
    assert run_cli("simulate", pendulum_artifact, "--steps", "50", "--out", inp).code == 0
    assert run_cli("replay", pendulum_artifact, "--input", inp, "--output", ref).code == 0
    lines = ref.read_text().splitlines(keepends=True)
    other = tmp_path / "other.csv"
    other.write_text("".join(lines[: rows + 1] if rows < 50 else lines + lines[1 : rows - 50 + 1]))
    res = assert_refused(
        ("replay", pendulum_artifact, "--input", inp, "--output", out, "--compare", other),
        f"has {rows} samples",
        tmp_path,
    )
    assert "50" in res.err
    # the library call refuses it the same way
    from gainlink.errors import DataError
    from gainlink.proof.onestep import one_step_check
    from gainlink.proof.replay_io import read_samples, read_trace
    from gainlink.shipping.artifact import load

    a = load(pendulum_artifact)
    samples = read_samples(inp, a)
    with pytest.raises(DataError, match=f"the trace has {rows} steps, the samples 50"):
        one_step_check(a, samples.Y, samples.R, read_trace(other, a))
