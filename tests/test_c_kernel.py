"""gainlink.firmware.c_kernel: a campaign block's C kernel (the lq law's float64 block step) built once into the build
cache, a compiler that is missing or fails one line, nothing left behind."""

from __future__ import annotations

import pytest
from gainlink.errors import ToolchainError
from gainlink.firmware import build, c_kernel
from gainlink.laws.lq import native_block


@pytest.fixture
def own_cache(tmp_path, monkeypatch):
    """The build cache in ``tmp_path / "cache"``, the process's lookups of kernels forgotten before and after."""
    monkeypatch.setattr(build, "cache_root", lambda: tmp_path / "cache")
    c_kernel._library.cache_clear()
    yield tmp_path / "cache"
    c_kernel._library.cache_clear()


def _build():
    return c_kernel.kernel_library(native_block.SOURCE, name=native_block.LIBRARY, what="the float64 law's block step")


def test_the_block_kernel_is_built_once_and_a_failing_compiler_is_one_line_leaving_nothing(own_cache, tmp_path,
                                                                                           monkeypatch):  # fmt: skip
    broken = tmp_path / "cc"
    broken.write_text("#!/bin/sh\necho 'reference_block.c:1:1: error: no such compiler today' >&2\nexit 1\n")
    broken.chmod(0o755)
    monkeypatch.setenv("CC", str(broken))
    with pytest.raises(ToolchainError) as err:
        _build()
    assert "no such compiler today" in str(err.value) and "\n" not in str(err.value)
    assert [p.name for p in own_cache.rglob("*") if p.is_file()] == [".lock"]  # no library, no temporary file
    monkeypatch.setenv("CC", str(tmp_path / "absent-cc"))
    with pytest.raises(ToolchainError, match=r"C compiler .*absent-cc not found") as err:
        _build()
    assert "\n" not in str(err.value)
    monkeypatch.delenv("CC")
    lib = _build()
    assert lib.parent.parent == own_cache and lib.is_file()
    built = lib.stat().st_mtime_ns
    c_kernel._library.cache_clear()  # as another process finds it
    assert _build() == lib and lib.stat().st_mtime_ns == built  # found, not built again
    assert sorted(p.name for p in lib.parent.iterdir()) == [".lock", lib.name]
