"""Designs shared by the whole test run: the artifact of a spec, designed once and read back by every test and
every pytest-xdist worker that asks for the same spec.

The scheduled tank and its variants are designed by a dozen modules, at seconds of CPU each (the envelope's rate
scan and its Lyapunov certificates). Tests of the design itself call :func:`gainlink.laws.design`; tests
that only need its artifact call :func:`designed`.
"""

from __future__ import annotations

import copy
import hashlib
import json
from typing import Any

from gainlink.laws import design as design_spec
from gainlink.laws.lq.golden import GoldenCase, example_cases
from gainlink.spec import parse_spec

from .paths import EXAMPLES
from .shared import once

_LOCAL: dict[str, dict] = {}  # this process's copies
_GOLDEN: list[tuple[GoldenCase, ...]] = []


def designed(spec: dict) -> dict[str, Any]:
    """The artifact dict of the spec dict ``spec``, designed once per test run; a fresh copy."""
    data = copy.deepcopy(spec)
    text = json.dumps(data, sort_keys=True, default=str)
    key = "design-" + hashlib.sha256(text.encode()).hexdigest()[:16]
    if key not in _LOCAL:
        _LOCAL[key] = once(key, lambda: design_spec(parse_spec(data)).artifact)
    return copy.deepcopy(_LOCAL[key])


def golden_examples() -> tuple[GoldenCase, ...]:
    """:func:`gainlink.laws.lq.golden.example_cases` of the shipped examples (their designs and golden records, 2.2
    CPU-s), made once per test run: eight modules use them, spread over every worker. One copy per process, as the
    function's own cache gives."""
    if not _GOLDEN:
        _GOLDEN.append(once("golden-example-cases", lambda: example_cases(EXAMPLES)))
    return _GOLDEN[0]
