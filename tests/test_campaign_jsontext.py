"""A block's JSON texts made a structure at a time (:mod:`gainlink.hil.campaign.jsontext`).

Oracle: ``json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=False)`` of each value, byte for byte,
and the same exception where it refuses one.
"""

from __future__ import annotations

import enum
import json
import math

import numpy as np
import pytest
from gainlink.hil.campaign.jsontext import Shared, form_texts, json_forms, json_texts, object_texts
from hypothesis import given, settings
from hypothesis import strategies as st


def _oracle(value) -> str:
    return json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=False)


def _metrics(k: int, x: float) -> dict:
    """A run's metrics as a block makes them: nested dicts of numbers, bools, strings and a list."""
    return {
        "complete": k % 7 != 3,
        "mode": "sil",
        "steps": 1000,
        "saturated_steps": k,
        "faults_injected": {},
        "latency_us": {"max": 221.859, "p50": 36.5025},
        "outputs_final": {"theta": -x * 1e-3, "x": x},
        "tracked": {"r_x": {"iae": x * x, "overshoot_pct": 100.0 * x, "settling_time_s": None, "start_s": 0.0}},
        "twin": {"iae": {"r_x": {"difference": x * 1e-9, "real": x}}, "steps": 1000},
        "names": ["x", "theta"],
    }


def _through_forms(values: list) -> list[str]:
    """Each value's text as a block file gives it back: its form's template filled with its slots, the floats
    through float64 numbers (:func:`json_forms`, then :func:`form_texts` as ``store.metric_texts`` reads them)."""
    forms, whole = json_forms(values)
    out: list = [None] * len(values)
    for form in forms:
        texts = [col for kind, col in zip(form.kinds, form.columns) if kind == "t"]
        floats = [col for kind, col in zip(form.kinds, form.columns) if kind == "f"]
        numbers = np.array(floats, np.float64).T.reshape(len(form.rows), -1)
        for i, text in zip(form.rows, form_texts(form.template, form.kinds, texts, numbers)):
            out[i] = text
    for i, text in whole.items():
        out[i] = text
    return out


class _Level(enum.IntEnum):
    LOW = 1


SPECIAL = [
    ("ints and floats in one key", lambda k, m: m | {"steps": 1000.0 if k % 2 else 1000}),
    ("negative and positive zero", lambda k, m: m | {"outputs_final": {"theta": -0.0 if k % 2 else 0.0, "x": 0.0}}),
    ("large and tiny floats", lambda k, m: m | {"latency_us": {"max": [1e16, 1e15, 1e22][k % 3], "p50": 5e-324 * k}}),
    ("exponent thresholds", lambda k, m: m | {"late": [1e-4, 1e-5, 9999999999999998.0, 0.1 + 0.2][k % 4]}),
    ("all zeros of one sign", lambda k, m: m | {"loop_cpu_s": -0.0}),
    ("keys that need escapes", lambda k, m: m | {'a"b\\c%s%%é\n': {"\u2603": k, "%d": "é%s\x00"}}),
    ("a run missing a key", lambda k, m: {key: v for key, v in m.items() if k % 3 or key != "twin"}),
    ("a run with an extra key", lambda k, m: m | ({"extra": {"deep": [k]}} if k % 4 == 1 else {})),
    ("one key, not the same", lambda k, m: m | {"one": {"a" if k % 2 else "b": k}}),
    ("a nested key missing", lambda k, m: m | {"tracked": {"r_x": {"iae": 1.5}} if k == 2 else m["tracked"]}),
    ("a bool where another run has a number", lambda k, m: m | {"saturated_steps": k % 2 == 0 if k % 3 else k}),
    ("None where another has a dict", lambda k, m: m | {"twin": None if k % 2 else m["twin"]}),
    ("lists of other lengths", lambda k, m: m | {"names": ["x"] * (k % 3)}),
    ("an int subclass", lambda k, m: m | {"steps": _Level.LOW if k == 1 else 1}),
    ("a numpy float", lambda k, m: m | {"late": np.float64(k / 3) if k % 2 else k / 3}),
    ("a tuple", lambda k, m: m | {"names": ("x", "theta") if k == 3 else ["x", "theta"]}),
    ("non-string keys", lambda k, m: m | {"by_step": {1: 2.0, 3: 4.0} if k == 2 else {"1": 2.0, "3": 4.0}}),
    ("empty dicts and lists everywhere", lambda k, m: {"a": {}, "b": [], "c": [{}, []], "d": {"e": {}}}),
    ("a constant string with a percent", lambda k, m: m | {"mode": "50% sil"}),
]


@pytest.mark.parametrize("name, change", SPECIAL, ids=[name for name, _ in SPECIAL])
def test_a_blocks_json_texts_are_each_runs_json(name, change):
    rng = np.random.default_rng(3)
    values = [change(k, _metrics(k, float(rng.lognormal()))) for k in range(12)]
    assert json_texts(values) == [_oracle(v) for v in values]
    assert _through_forms(values) == [_oracle(v) for v in values]


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_value_json_refuses_is_refused_as_json_refuses_it(bad):
    values = [_metrics(k, 1.0 + k) for k in range(5)]
    values[2]["tracked"]["r_x"]["iae"] = bad
    with pytest.raises(ValueError, match="Out of range float values are not JSON compliant"):
        _oracle(values[2])
    with pytest.raises(ValueError, match="Out of range float values are not JSON compliant"):
        json_texts(values)
    values[2]["tracked"]["r_x"]["iae"] = 1.0  # the other runs alone: every one as json writes it
    assert json_texts(values) == [_oracle(v) for v in values]


def test_an_object_of_columns_is_each_runs_object():
    seeds = [7, 2**40, 3]
    scenarios = [{"plant": {"parameters": {"M": 1.0 + k / 3, "g": 9.81}}, "duration": 10.0} for k in range(3)]
    columns = {"id": ["a", "b", "c"], "inputs": {"kind": ["sil"] * 3, "scenario": scenarios, "seed": seeds},
               "status": ["done"] * 3}  # fmt: skip
    want = [
        {"id": i, "inputs": {"kind": "sil", "scenario": sc, "seed": seed}, "status": "done"}
        for i, sc, seed in zip("abc", scenarios, seeds)
    ]
    assert object_texts(columns, 3) == [_oracle(w) for w in want]
    assert object_texts({}, 2) == ["{}", "{}"] and json_texts([]) == [] and object_texts(columns | {"id": []}, 0) == []


def test_a_value_every_run_shares_is_written_once_as_json_writes_it_in_each_run():
    """A column tree with :class:`Shared` values (a scenario's tables its runs share): each run's object as json writes
    it whole, keys sorted across shared and own values at every level; a shared value json refuses (a NaN, keys it
    cannot sort) refused for every run as json refuses it."""
    plant = {"kind": "cart_pendulum", "outputs": ["x", "theta"], "parameters": None, "step": 0.005, "%": -0.0}
    tree = {"plant": {k: Shared(v) for k, v in plant.items() if k != "parameters"}, "duration": Shared(10.0)}
    tree["plant"]["parameters"] = {"M": [1.0, 1.2500000000000002, 0.75], "g": Shared(9.81), "l": Shared(1)}
    tree["noise"] = Shared({"x": 5e-4, "theta": 0.0})
    want = [{"plant": plant | {"parameters": {"M": M, "g": 9.81, "l": 1}}, "duration": 10.0,
             "noise": {"x": 5e-4, "theta": 0.0}} for M in (1.0, 1.2500000000000002, 0.75)]  # fmt: skip
    assert object_texts(tree, 3) == [_oracle(w) for w in want]
    for bad, error in ((math.nan, ValueError), ({1: 2, "a": 3}, TypeError)):
        with pytest.raises(error):
            _oracle(want[0] | {"z": bad})
        with pytest.raises(error):
            object_texts(tree | {"z": Shared(bad)}, 3)


_LEAF = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=False, allow_infinity=False),
    st.text(max_size=6),
)
_JSON = st.recursive(
    _LEAF,
    lambda inner: st.one_of(st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=4), inner, max_size=4)),
    max_leaves=12,
)


@settings(max_examples=100, deadline=None)
@given(base=_JSON, others=st.lists(_JSON, max_size=3), picks=st.lists(st.integers(0, 3), min_size=1, max_size=12))
def test_any_mix_of_json_values_gives_each_ones_json(base, others, picks):
    """Runs that mostly share one structure (``base``) and some that do not: each run's text is its own json."""
    pool = [base, *others]
    values = [pool[k % len(pool)] for k in picks]
    assert json_texts(values) == [_oracle(v) for v in values]
    assert _through_forms(values) == [_oracle(v) for v in values]


@settings(max_examples=100, deadline=None)
@given(numbers=st.lists(st.floats(allow_nan=False, allow_infinity=False) | st.integers(-(2**64), 2**64), min_size=1))
def test_any_numbers_in_one_key_give_each_ones_json(numbers):
    values = [{"v": {"x": v, "y": [v, -v]}} for v in numbers]
    assert json_texts(values) == [_oracle(v) for v in values]
    assert _through_forms(values) == [_oracle(v) for v in values]


def test_a_long_column_of_floats_of_every_size_is_each_ones_repr():
    """A column long enough for Arrow's texts (``jsontext.float_texts``): floats of every exponent (random bits),
    around the thresholds where Python's ``repr`` switches to an exponent and where Arrow's does (1e-6), integers and
    halves as floats."""
    rng = np.random.default_rng(7)
    bits = np.frombuffer(rng.integers(0, 2**63, 4000, dtype=np.uint64).tobytes(), np.float64)
    edges = np.array([1e-4, 1e-5, 1e15, 1e16, 2.0**52, 2.0**53, 0.1, 0.5])
    near = np.concatenate([np.nextafter(edges, 0.0), np.nextafter(edges, np.inf), edges, -edges])
    floats = np.concatenate([bits, near, rng.lognormal(0, 8, 4000), rng.integers(-(10**6), 10**6, 500) / 2.0,
                             10.0 ** rng.uniform(-30, 30, 4000), -rng.random(4000),
                             10.0 ** rng.uniform(-6.5, -3.5, 3000) * rng.choice([-1, 1], 3000)])  # fmt: skip
    values = [float(v) for v in floats if np.isfinite(v)]
    rng.shuffle(values)
    rows = [{"x": v} for v in values]
    assert json_texts(rows) == [_oracle(r) for r in rows]
    assert _through_forms(rows) == [_oracle(r) for r in rows]
