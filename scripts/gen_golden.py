#!/usr/bin/env python3
"""Write golden vectors for the firmware: the three examples and N random stabilizable designs.

Each case gets <label>.gains.json (the artifact) and <label>.npz (samples Y, R and the float64
reference's u, saturated, xh, z, fault), plus index.json. Nothing is pasted: plants are drawn from a
seeded generator, designed by gainlink.synthesis, answered by gainlink.proof.reference.

    .venv/bin/python scripts/gen_golden.py [--out .cache/golden] [--random 30] [--steps 400]
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from gainlink.laws.lq.golden import example_cases, random_cases, write_case, write_index

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / ".cache" / "golden", help="output folder")
    parser.add_argument("--random", type=int, default=30, help="number of random designs")
    parser.add_argument("--steps", type=int, default=400, help="samples per random design")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    cases = list(example_cases(ROOT / "examples")) + list(random_cases(args.random, N=args.steps))
    for case in cases:
        write_case(case, args.out)
    index = write_index(cases, args.out)
    print(f"wrote {len(cases)} golden cases to {args.out} (index: {index.name})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
