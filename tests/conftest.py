"""Fixtures shared by the test modules: the examples designed once, the firmware apps and FMUs they run against.

Helpers that are not fixtures live in ``tests/support/`` (``from support.cli import run_cli``). Session fixtures
run once per pytest-xdist worker; what they build is cached on disk (``.cache/``) with a file lock, so workers that
ask at the same time build it once.
"""

from __future__ import annotations

import json
import logging
import os
import resource
import shutil
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from gainlink.fileio import exclusive_lock
from gainlink.laws import design as design_spec
from gainlink.laws.lq.golden import GoldenCase, closed_loop_cases, random_cases
from gainlink.shipping import artifact as artifact_mod
from gainlink.shipping.artifact import load
from gainlink.spec import load_spec
from support.mavlink import retuned_pendulum
from support.order import slow_first
from support.paths import EXAMPLE_NAMES, EXAMPLES
from support.shared import once_per_run, register_run


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The tests marked ``slow`` (builds, VMs, long closed loops) run first, the dearest first (``slow(cpu=N)``:
    the CPU seconds the test, or the group or fixture it starts, was measured to take), the rest keep their order,
    and the tests of one ``xdist_group`` stay together where their dearest one falls (support.order): with `make
    test`'s scheduling (``--dist loadgroup --no-loadscope-reorder``: tests a few at a time in this order, those of one
    ``xdist_group`` together on one worker) the long ones spread over the workers from the start instead of ending
    the run on one of them, and in one process a group's module fixtures are made once."""
    slow_first(items)


def _cpu_seconds() -> float:
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    """With ``GAINLINK_TEST_CPU=FILE``, append each test's CPU seconds (the worker's and its reaped child
    processes': builds, QEMU, firmware, Dask workers) to FILE as a JSON line: on a 2-core machine the suite's
    time is its CPU over two, so this, not ``--durations``' wall time under contention, says what to make
    cheaper (``scripts/test_cpu.py FILE`` sums it per test module). Each line also has the xdist worker, the
    test's start (epoch seconds) and its wall time: which worker ran what when (``--timeline``)."""
    path = os.environ.get("GAINLINK_TEST_CPU")
    start, began = _cpu_seconds(), time.time()
    try:
        return (yield)
    finally:
        if path:
            record = {"test": item.nodeid, "cpu": round(_cpu_seconds() - start, 3),
                      "worker": os.environ.get("PYTEST_XDIST_WORKER", "main"),
                      "start": round(began, 3), "wall": round(time.time() - began, 3)}  # fmt: skip
            with open(path, "a") as fh:
                fh.write(json.dumps(record) + "\n")


@pytest.fixture(scope="session", autouse=True)
def _shared_run(tmp_path_factory: pytest.TempPathFactory) -> None:
    """Gives :func:`support.shared.once` (and so :func:`support.designs.designed`) the run's shared folder (autouse:
    before any module's fixtures)."""
    register_run(tmp_path_factory)


@pytest.fixture(scope="session")
def example_artifacts(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """gains.json of each example, designed once per run (by one worker; the others read its files): name ->
    path. Shared: read only."""

    def make() -> dict[str, Path]:
        base = tmp_path_factory.mktemp("examples")
        paths = {}
        for name in EXAMPLE_NAMES:
            result = design_spec(load_spec(EXAMPLES / f"{name}.toml"))
            path = base / name / "gains.json"
            path.parent.mkdir()
            artifact_mod.write(path, result.artifact)
            paths[name] = path
        return paths

    return once_per_run(tmp_path_factory, "example_artifacts", make)


@pytest.fixture(scope="session")
def random_designs(tmp_path_factory: pytest.TempPathFactory) -> tuple[GoldenCase, ...]:
    """The 12 random golden designs of `make test` (``golden.random_cases(12)``: every form and anti-windup mode,
    n up to 12, the second six about operating points), computed once per run and shared by the workers. The
    matrix (`make test-matrix`) runs the 30 of ``random_cases(30)``, whose first 12 these are."""
    return once_per_run(tmp_path_factory, "random_designs", lambda: random_cases(12))


@pytest.fixture(scope="session")
def closed_loop_designs(tmp_path_factory: pytest.TempPathFactory) -> tuple[GoldenCase, ...]:
    """The 12 random designs with closed-loop records (``golden.closed_loop_cases(12)``), once per run."""
    return once_per_run(tmp_path_factory, "closed_loop_designs", lambda: closed_loop_cases(12))


@pytest.fixture
def pendulum_artifact(example_artifacts: dict[str, Path], tmp_path: Path) -> Path:
    """A private copy of the pendulum artifact (tests may tamper with it)."""
    dst = tmp_path / "gains.json"
    shutil.copy(example_artifacts["pendulum"], dst)
    return dst


@pytest.fixture(scope="session")
def pend(example_artifacts: dict[str, Path]) -> Path:
    """The pendulum example's gains.json (shared, read-only)."""
    return example_artifacts["pendulum"]


@pytest.fixture(scope="session")
def retuned(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The pendulum designed again with other weights (shared, read-only): a second set to upload."""
    return retuned_pendulum(tmp_path_factory.mktemp("retuned") / "gains.json")


@pytest.fixture(scope="session")
def can_firmware(pend: Path) -> Path:
    """The firmware's gainlink_can host executable built for the pendulum artifact."""
    from gainlink.hil.links.can_firmware import firmware_can_executable

    return firmware_can_executable(load(pend))


@pytest.fixture(scope="session")
def mavlink_exe(pend: Path) -> Path:
    """The firmware's MAVLink app (gainlink_mavlink) built for the pendulum artifact."""
    from gainlink.firmware.mavlink_app import mavlink_executable

    return mavlink_executable(load(pend))


@pytest.fixture(scope="session")
def cart_fmu() -> Path:
    """The project's nonlinear cart-pendulum FMU, built from its C sources with fmpy."""
    from gainlink.hil.plants.build import build_fmu

    return build_fmu("cart_pendulum")


@pytest.fixture(scope="module")
def quiet_design_warnings() -> Iterator[None]:
    """Design warnings (a compensator unstable by itself, ...) silenced for a module that designs many laws on
    purpose: ``pytestmark = pytest.mark.usefixtures("quiet_design_warnings")``."""
    logging.disable(logging.WARNING)
    yield
    logging.disable(logging.NOTSET)


@pytest.fixture
def realtime_alone() -> Iterator[None]:
    """Run the test with no other realtime HIL run of any suite on this host (a host-wide file lock).

    A realtime run holds the kernel's CPU wake-up latency request (``/dev/cpu_dma_latency``, global to the host)
    and runs under SCHED_FIFO: a test that reads that request, or measures ticks against their deadlines, must
    not overlap another one. Other tests still run beside it (pytest-xdist workers); only realtime runs queue.
    """
    with exclusive_lock(Path(tempfile.gettempdir()) / f"gainlink-realtime-{os.getuid()}.lock"):
        yield
