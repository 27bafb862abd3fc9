"""Write pytest's assert-rewritten bytecode of the test modules once, before `make test` starts its workers.

    env -u PYTHONDONTWRITEBYTECODE .venv/bin/python scripts/warm_test_asserts.py

Every pytest-xdist worker collects every test module, and pytest rewrites a module's asserts (parse, rewrite,
compile: about 6 CPU-s for the whole suite) unless its ``__pycache__`` holds a current rewritten copy. In a fresh
clone the four workers start together and each rewrites all of them. Here two processes rewrite them once; a
module already current is skipped (pytest's own check: the source's mtime and size).

This uses pytest's internal ``_rewrite_test``/``_read_pyc``/``_write_pyc`` (pytest is pinned below 9 in
pyproject.toml). If they change, the script says so and exits 0: the workers then rewrite as before.
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1] / "tests"


class _State:
    """The part of pytest's ``AssertionState`` that the pyc helpers use: a tracer."""

    @staticmethod
    def trace(*_args: object) -> None:
        return None


def _warm(path: str) -> bool:
    """Rewrite one module and write its cached pyc unless a current one is there; True if written."""
    from _pytest.assertion import rewrite

    fn = Path(path)
    pyc = rewrite.get_cache_dir(fn) / (fn.name[:-3] + rewrite.PYC_TAIL)
    if rewrite._read_pyc(fn, pyc, _State.trace) is not None:
        return False
    # No config: the rewrite differs only with the ini option enable_assertion_pass_hook, which is not set.
    source_stat, code = rewrite._rewrite_test(fn, None)  # type: ignore[arg-type]
    pyc.parent.mkdir(exist_ok=True)
    rewrite._write_pyc(_State(), code, source_stat, pyc)  # type: ignore[arg-type]
    return True


def main() -> int:
    """Rewrite the test modules (``test_*.py`` and ``conftest.py`` under the folder) in two processes."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, nargs="?", default=TESTS, help="the tests (default: tests/)")
    args = parser.parse_args()
    if not args.folder.is_dir():
        print(f"warm_test_asserts: {args.folder} is not a folder", file=sys.stderr)
        return 2
    if sys.dont_write_bytecode:
        print("warm_test_asserts: PYTHONDONTWRITEBYTECODE is set, nothing written")
        return 0
    paths = sorted(str(p) for pattern in ("test_*.py", "conftest.py") for p in args.folder.resolve().rglob(pattern))
    try:
        with ProcessPoolExecutor(max_workers=2) as pool:
            written = sum(pool.map(_warm, paths, chunksize=4))
    except (ImportError, AttributeError, TypeError) as exc:  # pytest's internals moved: the workers rewrite
        print(f"warm_test_asserts: skipped ({type(exc).__name__}: {exc})")
        return 0
    if written:
        print(f"warm_test_asserts: rewrote the asserts of {written} of {len(paths)} test modules")
    return 0


if __name__ == "__main__":
    sys.exit(main())
