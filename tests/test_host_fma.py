"""The host library's fused multiply-adds: inline FMA instructions on an x86-64 CPU that has them (``GL_HOST_FMA``),
libm's ``fmaf`` elsewhere; both round once, so the host's records are the same bits either way."""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest
from gainlink.firmware.build import build, host_has_fma
from gainlink.firmware.host import HostLaw
from gainlink.shipping import artifact as artifact_mod

pytestmark = pytest.mark.skipif(not host_has_fma(), reason="GL_HOST_FMA is set on an x86-64 CPU with FMA only")


def _calls_fmaf(library) -> bool:
    """Whether the shared library imports libm's ``fmaf`` (its undefined dynamic symbols)."""
    out = subprocess.run(["nm", "-D", "--undefined-only", str(library)], capture_output=True, text=True, check=True)
    return any(line.split()[-1].split("@")[0] == "fmaf" for line in out.stdout.splitlines() if line.strip())


@pytest.mark.skipif(shutil.which("nm") is None, reason="needs binutils' nm")
def test_the_host_law_steps_the_same_bits_with_inline_fma_as_with_libms_fmaf(pend):
    a = artifact_mod.load(pend)
    inline = build(a, target="host", only="gainlink_host").files["shared"]
    libm = build(a, target="host", only="gainlink_host", options={"GL_HOST_FMA": "OFF"}).files["shared"]
    assert not _calls_fmaf(inline) and _calls_fmaf(libm)  # the option acts: the default build has no fmaf call
    rng = np.random.default_rng(7)
    n = 20_000
    Y = rng.standard_normal((n, a.p)) * rng.choice([1e-3, 0.1, 1.0, 30.0], size=(n, 1))  # small to saturating
    R = rng.standard_normal((n, a.q)) * 0.5 if a.q else None
    got = HostLaw(a, library=inline).run(Y, R)
    want = HostLaw(a, library=libm).run(Y, R)
    assert got.tobytes() == want.tobytes()  # every record field (command, state, flags), bit for bit
