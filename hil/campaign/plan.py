"""From a campaign to its runs: grid points times draws, each a pure (artifact, scenario, seed) with an id.

Draw ``j`` (``0 <= j < runs``) takes its values and its run seed from ``default_rng([seed, j])``, the same
for every grid point: grid points are compared on the same plant draws and the same noise (common
random numbers), and raising ``runs`` keeps the earlier draws. A grid point whose axes touch the spec
designs its own artifact (designs are shared between points with the same spec). The run id is the
sha256 of what the run is a function of — kind, artifact sha256, scenario (FMUs by their sha256), seed
and gainlink's version — so a result file names exactly one run and a resumed campaign finds it.
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from gainlink.errors import GainlinkError, SpecError, did_you_mean
from gainlink.shipping.artifact import canonical_json, render
from gainlink.version import __version__

from ..loop.endpoints import refuse_link_faults
from ..loop.scenario import Scenario, parse_scenario
from .config import Axis, Campaign, CampaignError, path_steps
from .preflight import DryBuild, check_axis_values


@dataclass(frozen=True)
class RunPoint:
    """One run of a campaign: its inputs and where they came from.

    ``values`` maps each axis name to the value this run uses; ``grid_index`` and ``draw`` say which
    grid point and which draw it is. ``error`` is set when the run cannot even start (its grid point's
    design failed): it is recorded as failed with that reason, never submitted.
    """

    index: int
    id: str
    grid_index: int
    draw: int
    values: dict
    artifact_sha256: str | None
    scenario: dict
    seed: int
    error: str | None = None


@dataclass(frozen=True)
class CampaignPlan:
    """Every run (a :class:`PlannedRuns` from :func:`plan_campaign`: generated when read), the artifacts they use
    (sha256 -> canonical JSON bytes) and the FMUs (sha256 -> bytes)."""

    campaign: Campaign
    runs: Sequence[RunPoint]
    artifacts: dict = field(default_factory=dict)
    blobs: dict = field(default_factory=dict)


def set_path(tree: dict, path: str, value: Any, *, apply: str = "set", where: str = "") -> None:
    """Set ``path`` (dotted keys, ``[i]`` indices) in ``tree`` in place; ``scale``/``add`` need a number there."""
    steps = path_steps(path)
    node: Any = tree
    for i, step in enumerate(steps[:-1]):
        nxt = steps[i + 1]
        if isinstance(step, int):
            if not isinstance(node, list) or step >= len(node):
                raise CampaignError(f"campaign: {where}: {path}: no element [{step}] in the base")
            node = node[step]
            continue
        if not isinstance(node, dict):
            raise CampaignError(f"campaign: {where}: {path}: {step!r} is not inside a table")
        if step not in node:
            if isinstance(nxt, int):
                raise CampaignError(f"campaign: {where}: {path}: the base has no list {step!r} to index")
            node[step] = {}
        node = node[step]
    last = steps[-1]
    container_ok = (isinstance(node, list) and isinstance(last, int) and last < len(node)) or isinstance(node, dict)
    if not container_ok:
        raise CampaignError(f"campaign: {where}: {path}: cannot set it in the base")
    if apply != "set":
        if isinstance(node, dict) and last not in node:  # nothing to scale or add to: name what is there
            parent = path.rsplit(".", 1)[0] if "." in path else "the top level"
            has = ", ".join(map(str, node)) or "none"
            raise CampaignError(
                f"campaign: {where}: {path}: the base has no {last!r} to {apply}{did_you_mean(str(last), node)}; "
                f"give it a value in the campaign's scenario (the base's {parent}: {has})"
            )
        base = node[last]
        if isinstance(base, bool) or not isinstance(base, (int, float)):
            raise CampaignError(
                f'campaign: {where}: apply = "{apply}" needs a number at {path} in the base (found {base!r})'
            )
        value = base * value if apply == "scale" else base + value
    node[last] = value


def sample(axis: Axis, rng: np.random.Generator) -> Any:
    """One value of a draw axis (scipy.stats for the truncated normal and the log-uniform)."""
    p = axis.params
    dist = axis.distribution
    if dist == "normal":
        return float(rng.normal(p["mean"], p["std"]))
    if dist == "uniform":
        return float(rng.uniform(p["low"], p["high"]))
    if dist == "choice":
        return p["values"][int(rng.integers(len(p["values"])))]
    from scipy import stats

    if dist == "loguniform":
        return float(stats.loguniform(p["low"], p["high"]).rvs(random_state=rng))
    a, b = (p["low"] - p["mean"]) / p["std"], (p["high"] - p["mean"]) / p["std"]
    return float(stats.truncnorm(a, b, loc=p["mean"], scale=p["std"]).rvs(random_state=rng))


def draw_values(campaign: Campaign, j: int) -> tuple[int, dict]:
    """The run seed and the draw-axis values of draw ``j``."""
    rng = np.random.default_rng([campaign.seed, j])
    seed = int(rng.integers(2**31 - 1))  # first, so adding an axis keeps every run's noise
    return seed, {a.name: sample(a, rng) for a in campaign.draws}


def _apply_axis(axis: Axis, value: Any, *, spec: dict | None, scenario: dict, window: tuple[float, float]) -> None:
    where = f"axis {axis.name}"
    for target in axis.targets:
        if target == "faults.drop":
            if value > 0:
                scenario.setdefault("faults", []).append(
                    {"kind": "drop", "start": window[0], "stop": window[1], "probability": float(value)}
                )
        elif target == "faults.delay_steps":
            if value > 0:
                scenario.setdefault("faults", []).append(
                    {"kind": "delay", "start": window[0], "stop": window[1], "delay_steps": int(value)}
                )
        elif target.startswith("spec."):
            set_path(spec, target[len("spec.") :], copy.deepcopy(value), apply=axis.apply, where=where)
        else:
            set_path(scenario, target, copy.deepcopy(value), apply=axis.apply, where=where)


def run_id(*, kind: str, artifact_sha256: str | None, scenario: dict, seed: int) -> str:
    """The content address of a run (hex, 20 characters)."""
    body = {"kind": kind, "artifact": artifact_sha256, "scenario": scenario, "seed": seed, "gainlink": __version__}
    return hashlib.sha256(canonical_json(body).encode("ascii")).hexdigest()[:20]


def _design(spec: dict, *, source: str) -> bytes:
    from gainlink.laws import design
    from gainlink.spec import parse_spec

    sealed = design(parse_spec(spec, source=source)).artifact
    return render(sealed).encode("utf-8")


def _fmu_blob(scenario: dict, campaign: Campaign, blobs: dict, cache: dict) -> None:
    """An FMU plant travels as bytes: read it here, name it by sha256 (``path = "sha256:<hex>"``)."""
    plant = scenario.get("plant")
    if not isinstance(plant, dict) or plant.get("kind") != "fmu":
        return
    from ..plants.fmi import resolve_fmu

    key = (plant.get("fmu"), plant.get("path"))
    if key not in cache:
        path = resolve_fmu(fmu=plant.get("fmu"), path=plant.get("path"), base_dir=campaign.base_dir)
        data = Path(path).read_bytes()
        sha = hashlib.sha256(data).hexdigest()
        blobs[sha] = data
        cache[key] = sha
    plant.pop("fmu", None)
    plant["path"] = f"sha256:{cache[key]}"


def _check_scenario(campaign: Campaign, scenario: dict, where: str) -> Scenario:
    if "firmware" in scenario:
        raise CampaignError("campaign: scenario.firmware: a campaign builds the firmware on each worker")
    data = dict(scenario, artifact="gains.json")
    if campaign.kind == "sil":  # in process: no link, whatever the scenario's table says
        data["transport"] = {}
    try:
        parsed = parse_scenario(data)
        if campaign.kind == "sil":
            refuse_link_faults(parsed)
    except GainlinkError as exc:
        raise CampaignError(f"campaign: {where}: {exc}") from None
    return parsed


class PlannedRuns(Sequence):
    """A campaign's runs in plan order (grid point ``g``, draw ``j`` at index ``g * runs + j``), generated when asked,
    not held: ``runs[i]`` makes run ``i``, iterating makes them in order (the same ids, seeds and values whichever
    way). The designs, artifacts and FMUs they use were gathered when the campaign was planned."""

    def __init__(self, campaign: Campaign, planner: _Planner) -> None:
        self.campaign, self._planner = campaign, planner
        self._count = len(planner.points) * campaign.runs

    def __len__(self) -> int:
        return self._count

    def __getitem__(self, i: Any) -> Any:
        if isinstance(i, slice):
            return [self._planner.point(k) for k in range(*i.indices(self._count))]
        k = i + self._count if i < 0 else i
        if not 0 <= k < self._count:
            raise IndexError(i)
        return self._planner.point(k)

    def __iter__(self) -> Iterator[RunPoint]:
        for k in range(self._count):
            yield self._planner.point(k)


class _Planner:
    """Makes run ``k`` of a campaign (:meth:`point`), sharing the designs and FMUs between runs."""

    def __init__(self, campaign: Campaign) -> None:
        self.campaign = campaign
        self.artifacts: dict[str, bytes] = {}
        self.blobs: dict[str, bytes] = {}
        self.fmu_cache: dict = {}
        self.designs: dict[str, tuple[bytes, str] | str] = {}  # canonical spec -> (artifact, sha256), or the error
        path = campaign.artifact_path
        self.fixed = _with_sha(path.read_bytes()) if path is not None else None
        # Only spec.* axes change the spec: without one, every run shares the campaign's spec and its one design.
        self.spec_varies = any(a.design for a in (*campaign.grid, *campaign.draws))
        self.points = list(itertools.product(*(a.values for a in campaign.grid)))

    def point(self, k: int, *, dry: DryBuild | None = None) -> RunPoint:
        """Run ``k``; with ``dry``, its scenario parsed and its plant dry-built (:class:`.preflight.DryBuild`)."""
        c = self.campaign
        g, j = divmod(k, c.runs)
        seed, drawn = draw_values(c, j)
        values = {a.name: v for a, v in zip(c.grid, self.points[g])} | drawn
        spec = copy.deepcopy(c.spec) if self.spec_varies else c.spec
        scenario = copy.deepcopy(c.scenario)
        for axis in (*c.grid, *c.draws):
            _apply_axis(axis, values[axis.name], spec=spec, scenario=scenario, window=c.fault_window)
        where = f"run {k} ({', '.join(f'{n}={_short(v)}' for n, v in values.items()) or 'base'})"
        parsed = _check_scenario(c, scenario, where) if dry is not None else None
        key = canonical_json(spec) if self.spec_varies else ""
        got = self.fixed if self.fixed is not None else _artifact(c, spec, key, self.designs, where)
        sha, error = (got[1], None) if isinstance(got, tuple) else (None, got)
        if sha is not None:
            self.artifacts.setdefault(sha, got[0])
            if dry is not None:
                dry.check(parsed, scenario, artifact_json=got[0], sha=sha, where=where)
        _fmu_blob(scenario, c, self.blobs, self.fmu_cache)
        rid = run_id(kind=c.kind, artifact_sha256=sha, scenario=scenario, seed=seed)
        return RunPoint(
            index=k,
            id=rid,
            grid_index=g,
            draw=j,
            values=values,
            artifact_sha256=sha,
            scenario=scenario,
            seed=seed,
            error=error,
        )


def plan_campaign(campaign: Campaign) -> CampaignPlan:
    """Plan ``campaign``: make each run once, to check it and gather the designs and FMUs it uses, keeping none;
    its runs are returned as a :class:`PlannedRuns` (generated again when read).

    A mistake of the campaign file is refused here, before any run (:class:`CampaignError`, one line naming the
    key): a value of another kind than the scenario holds (:func:`.preflight.check_axis_values`), a spec the spec
    parser refuses at any grid point, a scenario the scenario parser refuses at any run, a plant that cannot be built
    for one run of each shape (:class:`.preflight.DryBuild`). A design that fails at a grid point (``DesignError``)
    is that point's result.
    """
    check_axis_values(campaign)
    dry = DryBuild(campaign)
    planner = _Planner(campaign)
    for k in range(len(planner.points) * campaign.runs):  # each made, checked and dropped
        planner.point(k, dry=dry)
    return CampaignPlan(
        campaign=campaign, runs=PlannedRuns(campaign, planner), artifacts=planner.artifacts, blobs=planner.blobs
    )


def _with_sha(art: bytes) -> tuple[bytes, str]:
    return art, json.loads(art)["sha256"]


def _artifact(campaign: Campaign, spec: dict, key: str, designs: dict, where: str) -> tuple[bytes, str] | str:
    """The artifact of ``spec`` (canonical ``key``) and its sha256, designed once per key; or the design's error."""
    if key not in designs:
        try:
            designs[key] = _with_sha(_design(spec, source=f"{campaign.spec_path} ({where})"))
        except SpecError as exc:  # the campaign's spec or its spec.* axes are wrong, at every run alike
            raise CampaignError(f"campaign: {where}: {exc}") from None
        except GainlinkError as exc:
            designs[key] = f"design failed: {exc}"
    return designs[key]


def _short(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    text = json.dumps(v) if not isinstance(v, str) else v
    return text if len(text) <= 24 else text[:21] + "..."


def describe_axes(campaign: Campaign) -> list[dict]:
    """The axes as JSON-able dicts (for campaign.json)."""
    out = []
    for a in (*campaign.grid, *campaign.draws):
        d: dict[str, Any] = {"name": a.name, "targets": list(a.targets), "apply": a.apply}
        if a.distribution is None:
            d["grid"] = list(a.values)
        else:
            d["distribution"] = a.distribution
            d.update(a.params)
        out.append(d)
    return out


def grid_size(campaign: Campaign) -> int:
    """How many grid points the campaign has."""
    return math.prod(len(a.values) for a in campaign.grid)
