"""From a campaign to its runs: grid points times draws, each a pure (artifact, scenario, seed) with an id.

Draw ``j`` (``0 <= j < runs``) takes its run seed and its values from its chunk of :data:`DRAW_CHUNK` draws, all
drawn from ``default_rng([seed, j // DRAW_CHUNK])`` (the chunk's seeds first, then each axis's values), the same for
every grid point: grid points are compared on the same plant draws and the same noise (common random numbers), and
raising ``runs`` keeps the earlier draws. A grid point whose axes touch the spec
designs its own artifact (designs are shared between points with the same spec). The run id is the
sha256 of what the run is a function of — kind, artifact sha256, scenario (FMUs by their sha256), seed
and gainlink's version — so a result file names exactly one run and a resumed campaign finds it.

Planning draws every draw once into arrays (:func:`draw_table`: a seed and a value per axis, 8 bytes each), designs
once per grid point (per run only when a draw axis changes the spec) and keeps each run's id (20 bytes) and whether
its design failed (1 byte); a run's scenario is made again when it is read. The ids come without making the runs where
the draw axes set, scale or shift scenario values: each grid point's id body is written once as canonical JSON with a
slot for each drawn value and the seed, and a run's id hashes that text with its values' JSON in the slots
(:class:`_IdTemplate`; making the run is its oracle and its fallback). Not every run's scenario goes through
the scenario parser: each grid point's runs at the draws that hold the smallest and the largest value of each numeric
draw axis, and the first draw of each combination of choice values (:meth:`_Planner.checked`). A drawn number reaches
its path unchanged, scaled or shifted (a monotone map), and the scenario parser's checks of one number are ranges
(finite, positive, ``>= 0``, within ``[0, 1]``): a value between two accepted ones is accepted, so a draw that can be
refused anywhere is refused at an extreme, in one line, before anything runs. A check that ties two drawn numbers
together (one must stay below another) is not covered by the extremes: such a run is refused on its worker and
recorded as that run's error, costing no other run its result.
"""

from __future__ import annotations

import bisect
import copy
import hashlib
import itertools
import json
import math
import pickle
import re
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from gainlink.errors import GainlinkError, SpecError, did_you_mean
from gainlink.shipping.artifact import canonical_json
from gainlink.version import __version__

from ..loop.endpoints import refuse_link_faults
from ..loop.scenario import Scenario, parse_scenario
from .config import Axis, Campaign, CampaignError, path_steps, value_at
from .designs import designed
from .jsontext import Shared
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
        value = _leaf_value(value, apply, base)
    node[last] = value


def _leaf_value(value: Any, apply: str, base: Any) -> Any:
    """What :func:`set_path` leaves at a target given ``value``: the value, or ``base`` scaled or shifted by it
    (Python's own arithmetic)."""
    if apply == "set":
        return value
    return base * value if apply == "scale" else base + value


#: Draws are made this many at a time, each chunk from its own generator (:func:`draw_table`).
DRAW_CHUNK = 1024


def _sampler(axis: Axis) -> Callable[[np.random.Generator, int], np.ndarray]:
    """An axis's numbers from a generator, ``size`` of them at once: the values, or for a choice axis the indices of
    the values. Made once per axis: scipy's frozen distribution draws from the generator it is given."""
    p = axis.params
    dist = axis.distribution
    if dist == "normal":
        return lambda rng, size: rng.normal(p["mean"], p["std"], size)
    if dist == "uniform":
        return lambda rng, size: rng.uniform(p["low"], p["high"], size)
    if dist == "choice":
        return lambda rng, size: rng.integers(len(p["values"]), size=size)
    from scipy import stats

    if dist == "loguniform":
        frozen = stats.loguniform(p["low"], p["high"])
    else:
        a, b = (p["low"] - p["mean"]) / p["std"], (p["high"] - p["mean"]) / p["std"]
        frozen = stats.truncnorm(a, b, loc=p["mean"], scale=p["std"])
    return lambda rng, size: np.asarray(frozen.rvs(size=size, random_state=rng))


def draw_chunk(campaign: Campaign, c: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Draws ``c * DRAW_CHUNK`` to ``(c + 1) * DRAW_CHUNK - 1``, all of them whatever the campaign's ``runs``: from
    ``default_rng([seed, c])`` the chunk's run seeds first (so adding an axis keeps every run's noise), then each
    axis's values in the campaign's order, a chunk's worth each. ``seeds`` int64 and, by axis name, float64 values
    (a choice axis: int64 indices into its values)."""
    rng = np.random.default_rng([campaign.seed, c])
    seeds = rng.integers(2**31 - 1, size=DRAW_CHUNK).astype(np.int64)
    # one axis after the other from the one generator: the order of this comprehension is the draws' definition
    return seeds, {a.name: _sampler(a)(rng, DRAW_CHUNK).astype(np.int64 if a.distribution == "choice" else np.float64)
                   for a in campaign.draws}  # fmt: skip


def draw_values(campaign: Campaign, j: int) -> tuple[int, dict]:
    """The run seed and the draw-axis values of draw ``j`` (its chunk's, :func:`draw_chunk`)."""
    seeds, cols = draw_chunk(campaign, j // DRAW_CHUNK)
    i = j % DRAW_CHUNK
    return int(seeds[i]), {a.name: _drawn_value(a, cols[a.name][i]) for a in campaign.draws}


def draw_table(campaign: Campaign) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Every draw's run seed and axis numbers, as :func:`draw_values` gives them: ``seeds`` (runs,) int64 and, by
    axis name, (runs,) float64 values (a choice axis: int64 indices into its values). Made once per plan, a chunk of
    :data:`DRAW_CHUNK` draws at a time (a generator a chunk, not a draw: ~0.1 µs a draw against ~10): a draw is the
    same at every grid point, and raising ``runs`` keeps the earlier draws."""
    chunks = [draw_chunk(campaign, c) for c in range(-(-campaign.runs // DRAW_CHUNK))]  # runs >= 1: one at least
    seeds = np.concatenate([s for s, _ in chunks])[: campaign.runs]
    return seeds, {a.name: np.concatenate([col[a.name] for _, col in chunks])[: campaign.runs] for a in campaign.draws}


def _apply_axis(
    axis: Axis, value: Any, *, spec: dict | None, scenario: dict | None, window: tuple[float, float]
) -> None:
    """Set ``value`` at the axis's targets: those in the spec when ``spec`` is given, the others when ``scenario``
    is."""
    where = f"axis {axis.name}"
    for target in axis.targets:
        if (spec if target.startswith("spec.") else scenario) is None:
            continue
        value = value if isinstance(value, (int, float, str)) else copy.deepcopy(value)
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
            set_path(spec, target[len("spec.") :], value, apply=axis.apply, where=where)
        else:
            set_path(scenario, target, value, apply=axis.apply, where=where)


def run_id(*, kind: str, artifact_sha256: str | None, scenario: dict, seed: int) -> str:
    """The content address of a run (hex, 20 characters)."""
    body = {"kind": kind, "artifact": artifact_sha256, "scenario": scenario, "seed": seed, "gainlink": __version__}
    return hashlib.sha256(canonical_json(body).encode("ascii")).hexdigest()[:20]


def _fmu_blob(scenario: dict, campaign: Campaign, blobs: dict, cache: dict) -> None:
    """An FMU plant travels as bytes: read it here, name it by sha256 (``path = "sha256:<hex>"``)."""
    sha = _fmu_sha(scenario, campaign, blobs, cache)
    if sha is not None:
        _name_fmu(scenario, sha)


def _fmu_sha(scenario: dict, campaign: Campaign, blobs: dict, cache: dict) -> str | None:
    """The sha256 of the scenario's FMU plant (its bytes read once into ``blobs``), None for another plant."""
    plant = scenario.get("plant")
    if not isinstance(plant, dict) or plant.get("kind") != "fmu":
        return None
    from ..plants.fmi import resolve_fmu

    key = (plant.get("fmu"), plant.get("path"))
    if key not in cache:
        path = resolve_fmu(fmu=plant.get("fmu"), path=plant.get("path"), base_dir=campaign.base_dir)
        data = Path(path).read_bytes()
        sha = hashlib.sha256(data).hexdigest()
        blobs[sha] = data
        cache[key] = sha
    return cache[key]


def _name_fmu(scenario: dict, sha: str) -> None:
    """The scenario's FMU plant named by its sha256 (what travels), in place of its file."""
    plant = scenario["plant"]
    plant.pop("fmu", None)
    plant["path"] = f"sha256:{sha}"


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
    way). The designs, artifacts and FMUs they use were gathered when the campaign was planned, with each run's id
    (:attr:`ids`) and whether its design failed (:attr:`failed`)."""

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

    @property
    def ids(self) -> np.ndarray:
        """Every run's id in plan order, as ASCII bytes (``(len,)``, ``S20``)."""
        return self._planner.ids

    @property
    def failed(self) -> np.ndarray:
        """Every run's flag, in plan order: its grid point's design failed (it is recorded, never submitted)."""
        return self._planner.failed

    def inputs(self, indices: np.ndarray) -> list[tuple[str | None, dict, int]]:
        """The runs at plan indices ``indices`` enumerated: ``(artifact sha256, scenario, seed)``, each what ``runs[k]``
        holds, made without the id (:attr:`ids` holds it)."""
        return [self._planner.inputs(k) for k in np.asarray(indices).tolist()]

    def task(self, indices: np.ndarray) -> DescribedRuns | list[tuple[str | None, dict, int]]:
        """The runs at plan indices ``indices`` (in plan order) as their task carries them: described
        (:class:`DescribedRuns`: each grid point's scenario once, each run's draw-table row and seed) when the plan can
        describe its runs so (:attr:`describable`), else enumerated (:meth:`inputs`). Either gives, run for run, the
        ``(artifact sha256, scenario, seed)`` that ``runs[k]`` holds."""
        if self.describable:
            return self._planner.described(np.asarray(indices, np.int64))
        return self.inputs(indices)

    @property
    def describable(self) -> bool:
        """Whether a task carries these runs described (:meth:`task`): each grid point's runs share one artifact and
        one FMU, so a run is its grid point's scenario with its draws. Not with a ``spec.*`` draw axis (each run its
        own design) or a draw axis that sets the plant table or its FMU (each run its own FMU)."""
        return self._planner.describable

    def heads(self) -> Iterator[RunHead]:
        """The runs in plan order, what a report row names of each (:class:`RunHead`), without making a scenario."""
        for k in range(self._count):
            yield self.head(k)

    def head(self, k: int) -> RunHead:
        """What a report row names of run ``k`` (:class:`RunHead`), without making its scenario (but with a
        ``spec.*`` draw axis, whose design is the run's own)."""
        planner = self._planner
        if planner.spec_per_run:
            p = planner.point(k)
            return RunHead(p.index, p.id, p.grid_index, p.draw, p.values, p.artifact_sha256, p.seed)
        g, j = divmod(k, self.campaign.runs)
        got = planner.fixed if planner.fixed is not None else planner.by_point[g]
        sha = got[1] if isinstance(got, tuple) else None
        return RunHead(k, planner.ids[k].decode("ascii"), g, j, planner.values(g, j), sha, int(planner.seeds[j]))

    def head_parts(self) -> HeadParts | None:
        """What every run's head (:meth:`head`) is made of: each grid point's values and artifact sha256, each draw's
        values and seed (run ``k`` is grid point ``k // runs``, draw ``k % runs``), for rows made many at a time;
        ``None`` under a ``spec.*`` draw axis (each run's design, and so its sha256, is its own)."""
        planner, c = self._planner, self.campaign
        if planner.spec_per_run:
            return None
        shas = []
        for g in range(len(planner.points)):
            got = planner.fixed if planner.fixed is not None else planner.by_point[g]
            shas.append(got[1] if isinstance(got, tuple) else None)
        grid = [{a.name: v for a, v in zip(c.grid, p)} for p in planner.points]
        choices = {a.name: list(a.params["values"]) for a in c.draws if a.distribution == "choice"}
        drawn = {a.name: planner.drawn[a.name] for a in c.draws}
        return HeadParts(grid=grid, shas=shas, drawn=drawn, choices=choices, seeds=planner.seeds, runs=c.runs)

    def columns(self) -> PlanColumns:
        """Every run's grid point and axis values in plan order as arrays (:class:`PlanColumns`), from the grid and
        the draw table, without making a run."""
        planner, c = self._planner, self.campaign
        points, runs = planner.points, c.runs
        numbers, numeric = {}, {}
        for i, a in enumerate(c.grid):
            x, ok = _numbers([p[i] for p in points])
            numbers[a.name], numeric[a.name] = np.repeat(x, runs), np.repeat(ok, runs)
        for a in c.draws:
            drawn = planner.drawn[a.name]
            if a.distribution == "choice":
                x, ok = _numbers(a.params["values"])
                pick = np.asarray(drawn, int)
                x, ok = x[pick], ok[pick]
            else:
                x, ok = np.asarray(drawn, float), np.ones(len(drawn), bool)
            numbers[a.name], numeric[a.name] = np.tile(x, len(points)), np.tile(ok, len(points))
        grid_values = {g: {a.name: v for a, v in zip(c.grid, p)} for g, p in enumerate(points)}
        return PlanColumns(np.repeat(np.arange(len(points)), runs), numbers, numeric, grid_values)


@dataclass(frozen=True)
class HeadParts:
    """A generated plan's runs' heads by part (:meth:`PlannedRuns.head_parts`): run ``k`` is grid point
    ``g, j = divmod(k, runs)``, its values ``grid[g]`` and draw ``j``'s of ``drawn`` (a choice axis's
    ``choices[name][drawn[name][j]]``, another's the float), its artifact ``shas[g]``, its seed ``seeds[j]``."""

    grid: list[dict]
    shas: list[str | None]
    drawn: dict[str, np.ndarray]  # per draw axis (in the campaign's order), each draw's number (a choice's: its index)
    choices: dict[str, list]  # a choice axis's values
    seeds: np.ndarray
    runs: int


@dataclass(frozen=True)
class PlanColumns:
    """A plan's runs in plan order as arrays: each run's grid point (``grid``), each axis's value as a float
    (``numbers``, NaN where it is not a number) and whether it is one (``numeric``: an int or a float, not a bool),
    and each grid point's values (``grid_values``, in the order first met)."""

    grid: np.ndarray
    numbers: dict[str, np.ndarray]
    numeric: dict[str, np.ndarray]
    grid_values: dict[int, dict]


def _numbers(values: Sequence) -> tuple[np.ndarray, np.ndarray]:
    """``values`` as floats (NaN where one is not a number: a string, a bool, a table) and whether each is one."""
    ok = np.array([isinstance(v, (int, float)) and not isinstance(v, bool) for v in values], bool)
    return np.array([float(v) if k else math.nan for v, k in zip(values, ok)], float), ok


def plan_columns(plan: CampaignPlan) -> PlanColumns:
    """:meth:`PlannedRuns.columns` of ``plan``; of a plan of points, gathered from the points."""
    if isinstance(plan.runs, PlannedRuns):
        return plan.runs.columns()
    names = [a.name for a in (*plan.campaign.grid, *plan.campaign.draws)]
    numbers, numeric = {}, {}
    for name in names:
        numbers[name], numeric[name] = _numbers([p.values[name] for p in plan.runs])
    grid_values: dict[int, dict] = {}
    for p in plan.runs:
        grid_values.setdefault(p.grid_index, {a.name: p.values[a.name] for a in plan.campaign.grid})
    return PlanColumns(np.array([p.grid_index for p in plan.runs], int), numbers, numeric, grid_values)


@dataclass(frozen=True)
class RunHead:
    """What a report row names of a run (a :class:`RunPoint` without its scenario)."""

    index: int
    id: str
    grid_index: int
    draw: int
    values: dict
    artifact_sha256: str | None
    seed: int


def run_heads(plan: CampaignPlan) -> Iterable[RunHead | RunPoint]:
    """The runs of ``plan`` in plan order as their report rows name them: a generated plan's without making any
    scenario (:meth:`PlannedRuns.heads`), a plan of points the points themselves."""
    return plan.runs.heads() if isinstance(plan.runs, PlannedRuns) else plan.runs


@dataclass(frozen=True)
class GridPart:
    """Runs ``start:stop`` of a :class:`DescribedRuns`, all of one grid point: its scenario (the campaign's with the
    grid axes applied, pickled), its artifact's sha256 and its FMU's (None when its plant is not an FMU)."""

    start: int
    stop: int
    sha: str | None
    scenario: bytes
    fmu: str | None


@dataclass(frozen=True, eq=False)
class DescribedRuns(Sequence):
    """A task's runs described, not enumerated (:meth:`PlannedRuns.task`): each grid point's scenario once
    (:class:`GridPart`) and, per run, its draw's row of the draw table (``drawn``: each draw axis's number, a choice
    axis's index) and its seed, a few bytes a run. ``runs[i]`` makes run ``i`` as the plan's ``runs[k]`` holds it,
    ``(artifact sha256, scenario, seed)``: its grid point's scenario with its draws applied (:meth:`apply_draws`, the
    plan's own :func:`_apply_axis` in the campaign's order, after the grid axes as :meth:`_Planner._made` applies
    them) and an FMU named by its sha256 after them, as :func:`_fmu_blob` names it."""

    axes: tuple[Axis, ...]  # the campaign's draw axes
    window: tuple[float, float]  # the campaign's fault window (a faults.* axis's)
    parts: tuple[GridPart, ...]
    seeds: np.ndarray
    drawn: tuple[np.ndarray, ...]  # per draw axis, each run's number
    leaves: bool = False  # each draw axis sets, scales or shifts a scenario value no other axis's target holds
    # each part's _slots once made (by part_runs, then scenario_trees): filled where the runs are made, on the worker
    made_slots: dict = field(default_factory=dict, init=False, compare=False, repr=False)

    def __len__(self) -> int:
        return len(self.seeds)

    def __getstate__(self) -> dict:
        # the task travels without the slots made from it (each run's value a target): the worker makes its own
        return {k: v for k, v in self.__dict__.items() if k != "made_slots"}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state, made_slots={})

    def __getitem__(self, i: Any) -> Any:
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(len(self)))]
        k = i + len(self) if i < 0 else i
        part = next((p for p in self.parts if p.start <= k < p.stop), None)
        if part is None:
            raise IndexError(i)
        return self.made(part, k)

    def __iter__(self) -> Iterator[tuple[str | None, dict, int]]:
        for part in self.parts:
            yield from self.part_runs(part)

    def part_runs(self, part: GridPart) -> Iterator[tuple[str | None, dict, int]]:
        """The runs of ``part`` in order, as :meth:`made` makes them: where each draw axis sets, scales or shifts a
        scenario value no other axis's target holds (:attr:`leaves`, the id template's condition), its scenario with
        the targets in place (:meth:`_slots`) and each run's values put there, what :meth:`made` leaves there; the
        tables and lists on the targets' paths are each run's own, the rest of the scenario is shared by the part's
        runs (read, never changed: a run's table is parsed from a JSON copy and stored as JSON); else each run made."""
        slots = self._slots(part) if self.leaves else None
        if slots is None:
            for i in range(part.start, part.stop):
                yield self.made(part, i)
            return
        base, paths, leaves = slots
        if part.fmu is not None:  # named after the draws in the run's own plant table
            paths = sorted(dict.fromkeys([("plant",), *paths]), key=len)
        copies = [(path, path[:-1], path[-1]) for path in paths]
        puts = [(steps[:-1], steps[-1], column) for steps, column in leaves]
        for i, seed in enumerate(self.seeds[part.start : part.stop].tolist()):
            own = {(): dict(base)}
            for path, up, key in copies:  # each container on a target's path copied once, its parent's before it
                node = own[up][key]
                own[path] = own[up][key] = list(node) if isinstance(node, list) else dict(node)
            for up, key, column in puts:
                value = column[i]
                own[up][key] = value if isinstance(value, (int, float, str)) else copy.deepcopy(value)
            scenario = own[()]
            if part.fmu is not None:
                _name_fmu(scenario, part.fmu)
            yield part.sha, scenario, seed

    def scenario_trees(self) -> list[tuple[int, int, dict]] | None:
        """The runs' scenarios as column trees (:func:`.jsontext.object_texts`: their JSON texts made without walking
        each run's tables), a grid part at a time, ``(start, stop, tree)``: the part's scenario with every value its
        runs share a :class:`~.jsontext.Shared` and each draw target's value the column of what :meth:`part_runs`
        puts there; None where :meth:`part_runs` makes each run (not :attr:`leaves`, a value it cannot put), names an
        FMU after its draws, or a target's path runs through a list."""
        if not self.leaves:
            return None
        trees = []
        for part in self.parts:
            slots = self._slots(part) if part.fmu is None else None
            tree = None if slots is None else _column_tree(slots[0], dict(slots[2]), set(slots[1]), ())
            if tree is None:
                return None
            trees.append((part.start, part.stop, tree))
        return trees

    def target_columns(self, part: GridPart) -> tuple[dict, list[tuple[tuple, list]]] | None:
        """``part``'s scenario with its draw targets in place (their values None; read it, never change it) and, per
        target, its path's steps and each run's value there, what :meth:`part_runs` puts there; None where
        :meth:`part_runs` makes each run (:meth:`_slots`)."""
        slots = self._slots(part) if self.leaves else None
        return None if slots is None else (slots[0], slots[2])

    def _slots(self, part: GridPart) -> tuple[dict, list[tuple], list[tuple[tuple, list]]] | None:
        """``part``'s scenario with every draw target in place (its tables made and its key set, in the order
        :meth:`apply_draws` makes them), the paths of the containers on the targets' paths (each after its parent's)
        and, per target, its path and each run's value there (:func:`_leaf_value`: the drawn value, or the scenario's
        number scaled or shifted by it); None where a value is not one to put so (a scale or shift of a non-number, a
        path the scenario refuses: :meth:`made` says why)."""
        if part.start not in self.made_slots:
            self.made_slots[part.start] = self._made_slots(part)
        return self.made_slots[part.start]

    def _made_slots(self, part: GridPart) -> tuple[dict, list[tuple], list[tuple[tuple, list]]] | None:
        """:meth:`_slots` made."""
        scenario, leaves = pickle.loads(part.scenario), []
        try:
            for axis, col in zip(self.axes, self.drawn):
                values = [_drawn_value(axis, x) for x in col[part.start : part.stop].tolist()]
                for target in axis.targets:
                    base = value_at(scenario, target)
                    if axis.apply != "set" and not (_is_number(base) and all(_is_number(v) for v in values)):
                        return None
                    set_path(scenario, target, None)
                    leaves.append((path_steps(target), [_leaf_value(v, axis.apply, base) for v in values]))
        except CampaignError:
            return None
        paths = list(dict.fromkeys(steps[:k] for steps, _ in leaves for k in range(1, len(steps))))
        return scenario, sorted(paths, key=len), leaves

    def made(self, part: GridPart, i: int) -> tuple[str | None, dict, int]:
        """Run ``i`` (of ``part``): its artifact sha256, its scenario and its seed."""
        scenario = pickle.loads(part.scenario)
        self.apply_draws(i, scenario)
        if part.fmu is not None:
            _name_fmu(scenario, part.fmu)
        return part.sha, scenario, int(self.seeds[i])

    def made_runs(self) -> MadeRuns:
        """The runs, each made once when first asked for (:class:`MadeRuns`), with this description (what a worker
        steps and records)."""
        return MadeRuns(self)

    def apply_draws(self, i: int, tree: dict) -> None:
        """Run ``i``'s drawn values set, scaled or shifted at their targets in ``tree`` (its grid point's scenario, or
        the part of it the targets lie in), in place."""
        for axis, col in zip(self.axes, self.drawn):
            _apply_axis(axis, _drawn_value(axis, col[i]), spec=None, scenario=tree, window=self.window)

    def uses(self) -> tuple[set[str], set[str]]:
        """The artifacts and the FMUs (each by sha256) the runs use."""
        return {p.sha for p in self.parts if p.sha}, {p.fmu for p in self.parts if p.fmu}


def _column_tree(node: dict, columns: dict[tuple, list], paths: set[tuple], at: tuple) -> dict | None:
    """The column tree of table ``node`` (at steps ``at``): a target's value its column (``columns`` by path), a table
    on a target's path (``paths``) its own tree, anything else :class:`~.jsontext.Shared`; None for a list on a
    target's path."""
    tree: dict = {}
    for key, value in node.items():
        steps = (*at, key)
        if steps in columns:
            tree[key] = columns[steps]
        elif steps not in paths:
            tree[key] = Shared(value)
        elif isinstance(value, dict) and (sub := _column_tree(value, columns, paths, steps)) is not None:
            tree[key] = sub
        else:
            return None
    return tree


class MadeRuns(Sequence):
    """A described task's runs, each ``(artifact sha256, scenario, seed)`` as :meth:`DescribedRuns.made_runs` gives
    them, made when asked for: ``runs[i]`` makes the runs of run ``i``'s grid part at once (:meth:`DescribedRuns.
    part_runs`), :meth:`one` run ``i`` alone. A worker whose block takes a part's drawn values from its columns
    (:meth:`DescribedRuns.target_columns`) makes only the part's first run (measured: making every run's scenario
    was ~2.7 us a run of a 2,500-run task's ~27 outside its runs). ``described``: the description they are made
    from (their grid points and draw axes)."""

    def __init__(self, described: DescribedRuns) -> None:
        self.described = described
        self._starts = [part.start for part in described.parts]
        self._parts: dict[int, list] = {}  # a part's runs, by its start, once one of them was asked for

    def __len__(self) -> int:
        return len(self.described)

    def __getitem__(self, i: Any) -> Any:
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(len(self)))]
        part = self._part(i)
        if part.start not in self._parts:
            self._parts[part.start] = list(self.described.part_runs(part))
        return self._parts[part.start][i - part.start]

    def one(self, i: int) -> tuple[str | None, dict, int]:
        """Run ``i`` (not negative) made alone, its part's other runs not made (a run of a part already made: as
        ``runs[i]``)."""
        part = self._part(i)
        made = self._parts.get(part.start)
        return made[i - part.start] if made is not None else self.described.made(part, i)

    def columns(self) -> tuple[list, list]:
        """Each run's artifact sha256 and seed, in order, without making a scenario."""
        shas = [part.sha for part in self.described.parts for _ in range(part.start, part.stop)]
        return shas, self.described.seeds.tolist()

    def _part(self, i: int) -> GridPart:
        if not 0 <= i < len(self):
            raise IndexError(i)
        return self.described.parts[bisect.bisect_right(self._starts, i) - 1]


def task_uses(runs: DescribedRuns | Sequence[tuple[str | None, dict, int]]) -> tuple[set[str], set[str]]:
    """The artifacts and the FMUs (each by sha256) a task's runs (:meth:`PlannedRuns.task`) use."""
    if isinstance(runs, DescribedRuns):
        return runs.uses()
    fmus = set()
    for _, scenario, _ in runs:
        path = str((scenario.get("plant") or {}).get("path", ""))
        if path.startswith("sha256:"):
            fmus.add(path.removeprefix("sha256:"))
    return {sha for sha, _, _ in runs if sha}, fmus


def _drawn_value(axis: Axis, x: Any) -> Any:
    """A draw axis's value from its number in the draw table (a float, or a choice's value at the index)."""
    return axis.params["values"][int(x)] if axis.distribution == "choice" else float(x)


class _Where:
    """A run's name in a refusal (``run 12 (M_factor=1.1, ...)``), made only when a refusal prints it."""

    def __init__(self, k: int, values: dict) -> None:
        self.k, self.values = k, values

    def __str__(self) -> str:
        return f"run {self.k} ({', '.join(f'{n}={_short(v)}' for n, v in self.values.items()) or 'base'})"


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
        # Only spec.* axes change the spec: without one, every run shares the campaign's spec and its one design;
        # without a spec.* draw axis, each grid point's runs share theirs.
        self.spec_varies = any(a.design for a in (*campaign.grid, *campaign.draws))
        self.spec_per_run = any(a.design for a in campaign.draws)
        self.points = list(itertools.product(*(a.values for a in campaign.grid)))
        self.by_point: dict[int, tuple[bytes, str] | str] = {}  # grid point -> its design (no spec.* draw axis)
        self.seeds, self.drawn = draw_table(campaign)
        # A run's scenario and spec are the base's loaded again (a deep copy, 10x cheaper than copy.deepcopy).
        self._scenario, self._spec = pickle.dumps(campaign.scenario), pickle.dumps(campaign.spec)
        size = len(self.points) * campaign.runs
        self.ids, self.failed = np.zeros(size, "S20"), np.zeros(size, bool)

    def values(self, g: int, j: int) -> dict:
        """The axis values of grid point ``g``, draw ``j``."""
        c = self.campaign
        out = {a.name: v for a, v in zip(c.grid, self.points[g])}
        for a in c.draws:
            out[a.name] = _drawn_value(a, self.drawn[a.name][j])
        return out

    @property
    def describable(self) -> bool:
        """See :attr:`PlannedRuns.describable`."""
        files = [path_steps(f) for f in _PLANT_FILE]
        targets = [path_steps(t) for a in self.campaign.draws for t in a.targets]
        return not self.spec_per_run and not any(f[: len(t)] == t for t in targets for f in files)

    def described(self, indices: np.ndarray) -> DescribedRuns:
        """The runs at plan indices ``indices`` (in plan order, none whose design failed) as a
        :class:`DescribedRuns`: a :class:`GridPart` for each stretch of one grid point's runs (its scenario with the
        grid axes applied, as :meth:`_made` applies them first, its artifact and its FMU), the draw table's rows and
        seeds of the runs' draws."""
        c = self.campaign
        g, j = np.divmod(indices, c.runs)
        cuts = (np.flatnonzero(np.diff(g)) + 1).tolist()
        parts = []
        for start, stop in zip([0, *cuts], [*cuts, len(indices)]) if len(indices) else ():
            point = int(g[start])
            values = self.values(point, 0)
            scenario = pickle.loads(self._scenario)
            for axis in c.grid:
                _apply_axis(axis, values[axis.name], spec=None, scenario=scenario, window=c.fault_window)
            got = self._design(point, values, None, _Where(point * c.runs, values))
            fmu = _fmu_sha(scenario, c, self.blobs, self.fmu_cache)
            scenario_bytes = pickle.dumps(scenario, protocol=pickle.HIGHEST_PROTOCOL)
            parts.append(GridPart(start, stop, got[1] if isinstance(got, tuple) else None, scenario_bytes, fmu))
        drawn = tuple(self.drawn[a.name][j] for a in c.draws)
        return DescribedRuns(tuple(c.draws), c.fault_window, tuple(parts), self.seeds[j], drawn, leaves=_templated(c))

    def point(self, k: int, *, dry: DryBuild | None = None) -> RunPoint:
        """Run ``k``; with ``dry``, its scenario parsed and its plant dry-built (:class:`.preflight.DryBuild`)."""
        values, scenario, sha, error, seed = self._made(k, dry=dry)
        g, j = divmod(k, self.campaign.runs)
        rid = run_id(kind=self.campaign.kind, artifact_sha256=sha, scenario=scenario, seed=seed)
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

    def inputs(self, k: int) -> tuple[str | None, dict, int]:
        """Run ``k``'s inputs as its task carries them (artifact sha256, scenario, seed): :meth:`point` without the
        run's id, whose canonical JSON and hash are two thirds of making a run (the plan holds the ids)."""
        _, scenario, sha, _, seed = self._made(k)
        return sha, scenario, seed

    def _made(self, k: int, *, dry: DryBuild | None = None) -> tuple[dict, dict, str | None, str | None, int]:
        """Run ``k``'s axis values, scenario, artifact sha256, its design's error and its seed."""
        c = self.campaign
        g, j = divmod(k, c.runs)
        values = self.values(g, j)
        where = _Where(k, values)
        scenario = pickle.loads(self._scenario)
        spec = pickle.loads(self._spec) if self.spec_per_run else None
        for axis in (*c.grid, *c.draws):
            _apply_axis(axis, values[axis.name], spec=spec, scenario=scenario, window=c.fault_window)
        parsed = _check_scenario(c, scenario, str(where)) if dry is not None else None
        got = self._design(g, values, spec, where)
        sha, error = (got[1], None) if isinstance(got, tuple) else (None, got)
        if sha is not None:
            self.artifacts.setdefault(sha, got[0])
            if dry is not None:
                dry.check(parsed, scenario, artifact_json=got[0], sha=sha, where=str(where))
        _fmu_blob(scenario, c, self.blobs, self.fmu_cache)
        return values, scenario, sha, error, int(self.seeds[j])

    def _design(self, g: int, values: dict, spec: dict | None, where: _Where) -> tuple[bytes, str] | str:
        """The run's artifact and its sha256 (or its design's error): the campaign's, its grid point's (designed with
        the grid values), or with a spec.* draw axis its own (``spec``, every axis applied)."""
        c = self.campaign
        if self.fixed is not None:
            return self.fixed
        if spec is None:
            if g not in self.by_point:
                spec = pickle.loads(self._spec)
                for axis in c.grid:
                    _apply_axis(axis, values[axis.name], spec=spec, scenario=None, window=c.fault_window)
                key = canonical_json(spec) if self.spec_varies else ""
                self.by_point[g] = _artifact(c, spec, key, self.designs, str(where))
            return self.by_point[g]
        return _artifact(c, spec, canonical_json(spec), self.designs, str(where))

    def checked(self) -> list[int]:
        """The runs whose scenarios planning parses (see the module docstring): at each grid point, draw 0, the draws
        holding each numeric draw axis's smallest and largest value, and the first draw of each combination of
        choice values."""
        c = self.campaign
        draws = {0}
        numeric = [self.drawn[a.name] for a in c.draws if a.distribution != "choice"]
        for col in numeric:
            draws.update((int(np.argmin(col)), int(np.argmax(col))))
        choices = [self.drawn[a.name] for a in c.draws if a.distribution == "choice"]
        if choices:
            _, first = np.unique(np.stack(choices, axis=1), axis=0, return_index=True)
            draws.update(int(j) for j in first)
        return [g * c.runs + j for g in range(len(self.points)) for j in sorted(draws)]

    def index(self) -> None:
        """Every run's id and whether its design failed: by its grid point's :class:`_IdTemplate` where the axes allow
        one (:func:`_templated`), else by making the run (:meth:`point`, also the template's fallback for a run whose
        value it cannot write)."""
        c = self.campaign
        drawn = [self._drawn_values(a) for a in c.draws]
        seeds = self.seeds.tolist()
        texts: dict = {}  # a slot's column of texts, shared by the grid points that write the same (_IdTemplate.texts)
        for g in range(len(self.points)):
            template = self._id_template(g) if _templated(c) else None
            ids = [None] * c.runs if template is None else template.run_ids(drawn, seeds, texts)
            for j, rid in enumerate(ids):
                k = g * c.runs + j
                if rid is None:
                    point = self.point(k)
                    rid, failed = point.id, point.error is not None
                else:
                    failed = template.failed  # type: ignore[union-attr]
                self.ids[k], self.failed[k] = rid.encode("ascii"), failed

    def _drawn_values(self, axis: Axis) -> list:
        """Every draw's value of draw axis ``axis`` as :meth:`values` gives it (a float, or a choice's value)."""
        col = self.drawn[axis.name].tolist()
        if axis.distribution == "choice":
            return [axis.params["values"][int(x)] for x in col]
        return [float(x) for x in col]

    def _id_template(self, g: int) -> _IdTemplate | None:
        """Grid point ``g``'s :class:`_IdTemplate`, ``None`` when only making each run can say (a target that is not
        a number to scale or shift, an FMU plant, a path the base refuses: the run made says why)."""
        c = self.campaign
        values = self.values(g, 0)
        scenario = pickle.loads(self._scenario)
        leaves = []
        try:
            for axis in c.grid:
                _apply_axis(axis, values[axis.name], spec=None, scenario=scenario, window=c.fault_window)
            for i, axis in enumerate(c.draws):
                for target in axis.targets:
                    base = value_at(scenario, target)
                    if axis.apply != "set" and not _is_number(base):
                        return None
                    set_path(scenario, target, _SLOT.format(len(leaves)))
                    leaves.append((i, axis.apply, base))
        except CampaignError:
            return None
        plant = scenario.get("plant")
        if isinstance(plant, dict) and plant.get("kind") == "fmu":
            return None
        got = self._design(g, values, None, _Where(g * c.runs, values))
        sha = None
        if isinstance(got, tuple):
            sha = got[1]
            self.artifacts.setdefault(sha, got[0])
        body = {"kind": c.kind, "artifact": sha, "scenario": scenario, "seed": _SLOT.format("seed"),
                "gainlink": __version__}  # fmt: skip
        return _IdTemplate.of(canonical_json(body), leaves, failed=not isinstance(got, tuple))


#: A drawn value's (or the seed's) place in a grid point's :class:`_IdTemplate`: a string no scenario holds.
_SLOT = "gainlink-plan-slot-{}-7c1e"
_PLANT_FILE = ("plant.kind", "plant.fmu", "plant.path")  # what makes a plant an FMU, read by _fmu_blob
_SLOTS = re.compile('"' + _SLOT.format("(seed|[0-9]+)") + '"')


class _IdTemplate:
    """The run ids of one grid point's runs without making their scenarios: the canonical JSON of an id's body
    (:func:`run_id`) made once with a slot where each drawn value lands and where the seed goes; a run's id is the
    sha256 of that text with its own values' JSON in the slots (what :func:`set_path` leaves there: the value, or the
    base's number scaled or shifted by it, by Python's own float arithmetic). Making each run (:meth:`_Planner.point`)
    is its oracle, and its fallback for a value it cannot write."""

    def __init__(self, parts: list[str], slots: list[int | None], leaves: list[tuple[int, str, Any]], failed: bool):
        self.parts, self.slots, self.leaves, self.failed = parts, slots, leaves, failed

    @classmethod
    def of(cls, text: str, leaves: list[tuple[int, str, Any]], *, failed: bool) -> _IdTemplate | None:
        """The template of canonical JSON ``text`` holding each slot once (``leaves``: each drawn slot's draw axis,
        ``apply`` and base value), ``None`` if it does not."""
        found = _SLOTS.split(text)
        parts, names = found[::2], found[1::2]
        slots = [None if n == "seed" else int(n) for n in names]
        if sorted(slots, key=lambda x: -1 if x is None else x) != [None, *range(len(leaves))]:
            return None
        return cls(parts, slots, leaves, failed)

    def run_ids(self, drawn: list[list], seeds: list[int], made: dict | None = None) -> list[str | None]:
        """The id of each draw ``j``'s run: draw-axis values ``drawn[i][j]`` (axis ``i`` in the campaign's order) and
        seed ``seeds[j]``; ``None`` where a value is not one the template writes (a non-finite number, a scale or
        shift by a non-number). Each slot's texts are made a column at a time (:meth:`texts`, kept in ``made`` for
        the next grid point), then each run's body once through the template."""
        made = {} if made is None else made
        columns = [self.texts(slot, drawn, seeds, made) for slot in self.slots]
        template = "%s".join(part.replace("%", "%%") for part in self.parts)
        sha256 = hashlib.sha256
        return [
            None if None in row else sha256((template % row).encode("ascii")).hexdigest()[:20] for row in zip(*columns)
        ]

    def texts(self, slot: int | None, drawn: list[list], seeds: list[int], made: dict) -> list[str | None]:
        """The column of texts of ``slot`` (``None``: the seed), from ``made`` when a grid point before wrote the same:
        a set value's texts are the same at every grid point, a scaled or shifted one's the same for the same base."""
        if slot is None:
            key: tuple = ("seed",)
        else:
            axis, apply, base = self.leaves[slot]
            key = (axis, apply) if apply == "set" else (axis, apply, type(base), repr(base))
        if key not in made:
            made[key] = list(map(str, seeds)) if slot is None else _leaf_texts(drawn[axis], apply, base)
        return made[key]


def _templated(campaign: Campaign) -> bool:
    """Whether a campaign's run ids can come from :class:`_IdTemplate`: each draw axis sets, scales or shifts scenario
    values (not the spec, not a fault or the transport), and no target lies inside another's (or is another's)."""
    if any(a.design or a.apply not in ("set", "scale", "add") for a in campaign.draws):
        return False
    if any(t.startswith(("faults.", "transport.")) or t in _PLANT_FILE for a in campaign.draws for t in a.targets):
        return False
    paths = [path_steps(t) for a in (*campaign.grid, *campaign.draws) for t in a.targets if not t.startswith("spec.")]
    return not any(i != j and q[: len(p)] == p for i, p in enumerate(paths) for j, q in enumerate(paths))


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _leaf_texts(values: list, apply: str, base: Any) -> list[str | None]:
    """:func:`_leaf_json` of each of ``values`` (one draw axis's, every draw): a column of floats set, scaled or
    shifted by a number at once (Python's own arithmetic and ``float.__repr__``, as the run made whole writes them),
    else each value's text made once per object (a choice axis repeats a few; by identity: ``-0.0 == 0.0``)."""
    if apply != "set" and not _is_number(base):
        return [None] * len(values)
    if all(type(v) is float for v in values) and (apply == "set" or type(base) in (int, float)):
        left = (
            values if apply == "set" else [base * v for v in values] if apply == "scale" else [base + v for v in values]
        )
        return [repr(v) if math.isfinite(v) else None for v in left]
    texts: dict[int, str | None] = {}
    for v in values:
        if id(v) not in texts:
            texts[id(v)] = _leaf_json(v, apply, base)
    return [texts[id(v)] for v in values]


def _leaf_json(value: Any, apply: str, base: Any) -> str | None:
    """The canonical JSON of what :func:`set_path` leaves at a target given ``value`` (``apply``: set, scale or add to
    ``base``); ``None`` for a value only the run made can say (a non-finite number, a non-number to scale or add)."""
    if apply != "set":
        if not _is_number(value):
            return None
        value = _leaf_value(value, apply, base)
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else None
    try:
        return canonical_json(value)
    except (GainlinkError, TypeError, ValueError):
        return None


def plan_campaign(campaign: Campaign) -> CampaignPlan:
    """Plan ``campaign``: check it, design each grid point, and give each run its id (from its grid point's
    :class:`_IdTemplate` where the axes allow, else by making the run), keeping no run; its runs are returned as a
    :class:`PlannedRuns` (generated again when read).

    A mistake of the campaign file is refused here, before any run (:class:`CampaignError`, one line naming the
    key): a value of another kind than the scenario holds (:func:`.preflight.check_axis_values`), a spec the spec
    parser refuses at any grid point, a scenario the scenario parser refuses at any run's draw (checked at the
    extremes of each drawn number, see the module docstring), a plant that cannot be built for one run of each shape
    (:class:`.preflight.DryBuild`). A design that fails at a grid point (``DesignError``) is that point's result.
    """
    check_axis_values(campaign)
    dry = DryBuild(campaign)
    planner = _Planner(campaign)
    for k in planner.checked():  # each made, checked and dropped
        planner.point(k, dry=dry)
    planner.index()
    return CampaignPlan(
        campaign=campaign, runs=PlannedRuns(campaign, planner), artifacts=planner.artifacts, blobs=planner.blobs
    )


def _with_sha(art: bytes) -> tuple[bytes, str]:
    return art, json.loads(art)["sha256"]


def _artifact(campaign: Campaign, spec: dict, key: str, designs: dict, where: str) -> tuple[bytes, str] | str:
    """The artifact of ``spec`` (canonical ``key``) and its sha256, designed once per key; or the design's error."""
    if key not in designs:
        try:
            designs[key] = _with_sha(designed(spec, source=f"{campaign.spec_path} ({where})"))
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
