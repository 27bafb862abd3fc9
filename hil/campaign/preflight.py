"""Checks of a campaign's runs on the client, before any is submitted: a mistake in the campaign file is one
line naming the key (exit status 2, nothing written), not an error in every run.

- :func:`check_axis_values`: every value an axis can set at a path of the base scenario is of the kind the base
  holds there (a number where it holds a number, a string where a string, ...);
- :class:`DryBuild`: the plant of one run of each *shape* (the scenario with its numbers blanked, and the signal
  names of the artifact) is built and reset to the run's initial state, and the run planned on it
  (:func:`~gainlink.hil.loop.plan.plan_run`: references, external scheduling signals, the law's trim; a HIL run's
  link layout too), as the worker would before it builds any firmware or starts any peer, so a misspelt plant
  option, parameter or state name, or a scheduled law's missing ``[schedule_signal]``, is refused here. Plants of
  ``kind = "python"`` and of entry-point plugins are left to the workers: their code may be installed there alone.

The spec's own mistakes are the spec parser's (a ``SpecError`` while planning, see :mod:`.plan`).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

from gainlink.errors import GainlinkError
from gainlink.laws import law_of
from gainlink.shipping.artifact import Artifact, from_dict

from ..links.config import transport_from_config
from ..loop.plan import plan_run
from ..loop.scenario import Scenario
from ..loop.scenario_plant import build_plant
from ..plants.base import PLANTS
from .config import Axis, Campaign, CampaignError, value_at

FAULT_TARGETS = ("faults.drop", "faults.delay_steps", "transport.encoding")
_MISSING = object()


def _kind(value: Any) -> str:
    if isinstance(value, bool):
        return "true or false"
    if isinstance(value, (int, float)):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "a list"
    return "a table" if isinstance(value, dict) else type(value).__name__


def _candidates(axis: Axis) -> list:
    """Every value the axis can set (a numeric distribution: numbers)."""
    if axis.distribution is None:
        return list(axis.values)
    return list(axis.params["values"]) if axis.distribution == "choice" else [0.0]


def _text(value: Any) -> str:
    text = json.dumps(value)
    return text if len(text) <= 40 else text[:37] + "..."


def check_axis_values(campaign: Campaign) -> None:
    """Refuse an axis that sets a value of another kind than the base scenario holds at its path."""
    for axis in (*campaign.grid, *campaign.draws):
        if axis.apply != "set":  # scale and add need a number there, which planning checks
            continue
        for target in axis.targets:
            if target in FAULT_TARGETS or target.startswith("spec."):
                continue
            base = value_at(campaign.scenario, target, _MISSING)
            if base is _MISSING:
                continue
            for value in _candidates(axis):
                if _kind(value) != _kind(base):
                    raise CampaignError(
                        f"campaign: axis {axis.name}: {target} is {_kind(base)} in the scenario ({_text(base)}), "
                        f"so the axis cannot set it to {_text(value)}"
                    )


def _blank_numbers(tree: Any) -> Any:
    if isinstance(tree, dict):
        return {k: _blank_numbers(v) for k, v in tree.items()}
    if isinstance(tree, list):
        return [_blank_numbers(v) for v in tree]
    return 0 if isinstance(tree, (int, float)) and not isinstance(tree, bool) else tree


class DryBuild:
    """Builds the plant of the first run of each shape of a campaign (see the module docstring)."""

    def __init__(self, campaign: Campaign) -> None:
        self.campaign = campaign
        self.seen: set[str] = set()
        self.artifacts: dict[str, Artifact] = {}

    def check(self, scenario: Scenario, raw: dict, *, artifact_json: bytes, sha: str, where: str) -> None:
        """Build and reset the plant of ``scenario`` (``raw``: its table) unless a run of its shape was built."""
        kind = raw.get("plant", {}).get("kind")
        if kind == "python" or kind not in PLANTS.names():
            return
        if sha not in self.artifacts:
            self.artifacts[sha] = from_dict(json.loads(artifact_json))
        artifact = self.artifacts[sha]
        shape = json.dumps([_blank_numbers(raw), artifact.signals], sort_keys=True)
        if shape in self.seen:
            return
        self.seen.add(shape)
        path = self.campaign.path or Path.cwd() / "campaign.toml"  # relative plant files: from the campaign's folder
        try:
            _dry_run(dataclasses.replace(scenario, path=path), artifact=artifact, kind=self.campaign.kind)
        except (GainlinkError, ValueError, TypeError) as exc:  # a built-in plant's complaint about its table
            raise CampaignError(f"campaign: {where}: {exc}") from None


def _dry_run(scenario: Scenario, *, artifact: Artifact, kind: str) -> None:
    """Build and reset the run's plant and plan the run on it, as the worker does before anything is built; for a
    HIL run the link's layout too."""
    law = law_of(artifact)
    law.refuse(f"campaign.{kind}", what=f"a {kind.upper()} campaign")
    if not scenario.sigma_rate_limit:
        artifact = law.without_rate_limit(artifact)
    plant = build_plant(scenario, artifact=artifact)
    try:
        plant.reset(initial=scenario.initial_state)
        plan_run(scenario, law=law, artifact=artifact, plant=plant)
    finally:
        plant.close()
    if kind == "hil":
        transport_from_config(scenario.transport, artifact=artifact)
