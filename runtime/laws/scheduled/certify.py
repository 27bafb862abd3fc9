"""The searches for the scheduled loop's Lyapunov certificates (:mod:`.lyapunov`), refined to a stated budget.

- **Frozen** (:func:`prove_frozen`): each interval starts as one piece; a piece whose own ``P`` is not proved is
  halved, down to :data:`FROZEN_DEPTH` halvings. A piece that cannot be proved at that depth, or when the budget
  is spent, is where the design is refused.
- **Any rate** (:func:`common`): one ``P`` on the frozen proof's pieces.
- **A rate** (:func:`certify_rate`): rate 0 first (a ``P(sigma)`` for the loop frozen anywhere, continuous
  across the pieces), on :data:`START_PIECES` pieces per interval with ``P``'s nodes at their ends. A certificate
  for rho holds for every slower rate (it covers fewer pairs of sigmas), though stability is not monotone in rho;
  so the rate is bisected in log scale below the falsifier's first growing rate, to :data:`RATE_TOLERANCE`. Where a
  rate is not proved the LMI's dual says which pieces and which of ``P``'s node intervals bind: the pieces holding
  :data:`REFINE_SHARE` of it are halved and those node intervals get a node (locally, never uniformly,
  :func:`refine`); the rate is tried again there and, once proved, :data:`STEP_UP` faster, :data:`REFINEMENTS`
  refinements in all. ``P``'s nodes are a partition of their own, coarser than the pieces. Refining never loses a
  proved rate: a half's hull lies inside its piece's, and a ``P`` on fewer nodes is one on more.

The budget is CPU seconds of this process (the searches stop starting LMIs once it is spent; what is proved by
then stands), recorded with what was done.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np

from ...errors import DesignError
from .hull import LoopHull, Piece
from .lyapunov import Attempt, Certificate, common_certificate, frozen_piece, rate_attempt

FROZEN_DEPTH = 10  # halvings of an interval before the frozen proof gives up on a piece (1/1024 of it)
RATE_TOLERANCE = 1.1  # the bisection stops when the slowest rate not proved is within 10 % of the fastest proved
STEP_UP = 1.25  # once a refined rate is proved, the next tried is this factor faster
REFINEMENTS = 4  # refinements in all, each where a rate was not proved (an LMI's cost grows with the pieces)
REFINE_SHARE = 0.5  # a refinement halves the pieces holding this share of the dual (the most binding first)
MAX_PIECES = 96  # the rate search never refines past this many pieces (an LMI's cost grows with them)
MIN_RATE = 1e-6  # the search gives up below this fraction of the rate it starts under
START_PIECES = 4  # pieces per interval the rate search starts from (the frozen proof's where it split more)


@dataclass
class Budget:
    """``seconds`` of CPU time from when it was made."""

    seconds: float
    start: float = field(default_factory=time.process_time)

    def spent(self) -> float:
        """CPU seconds used so far."""
        return time.process_time() - self.start

    def out(self) -> bool:
        """True once the budget is spent."""
        return self.spent() >= self.seconds


@dataclass(frozen=True)
class RateSearch:
    """What the rate search did: the fastest proved certificate (None: none), the slowest rate tried and not
    proved (None: none), the pieces it ended on, the LMIs it solved, whether the budget stopped it, and the piece
    holding most of the dual at the last rate not proved."""

    certificate: Certificate | None
    unproved: float | None
    pieces: list[Piece]
    solves: int
    budget_spent: bool
    binding: Piece | None


def prove_frozen(hull: LoopHull, budget: Budget, *, sigma: str) -> tuple[list[Piece], list[Certificate]]:
    """Every piece's frozen certificate, halving pieces that are not proved; DesignError naming the first
    piece that cannot be (at :data:`FROZEN_DEPTH`, or with the budget spent)."""
    todo = hull.uniform(1)
    done: list[tuple[Piece, Certificate]] = []
    while todo:
        piece = todo.pop(0)
        cert = frozen_piece(hull, piece).certificate
        if cert is not None:
            done.append((piece, cert))
            continue
        if piece.depth >= FROZEN_DEPTH or budget.out():
            why = "within the budget" if budget.out() else f"on pieces of 1/{2**FROZEN_DEPTH} of an interval"
            raise DesignError(
                f"no Lyapunov function proves the scheduled law stable frozen at every {piece.describe(sigma)} "
                f"({why}): add a point there"
            )
        todo[:0] = hull.split(piece)
    done.sort(key=lambda pc: pc[0].lo)
    return [p for p, _ in done], [c for _, c in done]


def common(hull: LoopHull, pieces: list[Piece]) -> Certificate | None:
    """One ``P`` for the loop whatever sigma does, proved on ``pieces``; None when none is found."""
    return common_certificate(hull, pieces).certificate


def start_pieces(hull: LoopHull, frozen: list[Piece]) -> list[Piece]:
    """The frozen proof's pieces, each interval cut in at least :data:`START_PIECES`."""
    out: list[Piece] = []
    for p in frozen:
        stack = [p]
        while stack:
            q = stack.pop(0)
            if (q.b - q.a) > Fraction(1, START_PIECES):
                stack[:0] = hull.split(q)
            else:
                out.append(q)
    return out


def _top(weights: np.ndarray) -> set[int]:
    """The indices holding :data:`REFINE_SHARE` of ``weights``, heaviest first (at least one)."""
    order = np.argsort(-weights, kind="stable")
    share = np.cumsum(weights[order])
    return set(order[: int(np.searchsorted(share, REFINE_SHARE * share[-1])) + 1].tolist())


def refine(hull: LoopHull, pieces: list[Piece], nodes: list[Fraction], attempt: Attempt,
           step: Fraction) -> tuple[list[Piece], list[Fraction]] | None:  # fmt: skip
    """Halve the pieces holding :data:`REFINE_SHARE` of the dual, and add a node inside the node intervals holding
    that share (at the piece end nearest their middle, when one is inside and leaves both sides at least ``step``
    wide: nodes closer than one step of sigma multiply the inequalities); None past :data:`MAX_PIECES`."""
    chosen = _top(attempt.piece_weights)
    if len(pieces) + len(chosen) > MAX_PIECES:
        return None
    finer: list[Piece] = []
    for j, p in enumerate(pieces):
        finer += list(hull.split(p)) if j in chosen else [p]
    ends = [p.hi for p in finer[:-1]]
    added = []
    for k in sorted(_top(attempt.node_weights)):
        inside = [e for e in ends if nodes[k] + step <= e <= nodes[k + 1] - step and nodes[k] < e < nodes[k + 1]]
        if inside:
            mid = (nodes[k] + nodes[k + 1]) / 2
            added.append(min(inside, key=lambda e: (abs(e - mid), e)))
    return finer, sorted(set(nodes) | set(added))


def certify_rate(hull: LoopHull, pieces: list[Piece], *, Ts: float, hi: float, budget: Budget) -> RateSearch:
    """The fastest rate below ``hi`` a ``P(sigma)`` proves (module docstring): bisection on the starting pieces;
    then, :data:`REFINEMENTS` times at most, refined where the slowest rate not proved binds, tried again there
    and, once proved, :data:`STEP_UP` faster until a rate is not proved."""
    search = _Search(hull, pieces, [p.lo for p in pieces] + [pieces[-1].hi], Ts)
    frozen = search.attempt(0.0)
    while frozen.certificate is None:  # rate 0 first: a P(sigma) for the loop frozen anywhere
        if search.refinements >= REFINEMENTS or budget.out() or not search.refine(frozen):
            return search.result(None, frozen, budget)
        frozen = search.attempt(0.0)
    best, failing = search.bracket(hi, budget)
    while failing is not None and search.refinements < REFINEMENTS and not budget.out() and search.refine(failing):
        attempt = search.attempt(failing.rate)
        while attempt.certificate is not None:
            best = attempt.certificate
            faster = attempt.rate * STEP_UP
            if faster >= hi or budget.out():
                return search.result(best, None, budget)
            attempt = search.attempt(faster)
        failing = attempt
    return search.result(best, failing, budget)


@dataclass
class _Search:
    """The rate search's pieces and ``P``'s nodes (refined as it goes) and what it has solved."""

    hull: LoopHull
    pieces: list[Piece]
    nodes: list[Fraction]
    Ts: float
    solves: int = 0
    refinements: int = 0

    def bracket(self, hi: float, budget: Budget) -> tuple[Certificate | None, Attempt | None]:
        """Bisection (log scale) below ``hi`` on the pieces as they are, to :data:`RATE_TOLERANCE`: the fastest
        certificate and the attempt at the slowest rate not proved; downwards by factors of four until a rate is
        proved (not below :data:`MIN_RATE` of ``hi``)."""
        lo, best, failing, floor = 0.0, None, None, hi * MIN_RATE
        rate = hi / 2
        while not budget.out() and rate >= floor:
            attempt = self.attempt(rate)
            if attempt.certificate is not None:
                lo, best = rate, attempt.certificate
            else:
                hi, failing = rate, attempt
            if lo > 0 and hi / lo <= RATE_TOLERANCE:
                break
            rate = float(np.sqrt(lo * hi)) if lo > 0 else hi / 4
        return best, failing

    def attempt(self, rate: float) -> Attempt:
        """The LMI at ``rate`` on the pieces and nodes as they are, re-checked."""
        self.solves += 1
        step = Fraction(self.Ts) * Fraction(rate)
        return rate_attempt(self.hull, self.pieces, self.nodes, step=step, rate=rate)

    def refine(self, attempt: Attempt) -> bool:
        """Refine where ``attempt`` binds; False when that would pass :data:`MAX_PIECES`."""
        finer = refine(self.hull, self.pieces, self.nodes, attempt, Fraction(self.Ts) * Fraction(attempt.rate or 0.0))
        if finer is None:
            return False
        self.pieces, self.nodes = finer
        self.refinements += 1
        return True

    def result(self, best: Certificate | None, failing: Attempt | None, budget: Budget) -> RateSearch:
        binding = None if failing is None else self.pieces[int(np.argmax(failing.piece_weights))]
        return RateSearch(best, None if failing is None else failing.rate, self.pieces, self.solves, budget.out(),
                          binding)  # fmt: skip
