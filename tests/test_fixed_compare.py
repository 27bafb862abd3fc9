"""`replay --compare` on a fixed-point artifact: the trace, step by step from its own XH, Z words, against the
bit-exact integer law (the oracle: gainlink.laws.fixed.model), command words equal bit for bit. The host C's trace
passes; one command moved by one LSB is caught at its step; a trace of another numeric format is refused (by the
format line a recorded trace carries, and by its words when it has none)."""

from __future__ import annotations

import csv
import io
import re

import pytest
from gainlink.laws import law_of
from gainlink.laws.fixed.onestep import fixed_one_step_check, trace_words
from gainlink.proof.replay_io import read_samples
from gainlink.shipping.artifact import load
from support.cli import assert_refused, run_cli
from support.fixed import pendulum_design

# One worker runs this module (make test: --dist loadgroup): the fixed-point pendulum and its builds, made once.
pytestmark = pytest.mark.xdist_group("test_fixed_compare")

BENT_STEP = 137


@pytest.fixture(scope="module")
def pendulum(tmp_path_factory) -> tuple:
    """The pendulum designed in q31 and q15, 300 noisy samples, and the host C's (native) trace of the q31 one."""
    d = tmp_path_factory.mktemp("fixed-compare")
    gains = {}
    for numeric in ("q31", "q15"):  # q15 meets a coarser error (0.01) than the default 1/4096 on the pendulum
        gains[numeric] = d / numeric / "gains.json"
        gains[numeric].parent.mkdir()
        pendulum_design(numeric).save(gains[numeric])
    sim = run_cli("simulate", gains["q31"], "--steps", "300", "--noise", "0.01", "--out", d / "in.csv")
    assert sim.code == 0, sim.err
    res = run_cli("replay", gains["q31"], "--input", d / "in.csv", "--output", d / "native.csv", "--engine", "native")
    assert res.code == 0, res.err
    return d, gains


def _rewrite(src, dst, edit) -> None:
    """``src`` (a replay CSV) with ``edit(row_index, row)`` applied to each row, written to ``dst`` (after the same
    ``# numeric=...`` line)."""
    meta, _, body = src.read_text().partition("\n")
    assert meta.startswith("# numeric=q"), meta
    rows = list(csv.DictReader(io.StringIO(body)))
    for k, row in enumerate(rows):
        edit(k, row)
    out = io.StringIO()
    out.write(meta + "\n")
    w = csv.DictWriter(out, fieldnames=list(rows[0]), lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    dst.write_text(out.getvalue())


def test_host_c_trace_passes_bit_for_bit(pendulum):
    d, gains = pendulum
    res = run_cli(
        "replay", gains["q31"], "--input", d / "in.csv", "--output", d / "model.csv", "--engine", "model",
        "--compare", d / "native.csv",
    )  # fmt: skip
    assert res.code == 0, res.err
    line = next(ln for ln in res.out.splitlines() if ln.startswith(f"one-step check of {d / 'native.csv'}"))
    assert "pass, 300 steps bit for bit against the q31 integer law from the trace's own XH, Z words" in line
    assert "one-step check of model: pass" in res.out


def test_one_lsb_on_one_command_is_caught_at_its_step(pendulum, tmp_path):
    d, gains = pendulum
    lsb = 2.0 ** -load(gains["q31"]).checks["fixed_point"]["formats"]["u"][0]

    def bend(k, row):
        if k == BENT_STEP:
            row["u0"] = repr(float(row["u0"]) + lsb)

    bent = tmp_path / "bent.csv"
    _rewrite(d / "native.csv", bent, bend)
    argv = ("replay", gains["q31"], "--input", d / "in.csv", "--output", tmp_path / "out.csv", "--compare", bent)
    # a failed check, not a refusal: the replay's output is written, the verdict is one line and exit 2
    res = assert_refused(argv, f"one-step check failed at step {BENT_STEP}: u0 of {bent} is word ")
    assert re.search(r"is word (-?\d+) where the integer law from its own state gives (-?\d+)", res.err)
    got, want = (int(v) for v in re.search(r"word (-?\d+) where .* gives (-?\d+)", res.err).groups())
    assert got - want == 1
    assert f"one-step check of {bent}: FAIL on 1 step(s), 300 steps" in res.out  # the next step starts from its state


def test_a_state_without_its_words_is_quantised_and_said(pendulum, tmp_path):
    """A trace written with twelve significant digits no longer holds the state words: the check starts each step
    from the state quantised to the state formats, says so, and still passes (twelve digits recover the words)."""
    d, gains = pendulum
    a = load(gains["q31"])

    def round12(k, row):
        for key in row:
            if key.startswith(("xh", "z")):
                row[key] = f"{float(row[key]):.12g}"

    short = tmp_path / "short.csv"
    _rewrite(d / "native.csv", short, round12)
    samples = read_samples(d / "in.csv", a)
    check = fixed_one_step_check(a, samples.Y, samples.R, trace_words(a, law_of(a).read_trace(short, a), "short"))
    assert check.passed and not check.state_words
    assert "quantised to the state formats" in check.summary()


def _without_format_line(src, dst):
    """``src`` as a trace recorded before replay outputs named their format."""
    dst.write_text(src.read_text().partition("\n")[2])
    return dst


def test_a_trace_of_another_numeric_format_is_refused_in_one_line(pendulum, tmp_path):
    """By its words, when it does not name its format (a trace recorded before the format line)."""
    d, gains = pendulum
    native = _without_format_line(d / "native.csv", tmp_path / "native.csv")
    argv = ("replay", gains["q15"], "--input", d / "in.csv", "--output", tmp_path / "out.csv", "--compare", native)
    assert_refused(argv, f"comparison file {native} is not a trace of q15 artifact", tmp_path)
    # the float64 law's trace (what a float32 artifact's replay holds) is not one either
    assert run_cli("replay", gains["q31"], "--input", d / "in.csv", "--output", tmp_path / "ref.csv").code == 0
    ref = _without_format_line(tmp_path / "ref.csv", tmp_path / "ref_old.csv")
    argv = ("replay", gains["q31"], "--input", d / "in.csv", "--output", tmp_path / "out.csv", "--compare", ref)
    assert_refused(argv, "is not a trace of q31 artifact", tmp_path)


def test_a_recorded_trace_names_its_format_and_one_of_another_format_is_refused_in_one_line(pendulum, pend, tmp_path):
    """A q15 trace against the q31 artifact: its words are q31 words too (q15's commands have fewer fractional
    bits), so without its format it would fail the one-step check at step 0; its first line refuses it."""
    d, gains = pendulum
    assert (d / "native.csv").read_text().startswith("# numeric=q31\nt,u0,")
    q15 = tmp_path / "q15.csv"
    res = run_cli("replay", gains["q15"], "--input", d / "in.csv", "--output", q15, "--engine", "model")
    assert res.code == 0, res.err
    assert q15.read_text().startswith("# numeric=q15\n")
    argv = ("replay", gains["q31"], "--input", d / "in.csv", "--output", tmp_path / "out.csv", "--compare", q15)
    res = assert_refused(argv, f"comparison file {q15} is a trace of a q15 law and artifact ", tmp_path)
    assert "is a q31 design" in res.err
    old = _without_format_line(q15, tmp_path / "q15_old.csv")  # what the line saves it from
    argv = ("replay", gains["q31"], "--input", d / "in.csv", "--output", tmp_path / "old.csv", "--compare", old)
    res = assert_refused(argv, "one-step check failed at step 0: ")  # a failed check: the output is written
    assert re.search(rf"one-step check failed at step 0: \w+ of {re.escape(str(old))}", res.err)
    # the float64 law's trace of the q31 artifact says what it is, and is refused by that line too
    assert run_cli("replay", gains["q31"], "--input", d / "in.csv", "--output", tmp_path / "ref.csv").code == 0
    assert (tmp_path / "ref.csv").read_text().startswith("# numeric=float64\n")
    argv = ("replay", gains["q31"], "--input", d / "in.csv", "--output", tmp_path / "out.csv", "--compare",
            tmp_path / "ref.csv")  # fmt: skip
    assert_refused(argv, "is a trace of a float64 law and artifact pendulum is a q31 design", tmp_path)
    # a float32 artifact's output is as it was: no format line
    assert run_cli("replay", pend, "--input", d / "in.csv", "--output", tmp_path / "f.csv").code == 0
    assert (tmp_path / "f.csv").read_text().startswith("t,u0,")


def test_a_trace_without_the_format_line_is_read_as_before(pendulum, tmp_path):
    """Traces recorded before the line existed: the one-step check is still the verdict (here: a pass)."""
    d, gains = pendulum
    old = _without_format_line(d / "native.csv", tmp_path / "old.csv")
    res = run_cli("replay", gains["q31"], "--input", d / "in.csv", "--output", tmp_path / "out.csv", "--compare", old)
    assert res.code == 0, res.err
    assert f"one-step check of {old}: pass, 300 steps bit for bit" in res.out
