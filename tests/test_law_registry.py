"""The tables the layers below the laws read a law's parts from (gainlink.registry; docs/design.md §8): filled by the
law families whichever gainlink module a program imports first, and a key no family registered refused in one line
naming it."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from gainlink.errors import LawError
from gainlink.shipping import artifact as artifact_mod
from gainlink.shipping import export_c, params, systems
from gainlink.spec import parse
from schedule_cases import TANK, tank_dict
from support.designs import designed
from support.mpc import mpc_pendulum

#: A fresh interpreter that imports one low-layer module only, then reads a scheduled and an MPC artifact, exports
#: them and parses the scheduled spec: every law part it needs comes from the tables the families fill.
PROBE = """
import json, sys
import gainlink.shipping.artifact as A
sched, mpc = A.load(sys.argv[1]), A.load(sys.argv[2])
from gainlink.shipping.export_c import render_export
from gainlink.spec.parse import load_spec
spec = load_spec(sys.argv[3])
print(json.dumps({
    "points": sched.schedule.points.tolist(), "horizon": mpc.mpc.horizon,
    "sched_files": sorted(render_export(sched)), "mpc_files": sorted(render_export(mpc)),
    "spec_points": [float(p) for p in spec.schedule.points],
}))
"""


def test_a_low_layer_module_imported_first_reads_every_law(tmp_path):
    sched, mpc = designed(tank_dict()), designed(mpc_pendulum())
    paths = []
    for name, data in (("sched", sched), ("mpc", mpc)):
        paths.append(tmp_path / f"{name}.json")
        artifact_mod.write(paths[-1], data)
    res = subprocess.run(
        [sys.executable, "-c", PROBE, *map(str, paths), str(TANK)], capture_output=True, text=True, timeout=120
    )
    assert res.returncode == 0, res.stderr
    got = json.loads(res.stdout)
    # the oracle: the artifacts' own JSON and the C files each law's export is made of (firmware/CMakeLists.txt)
    assert got["points"] == sched["schedule"]["points"] and got["horizon"] == mpc["mpc"]["horizon"]
    assert "gl_sched_gains.c" in got["sched_files"] and "gl_mpc_gains.c" in got["mpc_files"]
    assert got["spec_points"] == tank_dict()["schedule"]["points"]


@pytest.mark.parametrize(
    ("table", "key", "what"),
    [
        (export_c.RENDERINGS, "lq/q7", "C rendering"),
        (params.TABLES, "scheduled/q31", "parameter table"),
        (systems.COEFFICIENTS, "hinf", "frozen-point coefficients"),
        (artifact_mod.BLOCKS, "horizon", "artifact block reader"),
        (parse.PLANTS, "hinf", "spec plant reader"),
        (parse.BLOCKS, "hinf", "spec table reader"),
    ],
)
def test_an_unregistered_key_is_refused_in_one_line_naming_it(table, key, what):
    with pytest.raises(LawError) as err:
        table[key]
    text = str(err.value)
    assert "\n" not in text and repr(key) in text and what in text
    assert key not in table and table.get(key) is None


def test_every_pair_registers_its_export_and_parameter_table():
    from gainlink.laws import pairs

    # each law pair (gainlink.laws.pairs: the laws' own declaration) has its C and its MAVLink table below the laws
    assert sorted(export_c.RENDERINGS) == sorted(pairs()) == sorted(params.TABLES)


def test_the_bridges_plant_table_names_no_law_kind():
    """A plant is a plant whatever law runs against it: no kind in the bridge's plant table is named after a law
    (the words of scripts/count_law_branches.py, the counter of kind-named modules)."""
    import importlib.util

    import gainlink.hil.plants.config  # noqa: F401 - registers every built-in kind
    from gainlink.hil.plants.base import PLANTS
    from support.paths import ROOT

    spec = importlib.util.spec_from_file_location("count_law_branches", ROOT / "scripts" / "count_law_branches.py")
    counter = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(counter)
    assert PLANTS.names() and [k for k in PLANTS.names() if counter.named_after_a_kind(f"{k}.py")] == []
