"""Write the bytecode of the modules gainlink and its tests import, once, right after the set-up installed them.

    env -u PYTHONDONTWRITEBYTECODE .venv/bin/python scripts/warm_bytecode.py

uv installs without compiling (compiling all of site-packages took 25 of the set-up's 40 s, and most of it is never
imported). Left to the first import instead, the suite's four workers and the processes they start would compile the
same modules side by side. Importing them here compiles each once (a few seconds); a module imported only later is
compiled by the first process that needs it. A package that fails to import is skipped: the tests say why.
"""

from __future__ import annotations

import importlib
import json
import pkgutil
import subprocess
import sys

#: what gainlink imports lazily (inside the functions that need them) and what its tests use, in two halves: the
#: second is imported by a second process at the same time (two cores; 15 -> 11 s)
THIRD_PARTY = (
    "control",  # scipy.signal, scipy.stats, matplotlib.pyplot
    "slycot",
    "scipy.optimize",
    "scipy.integrate",
    "scipy.interpolate",
    "jsonschema",
    "matplotlib.backends.backend_agg",
    "flint",
    "clarabel",
    "scs",
)
SECOND_HALF = (
    "rich.progress",
    "fmpy.simulation",
    "fmpy.sundials",
    "can.interfaces.udp_multicast",
    "can.interfaces.socketcan",
    "can.interfaces.slcan",
    "cantools",
    "msgpack",
    "pymavlink.mavutil",
    "pymavlink.dialects.v20.common",
    "serial",
    "distributed",
    "hypothesis",
    "mavsdk",
    "defusedxml",
    "xdist",
    # the documentation's build (tests/test_docs.py, make docs)
    "sphinx.application",
    "myst_parser.sphinx_ext",
    "numpydoc.numpydoc",
    "sphinxarg.ext",
    "furo",
)


def _import_all(names: list[str]) -> list[str]:
    """Import each of ``names`` (which writes their bytecode); the names that failed."""
    failed = []
    for name in names:
        try:
            importlib.import_module(name)
        except Exception:  # any import error: that package's tests report it
            failed.append(name)
    return failed


def main() -> int:
    """Import gainlink's modules and :data:`THIRD_PARTY` here and :data:`SECOND_HALF` in a second process; print how
    many modules that wrote and how many names could not be imported."""
    if sys.argv[1:] == ["--second-half"]:
        failed = _import_all(list(SECOND_HALF))
        print(json.dumps({"modules": sorted(sys.modules), "failed": failed}))
        return 0
    second = subprocess.Popen([sys.executable, __file__, "--second-half"], stdout=subprocess.PIPE, text=True)
    import gainlink
    import gainlink.hil

    names = [
        info.name
        for pkg in (gainlink, gainlink.hil)
        for info in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + ".")
        if not info.name.endswith("__main__")
    ]
    failed = _import_all([*names, *THIRD_PARTY])
    out, _ = second.communicate()
    # the report is the last line: a package may print something of its own as it is imported
    last = out.strip().splitlines()[-1:] if second.returncode == 0 else []
    report = json.loads(last[0]) if last else {"modules": [], "failed": list(SECOND_HALF)}
    modules = set(sys.modules) | set(report["modules"])
    failed += report["failed"]
    print(f"setup: bytecode of {len(modules)} modules written" + (f" ({len(failed)} not importable)" if failed else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
