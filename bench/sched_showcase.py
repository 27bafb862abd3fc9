"""The scheduled-law showcase's numbers for the docs (docs/guide/scheduled.md; issue 18 item 6): ``gainlink hil
showcase`` with its built-in description (examples/tank_showcase.toml scheduled and at its middle point, HIL: the
firmware's CAN node on each law against the tank FMU), its report.json printed with the machine's load.

    .venv/bin/python bench/sched_showcase.py > out/bench/sched_showcase.json
    .venv/bin/python scripts/doc_figures.py --record sched_showcase && .venv/bin/python scripts/doc_figures.py
"""

from __future__ import annotations

import json
import logging
import os
import sys
import tempfile
import time
from pathlib import Path

from gainlink.hil.loop.showcase import run_showcase


def main() -> int:
    logging.disable(logging.WARNING)
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="gainlink-bench-showcase-") as tmp:
        run_showcase(report_dir=Path(tmp) / "report")
        doc = json.loads((Path(tmp) / "report" / "report.json").read_text())
    doc["spec"] = "examples/tank_showcase.toml"  # not the checkout's absolute path
    doc.update({"wall_s": round(time.perf_counter() - t0, 1), "load_average_1min": round(load, 2)})
    json.dump(doc, sys.stdout, indent=2, sort_keys=True)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
