"""Count the places outside the law modules that decide which kind of law they hold (issue 30).

    .venv/bin/python scripts/count_law_branches.py [--json] [--root DIR]

Which law an artifact runs is decided in one place, ``gainlink.laws.law_of``; everything else asks the law it
returns (docs/design.md, "Adding a law"). This script finds what still decides for itself:

- Python in ``runtime/`` and ``hil/`` outside ``runtime/laws/``: each test listed in :data:`PY_TESTS` (``schedule
  is None``, ``is_fixed(``, ``require_unscheduled``, a test for the fixed-point certificate, a ``law_of`` other than
  ``gainlink.laws.law_of``, ``trace_numeric``, ``"flags" in ....names``, a comparison of ``numeric``, an
  ``isinstance`` on a law's class, a schema-version dispatch). Comments and docstrings are not code and are skipped.
- C in ``firmware/`` outside the laws' own sources (:data:`C_LAW_OWN`): each ``#if``/``#elif``/``#ifdef``/``#ifndef``
  on a law macro (:data:`C_LAW_MACROS`).
- Modules named after a law kind (``fixed``, ``sched``, ``scheduled``, ``float32``, ...) outside the law's own
  (Python outside ``runtime/laws/``, C outside :data:`C_LAW_OWN`).

It prints each file's figure and the totals (``--json``: the same as JSON). ``scripts/law_branches_ceiling.json``
holds the ceiling the suite asserts (tests/test_law_branches.py): the figures only go down, to 0 when every
consumer asks the law.
"""

from __future__ import annotations

import argparse
import io
import json
import re
import sys
import tokenize
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: Python folders scanned, and the places whose modules may decide: the law modules and their registry, and the
#: registry's one reading of the artifact (``law_pair``), which sits below the laws layer because the C export names
#: the law too.
PY_DIRS = ("runtime", "hil")
PY_LAW_OWN: tuple[str, ...] = ("runtime/laws/", "runtime/shipping/law_c.py")

#: Each way Python code decides the kind of law: (name, pattern over a line of code without comments/docstrings).
PY_TESTS: tuple[tuple[str, re.Pattern[str]], ...] = tuple(
    (name, re.compile("|".join(alternatives)))
    for name, alternatives in (
        ("schedule is None", [r"\b(?:sched|schedule)\s+is\s+(?:not\s+)?None\b"]),
        ("is_fixed", [r"\bis_fixed\s*\("]),
        ("require_unscheduled", [r"\brequire_unscheduled\s*\("]),
        (
            "fixed_point present",
            [r"""\.get\(\s*["']fixed_point["']\s*\)""", r"""["']fixed_point["']\s+(?:not\s+)?in\b"""],
        ),
        (
            "fixed_point is None",
            [r"\bfixed_point\s+is\s+(?:not\s+)?None\b", r"\bif\s+(?:not\s+)?[\w.]*\bfixed_point\s*:"],
        ),
        ("trace_numeric", [r"(?<![.\w])trace_numeric\s*\("]),
        ("flags in names", [r"""["']flags["']\s+(?:not\s+)?in\s+[\w.]*\.names\b"""]),
        (
            "numeric compared",
            [r"\bnumeric\s*(?:==|!=)", r"(?:==|!=)\s*[\w.]*\bnumeric\b", r"\bnumeric\s+(?:not\s+)?in\s*[(\[{]"],
        ),
        ("isinstance of a law", [r"\bisinstance\s*\([^)]*\b\w*(?:Sched|Fixed)\w*"]),
        ("schema dispatch", [r"\bschema_version\W+\s*(?:==|!=)", r"(?:==|!=)\s*SCHEDULED_SCHEMA_VERSION\b"]),
        ("velocity form", [r"""(?:==|!=)\s*["']velocity["']"""]),
    )
)

#: ``law_of`` is gainlink.laws's: any other definition of it, or a call of one imported from elsewhere, decides.
PY_LAW_OF_DEF = re.compile(r"^\s*def\s+law_of\s*\(")
PY_LAW_OF_IMPORT = re.compile(r"^\s*from\s+([.\w]+)\s+import\s+[^#]*\blaw_of\b")
PY_LAW_OF_CALL = re.compile(r"\blaw_of\s*\(")

#: C: the laws' own sources and headers (the registry of the C side, gl_law.h, included), by path prefix.
C_LAW_OWN: tuple[str, ...] = (
    "firmware/src/gl_loop",
    "firmware/src/gl_fixed",
    "firmware/src/gl_sched",
    "firmware/src/gl_mpc",
    "firmware/src/gl_law",
    "firmware/include/gainlink/gl_loop",
    "firmware/include/gainlink/gl_fixed",
    "firmware/include/gainlink/gl_sched",
    "firmware/include/gainlink/gl_mpc",
    "firmware/include/gainlink/gl_law",
)
#: The macros that say which law an image compiles (a preprocessor test on one of them chooses by law).
C_LAW_MACROS = re.compile(
    r"\bGL_SCHEDULED\b|\bGL_\w*LAW_(?:FIXED|SCHED|MPC)\w*|\bGL_NUMERIC_\w+|\bGL_LAW(?:_STRUCTURE|_NUMERIC|_ID)?\b"
)
C_CONDITIONAL = re.compile(r"^\s*#\s*(?:if|elif|ifdef|ifndef)\b(.*)")
C_SUFFIXES = (".c", ".h")

#: Words a module named after a law kind carries (``pil_fixed.py``, ``main_sched.c``, ``scheduled_float32.py``).
KIND_WORDS = frozenset({"fixed", "fx", "fxparams", "fxset", "sched", "schedparams", "schedule", "scheduled",
                        "float32", "q31", "q15", "lq", "mpc"})  # fmt: skip
KIND_NAME_SPLIT = re.compile(r"[_\-.]")


def code_lines(source: str) -> list[str]:
    """``source``'s lines with comments cut and docstrings blanked (line numbers kept)."""
    lines = source.splitlines()
    try:
        tokens = list(tokenize.generate_tokens(io.StringIO(source).readline))
    except (tokenize.TokenError, SyntaxError):
        return lines
    blank: list[tuple[tuple[int, int], tuple[int, int]]] = []
    previous = tokenize.NEWLINE
    for tok in tokens:
        if tok.type == tokenize.COMMENT:
            blank.append((tok.start, (tok.start[0], len(lines[tok.start[0] - 1]))))
        elif tok.type == tokenize.STRING and previous in (tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT):
            blank.append((tok.start, tok.end))  # a string statement: a docstring
        if tok.type not in (tokenize.NL, tokenize.COMMENT):
            previous = tok.type
    for (r0, c0), (r1, c1) in blank:
        for row in range(r0, r1 + 1):
            text = lines[row - 1]
            start = c0 if row == r0 else 0
            end = c1 if row == r1 else len(text)
            lines[row - 1] = text[:start] + " " * (end - start) + text[end:]
    return lines


def python_sites(path: Path, rel: str) -> list[dict]:
    """Every line of a Python file outside the law modules that decides the law kind, with the test it uses."""
    source = path.read_text(encoding="utf-8")
    if not any(p.search(source) for _, p in PY_TESTS) and not PY_LAW_OF_CALL.search(source):
        return []  # nothing to look at closer (tokenizing every file is most of the scan's time)
    lines = code_lines(source)
    foreign_law_of = any((m := PY_LAW_OF_IMPORT.match(line)) and not _is_laws(m.group(1)) for line in lines)
    sites = []
    for no, line in enumerate(lines, start=1):
        tests = [name for name, pattern in PY_TESTS for _ in pattern.finditer(line)]
        if PY_LAW_OF_DEF.match(line):
            tests.append("law_of of its own")
        elif foreign_law_of and PY_LAW_OF_CALL.search(line) and not PY_LAW_OF_IMPORT.match(line):
            tests.append("law_of of its own")
        sites += [{"file": rel, "line": no, "test": t, "code": line.strip()} for t in tests]
    return sites


def _is_laws(module: str) -> bool:
    """Whether an import's module is gainlink.laws (absolute, or relative from anywhere in gainlink)."""
    return module.lstrip(".") == "laws" or module == "gainlink.laws" or module.endswith(".laws")


def c_sites(path: Path, rel: str) -> list[dict]:
    """Every preprocessor conditional on a law macro in a C file outside the laws' own sources."""
    sites = []
    for no, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), start=1):
        m = C_CONDITIONAL.match(line)
        if m and C_LAW_MACROS.search(m.group(1).split("/*")[0]):
            sites.append({"file": rel, "line": no, "test": "#if on the law", "code": line.strip()})
    return sites


def named_after_a_kind(rel: str) -> bool:
    """Whether a file's name carries a law-kind word (``pil_fixed.py``, ``main_sched.c``)."""
    stem = Path(rel).name.rsplit(".", 1)[0]
    return any(word in KIND_WORDS for word in KIND_NAME_SPLIT.split(stem.lower()))


def scan(root: Path = ROOT) -> dict:
    """The sites and the kind-named modules under ``root``, with the figures per file and in total."""
    sites: list[dict] = []
    modules: list[str] = []
    for rel, path in _files(root):
        own = rel.startswith(PY_LAW_OWN) if rel.endswith(".py") else rel.startswith(C_LAW_OWN)
        if own:
            continue
        sites += python_sites(path, rel) if rel.endswith(".py") else c_sites(path, rel)
        if named_after_a_kind(rel):
            modules.append(rel)
    per_file = Counter(s["file"] for s in sites)
    python = sum(n for f, n in per_file.items() if f.endswith(".py"))
    return {
        "python": python,
        "c": sum(per_file.values()) - python,
        "python_files": len([f for f in per_file if f.endswith(".py")]),
        "modules": len(modules),
        "per_file": dict(sorted(per_file.items())),
        "per_test": dict(Counter(s["test"] for s in sites).most_common()),
        "module_names": modules,
        "sites": sites,
    }


def _files(root: Path) -> list[tuple[str, Path]]:
    """(path relative to ``root``, path) of every Python file in :data:`PY_DIRS` and C file in ``firmware/``."""
    found = [p for d in PY_DIRS for p in (root / d).rglob("*.py")]
    found += [p for p in (root / "firmware").rglob("*") if p.suffix in C_SUFFIXES]
    return sorted((p.relative_to(root).as_posix(), p) for p in found if "__pycache__" not in p.parts)


def text_report(result: dict) -> str:
    """Per file, then per test, then the totals."""
    lines = [f"{n:4d}  {f}" for f, n in result["per_file"].items()]
    lines.append("")
    lines += [f"{n:4d}  {t}" for t, n in result["per_test"].items()]
    lines += [
        "",
        f"modules named after a law kind outside the laws' own: {result['modules']}",
        *(f"      {m}" for m in result["module_names"]),
        f"law-kind branches outside the law modules: {result['python']} in Python ({result['python_files']} files),"
        f" {result['c']} in C",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", action="store_true", help="print the figures (and every site) as JSON")
    parser.add_argument("--root", type=Path, default=ROOT, help="the checkout to scan (default: this one)")
    args = parser.parse_args(argv)
    result = scan(args.root)
    print(json.dumps(result, indent=2) if args.json else text_report(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
