"""scripts/count_law_branches.py: the places outside the law modules that decide which kind of law they hold.

The counter is checked on a tree written here, whose sites are counted by hand (the oracle); the checkout's figures
may only go down from the ceiling checked in beside the script (the issue-30 migration lowers it to 0).
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

from support.paths import ROOT

SCRIPT = ROOT / "scripts" / "count_law_branches.py"

#: file -> (text, law-kind branches a reader counts in it)
TREE = {
    "runtime/cli/x.py": (
        '"""Docstring: a.schedule is None and is_fixed(a) are words here."""\n'
        "from ..laws import law_of\n"
        "\n"
        "def f(a):\n"
        "    # if a.schedule is None: (a comment)\n"
        "    if a.schedule is not None and is_fixed(a):\n"  # 2
        "        return law_of(a)\n"  # gainlink.laws's: 0
        "    law_of(a).trace_numeric(None)\n"  # asking the law: 0
        "    a.require_unscheduled('f')\n"  # 1
        '    return a.checks.get("fixed_point") or numeric == "q15"\n',  # 2
        5,
    ),
    "hil/loop/pil_fixed.py": (
        "from gainlink.mavlink.fixed_params import law_of\n"
        "\n"
        "def g(a, dout, t):\n"
        '    fixed = "flags" in dout.names\n'  # 1
        "    return law_of(a), trace_numeric(a), isinstance(t, ScheduledTrace)\n",  # 3
        4,
    ),
    "runtime/laws/lq.py": ("def law_of(a):\n    return a.schedule is None and is_fixed(a)\n", 0),
    "runtime/shipping/codegen.py": ("def law_of(a):\n    return 'lq'\n", 1),
    "firmware/apps/can/main.c": (
        "#if defined(GL_SCHEDULED) && GL_SCHEDULED\n"  # 1
        "#endif\n"
        "#if GL_HAVE_VLDM /* GL_SCHEDULED in a comment of another test */\n"
        "#endif\n"
        "#elif defined(GL_MAV_LAW_FIXED)\n"  # 1
        "int x; /* #if GL_SCHEDULED */\n",
        2,
    ),
    "firmware/src/gl_sched.c": ("#if GL_SCHEDULED\n#endif\n", 0),
    "firmware/ports/cortex-m/main_sched.c": ("int main(void) { return 0; }\n", 0),
}


def load_script():
    spec = importlib.util.spec_from_file_location("count_law_branches", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_counter_finds_each_site_a_reader_counts_and_nothing_in_comments_docstrings_or_the_laws(tmp_path):
    for rel, (text, _) in TREE.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    proc = subprocess.run([sys.executable, str(SCRIPT), "--json", "--root", str(tmp_path)],
                          capture_output=True, text=True, timeout=60, check=True)  # fmt: skip
    got = json.loads(proc.stdout)
    want = {rel: n for rel, (_, n) in TREE.items() if n}
    assert got["per_file"] == want
    assert got["python"] == sum(n for rel, n in want.items() if rel.endswith(".py"))
    assert got["c"] == want["firmware/apps/can/main.c"]
    # pil_fixed.py and main_sched.c are named after a kind; the laws' own (runtime/laws, gl_sched.c) are not counted
    assert sorted(got["module_names"]) == ["firmware/ports/cortex-m/main_sched.c", "hil/loop/pil_fixed.py"]


def test_the_checkouts_law_branches_only_go_down():
    """The ceiling is lowered as consumers switch to gainlink.laws (issue 30); a new branch on the law kind
    outside the law modules fails here: ask the law (law_of(artifact)) instead."""
    ceiling = json.loads((SCRIPT.parent / "law_branches_ceiling.json").read_text())
    result = load_script().scan(Path(ROOT))
    for key in ("python", "c", "modules"):
        assert result[key] <= ceiling[key], (
            f"{result[key]} {key} law-kind branches/modules outside the law modules, ceiling {ceiling[key]}:\n"
            + "\n".join(f"{s['file']}:{s['line']} {s['code']}" for s in result["sites"])
        )
