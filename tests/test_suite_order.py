"""The suite's own machinery, in one process (``make test TEST_WORKERS=0``, ``pytest -n 0``): the slow-first order
keeps an xdist group's tests together, and a once-per-run value is made once.

Each probe runs a small pytest of its own in a temporary folder, with this suite's ordering hook (``conftest.py``'s
``pytest_collection_modifyitems``, loaded from the file), and counts what it made.
"""

from __future__ import annotations

import os
import subprocess
import sys

from support.paths import ROOT
from support.shared import once_per_run

PLUGIN = f"""
import importlib.util, sys
sys.path.insert(0, {str(ROOT / "tests")!r})
_spec = importlib.util.spec_from_file_location("suite_conftest", {str(ROOT / "tests" / "conftest.py")!r})
_suite = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_suite)
pytest_collection_modifyitems = _suite.pytest_collection_modifyitems

def pytest_configure(config):
    config.addinivalue_line("markers", "slow(cpu=N): probe")
"""

GROUPED = """
import os
import pytest

def note(what):
    with open(os.environ["PROBE_OUT"], "a") as fh:
        fh.write(what + "\\n")

@pytest.fixture(scope="module")
def made():
    note("made")

GROUP = pytest.mark.xdist_group("probe")

@GROUP
@pytest.mark.slow(cpu=5)
def test_slow(made):
    note("test_slow")

@GROUP
def test_quick(made):
    note("test_quick")
"""

OTHER = """
import pytest
from test_a import note

@pytest.mark.slow(cpu=1)
def test_other_slow():
    note("test_other_slow")

def test_other_quick():
    note("test_other_quick")
"""


def test_in_one_process_a_groups_module_fixture_is_made_once(tmp_path):
    """A group's slow test (cpu=5) goes first, another module's slow test (cpu=1) next: the group's quick test
    must come with its slow one, or its module fixture is torn down between them and made again (as the campaign
    module's two clusters were, by `make test TEST_WORKERS=0`)."""
    (tmp_path / "probe_plugin.py").write_text(PLUGIN)
    (tmp_path / "test_a.py").write_text(GROUPED)
    (tmp_path / "test_b.py").write_text(OTHER)
    out = tmp_path / "made.txt"
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-n", "0", "-p", "probe_plugin", "-p", "no:cacheprovider"],
        cwd=tmp_path,
        env={**os.environ, "PROBE_OUT": str(out), "PYTHONPATH": str(tmp_path)},
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert out.read_text().splitlines() == ["made", "test_slow", "test_quick", "test_other_slow", "test_other_quick"]


def test_a_once_per_run_value_is_made_once_and_each_call_gets_its_own_copy(tmp_path_factory, request):
    """In one process as under xdist: two modules asking for one value (the showcase tank's design by
    test_schedule_rate_proof and test_sched_campaign_example) made it twice in one process."""
    calls: list[int] = []

    def make() -> dict[str, list[int]]:
        calls.append(1)
        return {"value": [1, 2, 3]}

    name = f"probe-{request.node.name}-{os.getpid()}"
    first, second = once_per_run(tmp_path_factory, name, make), once_per_run(tmp_path_factory, name, make)
    assert calls == [1]
    assert first == second == {"value": [1, 2, 3]} and first is not second  # a caller may change its copy
