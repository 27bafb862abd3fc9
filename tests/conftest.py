"""Shared fixtures: example specs designed once per session, and an in-process CLI runner."""

from __future__ import annotations

import io
import shutil
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import dataclass
from pathlib import Path

import pytest
from gainlink.cli import main
from gainlink.shipping import artifact as artifact_mod
from gainlink.spec import load_spec
from gainlink.synthesis import synthesize

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
EXAMPLE_NAMES = ("pendulum", "quadrotor_lateral", "wood_berry")


@dataclass(frozen=True)
class CliResult:
    """Exit status and captured output of one in-process ``gainlink`` call."""

    code: int
    out: str
    err: str


def run_cli(*argv: str) -> CliResult:
    """Run ``gainlink`` in-process; any uncaught exception fails the calling test."""
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        try:
            code = main([str(a) for a in argv])
        except SystemExit as exc:  # argparse usage errors
            code = exc.code if isinstance(exc.code, int) else 1
    return CliResult(code=code, out=out.getvalue(), err=err.getvalue())


@pytest.fixture(scope="session")
def example_artifacts(tmp_path_factory) -> dict[str, Path]:
    """gains.json of each example, designed once per session: name -> path."""
    base = tmp_path_factory.mktemp("examples")
    paths = {}
    for name in EXAMPLE_NAMES:
        result = synthesize(load_spec(EXAMPLES / f"{name}.toml"))
        path = base / name / "gains.json"
        path.parent.mkdir()
        artifact_mod.write(path, result.artifact)
        paths[name] = path
    return paths


@pytest.fixture
def pendulum_artifact(example_artifacts, tmp_path) -> Path:
    """A private copy of the pendulum artifact (tests may tamper with it)."""
    dst = tmp_path / "gains.json"
    shutil.copy(example_artifacts["pendulum"], dst)
    return dst


@pytest.fixture(scope="session")
def pend(example_artifacts) -> Path:
    """The pendulum example's gains.json (shared, read-only)."""
    return example_artifacts["pendulum"]
