"""Folders of the checkout the tests read from."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
TESTS = ROOT / "tests"
EXAMPLES = ROOT / "examples"
EXAMPLE_NAMES = ("pendulum", "quadrotor_lateral", "wood_berry")
