"""Oracles independent of the code under test, shared by several test modules."""

from __future__ import annotations

import numpy as np
from gainlink.proof.reference import ReferenceLoop
from gainlink.shipping import artifact as artifact_mod
from gainlink.shipping.artifact import Artifact


def jacobian_poles(a: Artifact) -> np.ndarray:
    """Compensator poles by probing the float64 law itself (an oracle independent of gainlink.synthesis.compensator):
    with limits out of reach the map (xh, z) -> next (xh, z) at the operating point (y = y_op, r = Ci y_op)
    is linear; its columns are the images of unit states."""
    data = dict(a.data)
    data["u_min"], data["u_max"] = [-1e300] * a.m, [1e300] * a.m
    wide = artifact_mod.from_dict(artifact_mod.seal(data))
    N = a.n + a.q
    A = np.zeros((N, N))
    for j in range(N):
        law = ReferenceLoop(wide)
        e = np.eye(N)[j]
        law.xh, law.z = e[: a.n].copy(), e[a.n :].copy()
        law.step(a.y_op, a.Ci @ a.y_op)
        A[:, j] = np.concatenate([law.xh, law.z])
    return np.linalg.eigvals(A)
