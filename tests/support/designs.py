"""Designs shared by the whole test run: the artifact of a spec, designed once and read back by every test and
every pytest-xdist worker that asks for the same spec.

The scheduled tank and its variants are designed by a dozen modules, at seconds of CPU each (the envelope's rate
scan and its Lyapunov certificates). Tests of the design itself call :func:`gainlink.synthesis.synthesize`; tests
that only need its artifact call :func:`designed`.
"""

from __future__ import annotations

import copy
import hashlib
import json
from typing import Any

import pytest
from gainlink.spec import parse_spec
from gainlink.synthesis import synthesize

from .shared import once_per_run

_FACTORY: list[pytest.TempPathFactory] = []  # the run's, registered by conftest before any test
_LOCAL: dict[str, dict] = {}  # this process's copies


def register(factory: pytest.TempPathFactory) -> None:
    """Called once per process by the session fixture of ``conftest.py``."""
    _FACTORY[:] = [factory]


def designed(spec: dict) -> dict[str, Any]:
    """The artifact dict of the spec dict ``spec``, designed once per test run; a fresh copy."""
    data = copy.deepcopy(spec)
    text = json.dumps(data, sort_keys=True, default=str)
    key = "design-" + hashlib.sha256(text.encode()).hexdigest()[:16]
    if key not in _LOCAL:
        make = lambda: synthesize(parse_spec(data)).artifact  # noqa: E731
        _LOCAL[key] = once_per_run(_FACTORY[0], key, make) if _FACTORY else make()  # no factory: not in a test
    return copy.deepcopy(_LOCAL[key])
