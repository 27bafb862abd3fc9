"""The most instructions a call of a loop-free function can execute, from the disassembly of the image.

On the soft-float cores (M0, M3) the float routines' paths (``gl_fmaf``, libgcc's ``__aeabi_*`` and ``__*sf2``,
``__clzsi2``) depend on their operands, so a step's count is not fixed by its path through the law's own code
(:mod:`gainlink.firmware.branches`). What bounds it is each routine's dearest path. A function whose control-flow
graph has no cycle has finitely many paths from its entry to a return, and the dearest one is the longest path of the
graph with each instruction weighing 1 and each call (``bl``, a tail call by ``b``, a conditional branch out of the
function) weighing its callee's own dearest call: that is what QEMU's instruction counter
(:mod:`gainlink.firmware.cost`) counts, every executed instruction once, a conditional branch whether taken or not.
A cycle (a loop whose trip count the graph does not bound), a jump through a register or a table, a call of a function
the disassembly does not hold, or recursion: no bound, and :class:`Unbounded` says where.

The bound covers every operand (it takes the worst side of every branch, feasible or not), so it may be above any
count a call reaches: it is a bound, not a measure.
"""

from __future__ import annotations

from dataclasses import dataclass

from .branches import Insn, branch_target, is_conditional_branch


class Unbounded(ValueError):
    """The function's graph has a cycle, an indirect jump, recursion or a callee outside the disassembly."""


@dataclass(frozen=True)
class Node:
    """An instruction of the graph: the function it calls (``bl``, a tail call) if any, and where it goes."""

    insn: Insn
    callee: str | None
    successors: tuple[int, ...]  # indices in the function's instruction list
    extra: int = 0  # a bounded loop's back edge: the instructions its body runs again, at most


def _base(mnemonic: str) -> str:
    return mnemonic.split(".")[0]


def _is_return(insn: Insn) -> bool:
    b, ops = _base(insn.mnemonic), insn.operands
    if b == "bx" and ops.strip() == "lr":
        return True
    if b == "ldr" and ops.startswith("pc, [sp]"):  # ldr.w pc, [sp], #8: the saved lr popped into pc
        return True
    if b in ("pop", "ldmia", "ldm") and "{" in ops:
        return "pc" in ops[ops.index("{") :]
    return False


def _indirect(insn: Insn) -> bool:
    b, ops = _base(insn.mnemonic), insn.operands
    if b in ("tbb", "tbh") or (b in ("bx", "blx") and branch_target(insn) is None and ops.strip() != "lr"):
        return True
    dest = ops.split(",")[0].strip()
    return dest == "pc" and not _is_return(insn) and b not in ("b", "bl")


class Bounds:
    """Each function's dearest call in a disassembly (:func:`gainlink.firmware.branches.disassemble`), memoised."""

    def __init__(self, funcs: dict[str, list[Insn]], given: dict[str, int] | None = None,
                 loops: dict[tuple[str, int], int] | None = None) -> None:  # fmt: skip
        """``given``: the cost of a call of these functions, taken as it is (a copy of a fixed length, measured);
        ``loops``: (function, address of a loop's backward conditional branch) -> the most times it is taken (argued
        by the caller): the loop's body, straight code from the branch's target to the branch, is then counted that
        many times more, and the back edge leaves the graph."""
        self.funcs = funcs
        self.bound: dict[str, int] = dict(given or {})
        self.loops = dict(loops or {})
        self._open: list[str] = []
        self._alias: dict[str, str] = {}
        # a symbol objdump does not label (an alias: __aeabi_fadd is __addsf3) by its address, and where each starts
        self._starts = sorted((i[0].address, f) for f, i in funcs.items() if i and not i[0].mnemonic.startswith("."))
        self._at = dict(self._starts)
        for t in (branch_target(i) for insns in funcs.values() for i in insns):
            if t and t[1] not in funcs and t[0] in self._at:
                self._alias[t[1]] = self._at[t[0]]

    def __call__(self, name: str) -> int:
        """The most instructions a call of ``name`` executes, callees included (:class:`Unbounded` if none)."""
        if name in self.bound:
            return self.bound[name]
        if name not in self.funcs and name in self._alias:
            return self(self._alias[name])
        if name in self._open:
            raise Unbounded(f"recursion: {' -> '.join([*self._open, name])}")
        if name not in self.funcs:
            raise Unbounded(f"{name} is called but not in the disassembly")
        self._open.append(name)
        try:
            self.bound[name] = longest(name, self.graph(name), self.weight)
        finally:
            self._open.pop()
        return self.bound[name]

    def weight(self, node: Node) -> int:
        """What executing ``node`` costs at most: 1, its callee's bound, a bounded loop's body again."""
        return 1 + (self(node.callee) if node.callee else 0) + node.extra

    def _callee(self, target: tuple[int, str]) -> str:
        return target[1] if target[1] in self.funcs else self._alias.get(target[1], target[1])

    def _next_function(self, address: int) -> str | None:
        """The function that starts next after ``address`` (where code that falls off its function's end goes)."""
        return next((f for a, f in self._starts if a > address), None)

    def graph(self, name: str) -> list[Node]:
        """``name``'s instructions as a graph."""
        insns = [i for i in self.funcs[name] if not i.mnemonic.startswith(".")]
        index = {i.address: k for k, i in enumerate(insns)}
        return [self._node(name, k, insn, insns, index) for k, insn in enumerate(insns)]

    def _node(self, name: str, k: int, insn: Insn, insns: list[Insn], index: dict[int, int]) -> Node:
        b = _base(insn.mnemonic)
        nxt = (k + 1,) if k + 1 < len(insns) else ()
        if _indirect(insn):
            raise Unbounded(f"{name}: a jump through a register or a table: {insn.text}")
        if _is_return(insn):
            return Node(insn, None, ())
        tgt = branch_target(insn)
        if b == "bl":
            if tgt is None:
                raise Unbounded(f"{name}: a call with no target: {insn.text}")
            return Node(insn, self._callee(tgt), nxt)
        inside = tgt is not None and tgt[0] in index
        if b == "b":
            if inside:
                return Node(insn, None, (index[tgt[0]],))
            return Node(insn, self._callee(tgt) if tgt else None, ())  # a tail call: the callee returns for us
        if is_conditional_branch(insn.mnemonic):
            if tgt is None:
                raise Unbounded(f"{name}: a conditional branch with no target: {insn.text}")
            if (name, insn.address) in self.loops and inside:
                return Node(insn, None, nxt, self._body(name, insns, index[tgt[0]], k) * self.loops[name, insn.address])
            if inside:
                return Node(insn, None, (*nxt, index[tgt[0]]))
            # a conditional tail call: the weight of its taken side, the longer, bounds both
            return Node(insn, self._callee(tgt), nxt)
        if not nxt:  # the last instruction and no return: it runs on into the next function (a tail call)
            return Node(insn, self._next_function(insn.address), ())
        return Node(insn, None, nxt)

    def _body(self, name: str, insns: list[Insn], head: int, end: int) -> int:
        """The instructions of a bounded loop's body, ``insns[head..end]``: straight code (no branch, call or return
        in it; nothing else in the function jumps into it but to its head), or :class:`Unbounded`."""
        if head > end:
            raise Unbounded(f"{name}: {insns[end].text} is not a backward branch")
        body = {i.address for i in insns[head + 1 : end + 1]}
        for k, i in enumerate(insns):
            b, tgt = _base(i.mnemonic), branch_target(i)
            in_body = head <= k < end
            if in_body and (b in ("b", "bl", "blx", "bx") or is_conditional_branch(i.mnemonic) or _is_return(i)):
                raise Unbounded(f"{name}: the loop ending at {insns[end].text} is not straight at {i.text}")
            if tgt is not None and tgt[0] in body:
                raise Unbounded(f"{name}: {i.text} jumps into the loop ending at {insns[end].text}")
        return end - head + 1


def longest(name: str, graph: list[Node], weight) -> int:
    """The heaviest path from ``graph``'s entry (its first node) to a node with no successor (``weight`` of a node:
    :meth:`Bounds.weight`), or :class:`Unbounded` naming a back edge of a cycle."""
    if not graph:
        raise Unbounded(f"{name} has no instructions")
    reach = reachable(graph, 0)
    for k in reach:
        node = graph[k]
        if (
            not node.successors
            and node.callee is None
            and not (_is_return(node.insn) or _base(node.insn.mnemonic) == "b")
        ):
            raise Unbounded(f"{name}: falls off its end at {graph[k].insn.text}")
    return heaviest(name, graph, reach, 0, weight)


def heaviest(name: str, graph: list[Node], nodes: set[int], start: int, weight, end: int | None = None) -> int:
    """The heaviest path from ``start`` through ``nodes`` (edges leaving them ignored) to a node with no successor in
    them, or to ``end`` when given (its successors ignored); :class:`Unbounded` if ``nodes`` hold a cycle."""
    inside = {k: tuple(s for s in graph[k].successors if s in nodes) if k != end else () for k in nodes}
    best: dict[int, int] = {}
    for k in reversed(_topological(name, graph, inside)):  # a node's successors come after it in the order
        tails = [best[s] for s in inside[k] if best[s] >= 0]
        if end is not None and k != end and not tails:
            best[k] = -1  # ``end`` is not reached from here
        else:
            best[k] = weight(graph[k]) + max(tails, default=0)
    if best[start] < 0:
        raise Unbounded(f"{name}: no path from {graph[start].insn.text} to {graph[end].insn.text}")
    return best[start]


def reachable(graph: list[Node], start: int) -> set[int]:
    """The nodes reached from ``start``."""
    seen, todo = {start}, [start]
    while todo:
        for s in graph[todo.pop()].successors:
            if s not in seen:
                seen.add(s)
                todo.append(s)
    return seen


def reaching(graph: list[Node], end: int, within: set[int]) -> set[int]:
    """The nodes of ``within`` from which ``end`` is reached inside ``within``."""
    preds: dict[int, list[int]] = {}
    for k in within:
        for s in graph[k].successors:
            preds.setdefault(s, []).append(k)
    seen, todo = {end}, [end]
    while todo:
        for p in preds.get(todo.pop(), []):
            if p not in seen and p in within:
                seen.add(p)
                todo.append(p)
    return seen


def _topological(name: str, graph: list[Node], inside: dict[int, tuple[int, ...]]) -> list[int]:
    """Kahn's order of ``inside``'s nodes (their successors given); a node left over is on a cycle."""
    indegree = dict.fromkeys(inside, 0)
    for succ in inside.values():
        for s in succ:
            indegree[s] += 1
    ready = [k for k, d in indegree.items() if d == 0]
    order = []
    while ready:
        k = ready.pop()
        order.append(k)
        for s in inside[k]:
            indegree[s] -= 1
            if indegree[s] == 0:
                ready.append(s)
    if len(order) != len(inside):
        left = set(inside) - set(order)
        back = [graph[k].insn.text for k in sorted(left) if any(s in left for s in inside[k])]
        raise Unbounded(f"{name} has a loop (its graph has a cycle through {back[0] if back else '?'})")
    return order
