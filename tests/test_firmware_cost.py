"""The QEMU TCG instruction-count plugin: exact, deterministic, and the step within its budget."""

from __future__ import annotations

import logging

import pytest
from gainlink.firmware.build import replay_image
from gainlink.firmware.cost import count_step_instructions, law_macs
from support.designs import golden_examples


@pytest.fixture(scope="module")
def pendulum():
    logging.disable(logging.WARNING)
    yield golden_examples()[0]
    logging.disable(logging.NOTSET)


def test_plugin_counts_every_call_deterministically(pendulum):
    a = pendulum.artifact
    elf = replay_image(a, target="cortex-m4", board="mps2-an386")
    one = count_step_instructions(elf, a, Y=pendulum.Y[:200], R=pendulum.R[:200])
    again = count_step_instructions(elf, a, Y=pendulum.Y[:200], R=pendulum.R[:200])
    assert one.calls == 200, "one entry into gl_loop_step per sample"
    assert one == again, "the count is exact and repeatable"
    longer = count_step_instructions(elf, a, Y=pendulum.Y[:400], R=pendulum.R[:400])
    assert longer.calls == 400 and longer.instructions > one.instructions


def test_pendulum_step_within_budget(pendulum):
    """Budget from the issue: <= 100 instructions per step for the pendulum (Kalman, LQI, back-calculation)."""
    a = pendulum.artifact
    assert (a.observer_form, a.anti_windup, a.q) == ("predictor", "backcalc", 1)
    elf = replay_image(a, target="cortex-m4", board="mps2-an386")
    cost = count_step_instructions(elf, a, Y=pendulum.Y, R=pendulum.R)
    assert pendulum.expected.saturated.any(), "the samples take the saturated path too"
    assert cost.per_step <= 100, f"{cost.per_step:.1f} instructions per step"
    assert cost.per_step <= 2.2 * law_macs(a)
