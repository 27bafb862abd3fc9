"""`gainlink firmware run` of a fixed-point artifact runs its integer law: the host build's integer loop executable
(gainlink_loop_host, firmware/ports/host/main.c: the one host main, running the integer law), not the float32 loop of
the same export.

With --input the replay CSV starts with the `# numeric=q31|q15` line `gainlink replay` writes for the artifact, and
its commands, estimate and integrators are the integer words of the bit-exact numpy model
(gainlink.laws.fixed.model, the oracle) in real units, bit for bit, and not the float32 law's; without --input the
executable answers stdin lines with the model's words, each as it comes (a program may drive it line by line). On
the q31 pendulum and the q15 Wood-Berry column, samples about the middle of their declared ranges, one past its range
(clipped and flagged) and one NaN (refused)."""

from __future__ import annotations

import select
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from gainlink.laws import law_of
from gainlink.laws.fixed.model import FixedPointLoop
from gainlink.laws.fixed.qformat import real
from gainlink.laws.lq.model import Float32Loop
from support.fixed import example, model_run

GAINLINK = str(Path(sys.executable).with_name("gainlink"))
STEPS = 120
NAN_STEP, CLIP_STEP = 7, 30
SPREAD = 0.2  # of each half range: most steps unsaturated, so the commands are the law's own


@pytest.fixture(scope="module", params=[("pendulum", "q31"), ("wood_berry", "q15")], ids=lambda c: c[1])
def saved(request, tmp_path_factory):
    """A fixed-point example saved, with float32 samples and references about the middle of their ranges, one past
    its range and one NaN."""
    a = example(*request.param)
    path = tmp_path_factory.mktemp(f"fxrun-{request.param[1]}") / "gains.json"
    a.save(path)
    rng = np.random.default_rng(19)
    ranges = a.checks["fixed_point"]["ranges"]

    def draw(lo, hi, size):
        lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
        return ((lo + hi) / 2 + SPREAD * (hi - lo) / 2 * rng.uniform(-1, 1, (STEPS, size))).astype(np.float32)

    Y = draw(ranges["y_min"], ranges["y_max"], a.p)
    R = draw(ranges["r_min"], ranges["r_max"], a.q) if a.q else np.zeros((STEPS, 0), dtype=np.float32)
    Y[NAN_STEP, 0] = np.nan
    Y[CLIP_STEP, 0] = 2 * ranges["y_max"][0] - ranges["y_min"][0]  # past its range: clipped and flagged
    return a, path, Y.astype(np.float64), R.astype(np.float64)


def _input_csv(path: Path, a, Y, R, t) -> None:
    header = ["t"] + [f"y{i}" for i in range(a.p)] + [f"r{i}" for i in range(a.q)]
    rows = [",".join(repr(float(v)) for v in np.concatenate([[t[k]], Y[k], R[k]])) for k in range(len(Y))]
    path.write_text(",".join(header) + "\n" + "\n".join(rows) + "\n")


def test_firmware_run_replays_a_fixed_point_artifact_through_the_integer_loop(saved, tmp_path):
    a, path, Y, R = saved
    numeric = a.checks["fixed_point"]["numeric"]
    t = np.arange(STEPS) * a.Ts
    _input_csv(tmp_path / "in.csv", a, Y, R, t)
    out = tmp_path / "out.csv"
    proc = subprocess.run(
        [GAINLINK, "firmware", "run", str(path), "--input", str(tmp_path / "in.csv"), "--output", str(out)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr
    # The oracle's words, in real units: the commands, estimate and integrators bit for bit, and every flag.
    model, f = model_run(a, Y, R), FixedPointLoop(a).f
    got = law_of(a).read_trace(out, a)
    assert np.array_equal(got.u * 2.0 ** f["u"], model.U)
    assert np.array_equal(got.xh * 2.0 ** f["xh"], model.XH)
    assert np.array_equal(got.z * 2.0 ** f["z"], model.Z)
    assert np.array_equal(got.fault, model.fault) and got.fault[NAN_STEP] and got.fault.sum() == 1
    assert np.array_equal(got.saturated, (model.sat[:, None] >> np.arange(a.m)) & 1 != 0)
    assert model.clip[CLIP_STEP] != 0 and not got.fault[CLIP_STEP]
    # Not the float32 loop of the same export.
    f32 = Float32Loop(a).run(Y, R)
    assert np.any(got.u.astype(np.float32) != f32.u.astype(np.float32))
    # The file is what `gainlink replay --engine model` writes for these samples, byte for byte.
    text = out.read_text()
    assert text.splitlines()[0] == f"# numeric={numeric}"
    law = law_of(a)
    assert text == law.trace_text(a, law.replay(a, "model", Y, R), t, engine="model")
    assert "gainlink_loop_host" in proc.stdout and f"{numeric} integer law" in proc.stdout, proc.stdout


def test_firmware_run_without_input_is_the_integer_loop_on_stdin(saved):
    a, path, Y, R = saved
    lines = [" ".join(repr(float(v)) for v in np.concatenate([Y[k], R[k]])) for k in range(40)]
    proc = subprocess.run(
        [GAINLINK, "firmware", "run", str(path)], input="\n".join(lines) + "\n", capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout.splitlines()
    numeric = a.checks["fixed_point"]["numeric"]
    assert (
        out[0]
        == f"gainlink-loop {a.name} sha256:{a.sha256} {a.n} {a.m} {a.p} {a.q} law={numeric} variant=unrolled wire=4"
    )
    # each step: status flags sat u (m floats), then the words U V (m), XH (n), Z (q), clip, overflow
    steps = [line.split()[1:] for line in out[1:]]
    model = model_run(a, Y[:40], R[:40])
    fu = np.array(FixedPointLoop(a).f["u"])
    m = a.m
    for k, words in enumerate(steps):
        _status, flags, sat = (int(v) for v in words[:3])
        *state, clip, _ovf = (int(v) for v in words[3 + m :])
        assert [sat, clip, bool(flags & 1)] == [model.sat[k], model.clip[k], model.fault[k]], k
        assert state == [*model.U[k], *model.V[k], *model.XH[k], *model.Z[k]], k
    assert len(steps) == 40 and np.any(real(model.U, fu) != Float32Loop(a).run(Y[:40], R[:40]).u)


def test_firmware_run_without_input_reads_the_float_loops_lines_and_exits_2_on_an_unreadable_one(saved):
    """The one host loop's stdin lines (commas or tabs between the numbers, `idle`, `reset`) drive the integer law as
    they drive the float one: each answered with its record, the model's words; a line it cannot read (a CSV header)
    is answered `error ...`, changes nothing, and the exit status is 2 with one line on stderr."""
    a, path, Y, R = saved
    rows = [np.concatenate([Y[k], R[k]]) for k in range(6)]
    lines = [",".join(repr(float(v)) for v in rows[0]), "\t".join(repr(float(v)) for v in rows[1])]
    lines += [", ".join(repr(float(v)) for v in row) for row in rows[2:4]]
    header = ",".join([f"y{i}" for i in range(a.p)] + [f"r{i}" for i in range(a.q)])
    script = [header, *lines, "reset", *lines[:2]]
    proc = subprocess.run(
        [GAINLINK, "firmware", "run", str(path)], input="\n".join(script) + "\n", capture_output=True, text=True
    )
    out = proc.stdout.splitlines()
    numeric = a.checks["fixed_point"]["numeric"]
    assert out[0].startswith(f"gainlink-loop {a.name} sha256:{a.sha256} {a.n} {a.m} {a.p} {a.q} law={numeric} ")
    answers = out[1:]
    assert len(answers) == len(script)  # one answer per line, whatever the line
    assert answers[0] == f"error expected {a.p + a.q} numbers, idle, reset, stage or crc"
    assert answers[5].startswith("reset ")
    model = model_run(a, Y[:4], R[:4])
    m = a.m
    for k, line in enumerate(answers[1:5] + answers[6:]):
        assert line.startswith("step "), line
        words = line.split()[1:]
        _status, flags, sat = (int(v) for v in words[:3])
        *state, clip, _ovf = (int(v) for v in words[3 + m :])
        j = k if k < 4 else k - 4  # after the reset: the first steps again
        assert [sat, clip, bool(flags & 1)] == [model.sat[j], model.clip[j], model.fault[j]], k
        assert state == [*model.U[j], *model.V[j], *model.XH[j], *model.Z[j]], k
    assert proc.returncode == 2
    assert proc.stderr.splitlines() == [
        f"gainlink_loop_host: 1 of {len(script)} input lines unreadable (the first: line 1)"
    ]


def _answer(proc: subprocess.Popen, timeout: float) -> str:
    """The next line the process writes, within ``timeout`` seconds (unbuffered pipe: nothing is read ahead)."""
    ready, _, _ = select.select([proc.stdout], [], [], timeout)
    assert ready, f"no answer within {timeout} s"
    return proc.stdout.readline().decode()


def test_the_integer_loop_answers_each_line_before_the_next_is_sent(saved):
    """Driven through pipes one line at a time, as a program talking to the firmware would: every answer is flushed
    as it is made, not when stdin closes."""
    a, path, Y, R = saved
    model = model_run(a, Y[:3], R[:3])
    proc = subprocess.Popen([GAINLINK, "firmware", "run", str(path)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            bufsize=0)  # fmt: skip
    try:
        assert _answer(proc, 300).startswith(f"gainlink-loop {a.name} ")  # after the (cached) build
        for k in range(3):
            proc.stdin.write((" ".join(repr(float(v)) for v in np.concatenate([Y[k], R[k]])) + "\n").encode())
            words = [int(v) for v in _answer(proc, 30).split()[4 + a.m : 4 + 2 * a.m]]  # step status flags sat u U
            assert words == list(model.U[k]), k
    finally:
        proc.stdin.close()
        assert proc.wait(timeout=30) == 0
        proc.stdout.close()
