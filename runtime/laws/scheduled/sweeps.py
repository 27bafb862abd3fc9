"""Periodic sweeps of sigma over sub-ranges of the envelope, judged by their monodromy matrices.

A sweep is a triangle: from ``a`` up to ``b`` and back at ``step`` per sample (samples ``a + k step``, the top
clipped to ``b``). Its ends are every pair of :func:`sweep_nodes`. All sweeps that start at one node visit the same
samples on the way up and down, so their transitions share their factors: walking the ends upwards, the product up
(``A_m ... A_1``) and the product down (``A_0 A_1 ... A_m``) are extended by the samples in between, and each
sweep's monodromy matrix is ``down · L(b) · up``, whose eigenvalues are those of ``L(b) · up · down``. The sweeps
from one node cost one pass up to the envelope's top instead of one per end.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

import numpy as np

SWEEP_PIECES = 8  # the envelope is cut in this many equal parts for the ends of the sweeps


def sweep_nodes(points: np.ndarray) -> np.ndarray:
    """The ends of the sweeps: the schedule's points, the envelope cut in :data:`SWEEP_PIECES` equal parts, and the
    middle of each interval (sorted, without repeats)."""
    pts = np.asarray(points, dtype=float)
    lo, hi = float(pts[0]), float(pts[-1])
    nodes = np.unique(np.concatenate([pts, np.linspace(lo, hi, SWEEP_PIECES + 1), (pts[:-1] + pts[1:]) / 2]))
    keep = np.concatenate([[True], np.diff(nodes) > 1e-9 * (hi - lo)])
    return nodes[keep]


def product(mats: np.ndarray) -> tuple[np.ndarray, float]:
    """The product of the (K, N, N) matrices in time order (later on the left), multiplied in pairs level by
    level, as a matrix of unit Frobenius norm and its log-norm (-inf: the product vanishes)."""
    mat, log_scale = products(mats[None])
    return mat[0], float(log_scale[0])


def products(stack: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`product` of each of the (S, K, N, N) sequences at once: (S, N, N) and (S,) log-norms."""
    S, _, N, _ = stack.shape
    log_scale = np.zeros(S)
    if stack.shape[1] == 0:
        return np.broadcast_to(np.eye(N), (S, N, N)).copy(), log_scale
    while stack.shape[1] > 1:
        if stack.shape[1] % 2:
            stack = np.concatenate([stack, np.broadcast_to(np.eye(N), (S, 1, N, N))], axis=1)
        stack = stack[:, 1::2] @ stack[:, 0::2]
        norms = np.sqrt(np.einsum("skab,skab->sk", stack, stack))
        log_scale += np.sum(np.log(np.where(norms == 0.0, 1.0, norms)), axis=1)
        log_scale[np.any(norms == 0.0, axis=1)] = -np.inf
        stack = stack / np.where(norms == 0.0, 1.0, norms)[:, :, None, None]
    return stack[:, 0], log_scale


def radius(mat: np.ndarray, log_scale: float) -> float:
    """Spectral radius of ``exp(log_scale) · mat``."""
    rho = float(np.max(np.abs(np.linalg.eigvals(mat)))) if np.isfinite(log_scale) else 0.0
    return 0.0 if rho == 0.0 else float(np.exp(min(np.log(rho) + log_scale, 700.0)))


def sweep_radii(loops_at: Callable[[np.ndarray], np.ndarray], nodes: np.ndarray, step: float) -> np.ndarray:
    """Monodromy spectral radius of the triangle between every pair of ``nodes`` (``itertools.combinations``
    order) at ``step`` per sample; ``loops_at(sigmas)`` gives the loop's (K, N, N) matrices."""
    out: list[float] = []
    for i in range(len(nodes) - 1):
        out += _from(loops_at, float(nodes[i]), np.asarray(nodes[i + 1 :], dtype=float), step)
    return np.array(out)


def _from(loops_at, a: float, ends: np.ndarray, step: float) -> list[float]:
    """The sweeps from ``a`` to each of ``ends`` (increasing): ``n`` samples up, the last one at the end."""
    counts = [max(1, int(np.ceil((b - a) / step))) for b in ends]
    lattice = loops_at(a + step * np.arange(counts[-1]))  # A_0 (at a) ... A_{n-1}
    segs = _segments(lattice, counts)  # the samples between one end and the next, padded with identities
    seg_up, up_logs = products(segs)
    seg_down, down_logs = products(segs.transpose(0, 1, 3, 2))
    up, up_log = np.eye(lattice.shape[1]), 0.0  # A_m ... A_1
    down, down_log = _normed(lattice[0], 0.0)  # A_0 A_1 ... A_m
    out = []
    for j, top in enumerate(loops_at(ends)):
        up, up_log = _times(seg_up[j], up_logs[j], up, up_log)
        down, down_log = _times(down, down_log, seg_down[j].T, down_logs[j])
        out.append(radius(*_times(top, 0.0, *_times(up, up_log, down, down_log))))
    return out


def _segments(lattice: np.ndarray, counts: list[int]) -> np.ndarray:
    """(S, K, N, N): for each end, the lattice samples ``A_{m+1} ... A_{n-1}`` it adds to the previous end's."""
    bounds = [1] + counts
    size = max(1, max(b - a for a, b in itertools.pairwise(bounds)))
    N = lattice.shape[1]
    segs = np.broadcast_to(np.eye(N), (len(counts), size, N, N)).copy()
    for j, (a, b) in enumerate(itertools.pairwise(bounds)):
        segs[j, : b - a] = lattice[a:b]
    return segs


def _times(x: np.ndarray, x_log: float, y: np.ndarray, y_log: float) -> tuple[np.ndarray, float]:
    return _normed(x @ y, x_log + y_log)


def _normed(mat: np.ndarray, log_scale: float) -> tuple[np.ndarray, float]:
    norm = float(np.linalg.norm(mat))
    if norm == 0.0 or not np.isfinite(log_scale):
        return np.zeros_like(mat), -np.inf
    return mat / norm, log_scale + float(np.log(norm))
