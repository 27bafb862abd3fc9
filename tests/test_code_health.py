"""The code's health as part of the test command: ruff's lint and format check, mypy on the public API, and the
import layers (import-linter's contracts in pyproject.toml: layers one way, no import cycles). The documentation's
checks (its build, its code, its figures) are tests/test_docs.py.

Each runs as a subprocess over the whole checkout (configured in pyproject.toml), so under pytest-xdist they run
beside the rest of the suite. A failure shows the tool's own report.
"""

from __future__ import annotations

import os
import subprocess
import sys

from support.cli import assert_refused
from support.paths import ROOT


def run_tool(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, *argv], cwd=ROOT, capture_output=True, text=True, stdin=subprocess.DEVNULL, timeout=600
    )


def test_ruff_lint_is_clean():
    proc = run_tool("-m", "ruff", "check", "--no-cache", "--output-format", "concise", ".")
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_ruff_format_leaves_every_file_unchanged():
    proc = run_tool("-m", "ruff", "format", "--no-cache", "--check", "--diff", ".")
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_mypy_passes_on_the_public_api_strictly():
    proc = run_tool(str(ROOT / "scripts" / "typecheck.py"))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Success: no issues found" in proc.stdout


def test_import_layers_point_one_way_and_nothing_imports_in_a_cycle():
    proc = run_tool(str(ROOT / "scripts" / "lint_imports.py"))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "0 broken" in proc.stdout or "broken" not in proc.stdout, proc.stdout


PROBE = """
import os
import pytest

@pytest.mark.xdist_group("probe")
@pytest.mark.parametrize("k", range(6))
def test_member(request, k):
    with open(os.environ["PROBE_OUT"], "a") as fh:
        fh.write(f"{os.environ['PYTEST_XDIST_WORKER']} {request.node.nodeid}\\n")
"""


def test_an_xdist_group_reaches_one_worker(tmp_path):
    """`make test` keeps the tests of one xdist_group on one worker (their module fixtures made once) only if
    pytest-xdist can tag their ids with the group: under pytest 9 it could not, and every group was silently spread
    over all the workers (pytest is pinned below 9 for this). Six grouped tests on two workers: one worker, tagged."""
    (tmp_path / "test_probe.py").write_text(PROBE)
    out = tmp_path / "ran.txt"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "-q",
            "-n",
            "2",
            "--dist",
            "loadgroup",
            "-p",
            "no:cacheprovider",
            "test_probe.py",
        ],
        cwd=tmp_path,
        env={**os.environ, "PROBE_OUT": str(out)},
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    ran = [line.split(" ", 1) for line in out.read_text().splitlines()]
    assert len(ran) == 6 and len({worker for worker, _ in ran}) == 1, ran
    assert all(nodeid.endswith("@probe") for _, nodeid in ran), ran


FAILING = """
def test_compares():
    seen = [1, 2]
    assert seen == [1, 3]
"""


def test_the_warmed_rewritten_asserts_are_the_ones_pytest_runs(tmp_path):
    """`make test` writes the rewritten asserts once (scripts/warm_test_asserts.py) so that its workers do not each
    rewrite every module. pytest must take that pyc as current (not rewrite again: the file is untouched) and it must
    be pytest's rewrite (the failure explains the comparison, which a plain assert would not)."""
    (tmp_path / "test_warm.py").write_text(FAILING)
    env = {key: value for key, value in os.environ.items() if key != "PYTHONDONTWRITEBYTECODE"}

    def warm() -> subprocess.CompletedProcess[str]:
        script = str(ROOT / "scripts" / "warm_test_asserts.py")
        return subprocess.run([sys.executable, script, str(tmp_path)], env=env, capture_output=True, text=True)

    first = warm()
    assert first.returncode == 0 and "rewrote the asserts of 1 of 1" in first.stdout, first.stdout + first.stderr
    (pyc,) = (tmp_path / "__pycache__").glob("test_warm.*-pytest-*.pyc")
    written = pyc.stat().st_mtime_ns
    again = warm()
    assert again.returncode == 0 and "rewrote" not in again.stdout, again.stdout
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "test_warm.py"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "At index 1 diff: 2 != 3" in proc.stdout, proc.stdout
    assert pyc.stat().st_mtime_ns == written
    argv = [sys.executable, ROOT / "scripts" / "warm_test_asserts.py", tmp_path / "nowhere"]
    res = assert_refused(argv, "is not a folder", tmp_path, process=True, prefix="warm_test_asserts: ", env=env)
    assert res.err == f"warm_test_asserts: {tmp_path / 'nowhere'} is not a folder\n"
