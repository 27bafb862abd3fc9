"""A value computed once per test run and shared by every pytest-xdist worker of the run.

Session fixtures run once per worker; a costly, deterministic value (the random golden designs take some 20 s of
CPU) would be computed by each. :func:`once_per_run` computes it in the first worker that asks, under a file lock
in the run's shared temporary folder, and the others read it back (pickle).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import pickle
from collections.abc import Callable, Iterator
from typing import Any, TypeVar

import numpy as np
import pytest
from gainlink.fileio import atomic_write_bytes, exclusive_lock

T = TypeVar("T")

_RUN: list[pytest.TempPathFactory] = []  # the run's factory, registered by conftest before any test


def once_per_run(factory: pytest.TempPathFactory, name: str, make: Callable[[], T]) -> T:
    """``make()``, computed by one process of this run; every call gets its own copy (unpickled), in one process as
    under pytest-xdist (`make test TEST_WORKERS=0`, ``-n 0``: the slow-first order sets a module fixture up again
    after its module's slow tests, and the modules sharing a value each asked for it)."""
    base = factory.getbasetemp()
    root = base.parent if "PYTEST_XDIST_WORKER" in os.environ else base  # the run's folder, above every worker's own
    path = root / f"{name}.pickle"
    with exclusive_lock(root / f"{name}.lock"):
        if path.is_file():
            value: T = pickle.loads(path.read_bytes())
            return value
        value = make()
        atomic_write_bytes(path, pickle.dumps(value))
        return value


def register_run(factory: pytest.TempPathFactory) -> None:
    """Called once per process by the autouse session fixture of ``conftest.py``."""
    _RUN[:] = [factory]


def once(name: str, make: Callable[[], T]) -> T:
    """:func:`once_per_run` for helpers called without fixtures (computed here when no test runs)."""
    return once_per_run(_RUN[0], name, make) if _RUN else make()


@contextlib.contextmanager
def shared_lmi_solves(factory: pytest.TempPathFactory) -> Iterator[None]:
    """Within it, each LMI of the scheduled law's certificate search (:meth:`gainlink.synthesis.lmi.LmiFamily.solve`)
    is solved once per test run and read back by any design that builds the same problem, bit for bit (its standard
    form's hash names it): the showcase's tank and examples/tank_showcase_load.toml, designed by different modules,
    search the same certificate (21 Clarabel solves, ~20 CPU-s). Only the solver's candidate is shared: each design
    still proves its certificate itself (ball arithmetic on the candidate), as it would after a solve."""
    from gainlink.synthesis import lmi

    solve = lmi.LmiFamily.solve

    def shared(family: lmi.LmiFamily) -> lmi.LmiSolution:
        return once_per_run(factory, f"lmi-{_problem_key(family)}", lambda: solve(family))

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(lmi.LmiFamily, "solve", shared)
        yield


def _problem_key(family: Any) -> str:
    """A hash of ``family``'s whole problem as the solvers get it (matrices, cones, bounds)."""
    A, b, c, cones = family._standard_form()
    h = hashlib.sha256()
    for part in (A.indptr, A.indices, A.data, b, c, np.array([cones, family.N, family.nodes, family.cap], float)):
        h.update(np.ascontiguousarray(part).tobytes())
    return h.hexdigest()[:32]
