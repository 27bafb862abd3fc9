"""Write the bytecode of the modules gainlink and its tests import, once, right after the set-up installed them.

    env -u PYTHONDONTWRITEBYTECODE .venv/bin/python scripts/warm_bytecode.py

uv installs without compiling (compiling all of site-packages took 25 of the set-up's 40 s, and most of it is never
imported). Left to the first import instead, the suite's four workers and the processes they start would compile the
same modules side by side. Importing them here compiles each once (a few seconds); a module imported only later is
compiled by the first process that needs it. A package that fails to import is skipped: the tests say why.
"""

from __future__ import annotations

import importlib
import pkgutil
import sys

#: what gainlink imports lazily (inside the functions that need them) and what its tests use
THIRD_PARTY = (
    "control",  # scipy.signal, scipy.stats, matplotlib.pyplot
    "slycot",
    "scipy.optimize",
    "scipy.integrate",
    "scipy.interpolate",
    "jsonschema",
    "matplotlib.backends.backend_agg",
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
    "flint",
    "clarabel",
    "scs",
    "hypothesis",
    "mavsdk",
    "defusedxml",
    "xdist",
)


def main() -> int:
    """Import gainlink's modules and :data:`THIRD_PARTY`; print how many could not be imported."""
    import gainlink
    import gainlink.hil

    names = [
        info.name
        for pkg in (gainlink, gainlink.hil)
        for info in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + ".")
        if not info.name.endswith("__main__")
    ]
    failed = []
    for name in [*names, *THIRD_PARTY]:
        try:
            importlib.import_module(name)
        except Exception:  # any import error: that package's tests report it
            failed.append(name)
    print(
        f"setup: bytecode of {len(sys.modules)} modules written"
        + (f" ({len(failed)} not importable)" if failed else "")
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
