"""Which conditional branches of a compiled step depend on the law's numbers: the disassembly half of a cost proof.

The instructions a call of a function executes are fixed by the path it takes, and the path by the outcomes of its
conditional branches. A branch is *fixed* when its condition comes only from immediates, the call's pointer
arguments, addresses loaded through them, and the outcomes of the branches taken before it (a loop's counter, an
end-of-array or NULL test, a flag that only repeats an earlier branch's decision): given the outcomes of the *data*
branches, those decided by the law's numbers (a float compare, a solver's convergence flag), the path is determined.
This module reads the ELF the cost is measured on (``arm-none-eabi-objdump -d``), follows the function and every
function it calls, and classifies every conditional branch by where its condition comes from, with a forward
data-flow over each function's control-flow graph (the registers and the APSR flags). A predicated instruction of an
IT block joins its condition's origins into what it writes, except on the edges of a branch on that same condition
with the flags unchanged since: there it runs or not as the edge decides (``ite hi; movhi r7, #1; movls r7, #0;
bhi``: r7 is 0 on the fall-through). Origins of data:

- ``float``: the flags of a float compare (``vmrs APSR_nzcv, fpscr``), or a word moved from a float register
  (``vmov rN, sM``);
- ``bits``: a word loaded from memory that then went through a bit or multiply operation (how integer code would test
  a float's bits);
- ``ret:<f>``: what ``f`` returned.

The premise, stated wherever the result is printed: on the hard-float cores the law's numbers live in the FPU's
registers, and a word an integer register loads is an address or a copy unless a bit or multiply operation works on
it (then it is ``bits``). A load, an add of an immediate or another address, and a compare keep a word an address.
A callee is analysed with the origins its call sites give r0..r3. The C library's copies (:data:`COPIES`) are not
followed: their paths depend on their addresses and length, and a call passing them data is reported.

Soft-float cores call the float routines (``gl_fmaf``, ``__aeabi_*``) whose paths depend on the operands: there the
analysis reports those calls and proves nothing (:attr:`Analysis.soft_float`).
"""

from __future__ import annotations

import re
import subprocess
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

from .size import tool

#: The C library's copies: their paths depend on their addresses' alignment and their length only, so they are not
#: followed; a call passing them the law's numbers (an address or a length computed from data) is reported. They
#: return their destination (an address).
COPIES = frozenset({"memcpy", "memmove", "memset", "__aeabi_memcpy", "__aeabi_memmove", "__aeabi_memset"})
#: Calls that make a count depend on float operands (the soft-float cores).
SOFT_FLOAT = re.compile(r"^(gl_fmaf|__aeabi_[fd]\w*|__(add|sub|mul|div)[sd]f3|__(eq|ne|lt|le|gt|ge|un)[sd]f2)$")

_FUNC = re.compile(r"^([0-9a-f]+) <(\S+)>:$")
_INSN = re.compile(r"^\s*([0-9a-f]+):\s+((?:[0-9a-f]{4,8}\s)+)\s*(\S+)(?:\s+(.*))?$")
_REG = re.compile(r"\b(r1[0-2]|r[0-9]|sb|sl|fp|ip|sp|lr|pc)\b")
_TARGET = re.compile(r"^([0-9a-f]+) <([^>+]+)(?:\+0x[0-9a-f]+)?>")
_CONDS = ("eq", "ne", "cs", "hs", "cc", "lo", "mi", "pl", "vs", "vc", "hi", "ls", "ge", "lt", "gt", "le")
_ALIAS = {"sb": "r9", "sl": "r10", "fp": "r11", "ip": "r12"}
_BIT_OPS = ("and", "orr", "orn", "eor", "bic", "mvn", "lsl", "lsr", "asr", "ror", "rrx", "mul", "mla", "mls", "ubfx",
            "sbfx", "bfi", "bfc", "clz", "rev", "rbit", "uxt", "sxt", "umull", "smull", "umlal", "smlal", "sdiv",
            "udiv", "usat", "ssat", "sel")  # fmt: skip
_COMPARES = ("cmp", "cmn", "tst", "teq")
_NORM = {"hs": "cs", "lo": "cc"}
_OPPOSITE = {"eq": "ne", "ne": "eq", "cs": "cc", "cc": "cs", "mi": "pl", "pl": "mi", "vs": "vc", "vc": "vs",
             "hi": "ls", "ls": "hi", "ge": "lt", "lt": "ge", "gt": "le", "le": "gt"}  # fmt: skip
_NO_WRITE = ("str", "stm", "push", "vst", "vpush", "nop", "dmb", "dsb", "isb", "bkpt", "svc", "cps", "msr", "pld")


@dataclass(frozen=True)
class Insn:
    """One instruction of the disassembly."""

    address: int
    mnemonic: str
    operands: str

    @property
    def text(self) -> str:
        return f"{self.address:x}: {self.mnemonic} {self.operands}".strip()


@dataclass(frozen=True)
class Branch:
    """A conditional branch and the origins of what decides it (empty: the same outcome on every call)."""

    function: str
    insn: Insn
    origins: frozenset[str]  # MEM alone: an address (module docstring)
    taken: int
    fallthrough: int

    @property
    def data(self) -> bool:
        """Whether the law's numbers may decide it."""
        return _is_data(self.origins)


@dataclass
class Analysis:
    """Every conditional branch of ``root`` and its callees, the calls that pass data, the soft-float calls."""

    root: str
    functions: list[str]
    branches: list[Branch]
    calls: dict[int, str] = field(default_factory=dict)  # call or tail-call address -> callee
    data_calls: list[str] = field(default_factory=list)
    indirect: list[str] = field(default_factory=list)  # a jump through a register or a table: no path is known
    soft_float: list[str] = field(default_factory=list)

    def data_branches(self, function: str | None = None) -> list[Branch]:
        """The branches the law's numbers may decide (in ``function``, or anywhere)."""
        return [b for b in self.branches if b.data and (function is None or b.function == function)]


def disassemble(elf: Path) -> dict[str, list[Insn]]:
    """Every function of ``elf``'s code, its instructions in address order (``objdump -d``)."""
    out = subprocess.run([tool("arm-none-eabi-objdump"), "-d", str(elf)], capture_output=True, text=True, check=True)
    return parse(out.stdout)


def parse(text: str) -> dict[str, list[Insn]]:
    """Functions and instructions from ``objdump -d`` text (literal pools' ``.word`` lines are kept: never reached)."""
    funcs: dict[str, list[Insn]] = {}
    current: list[Insn] | None = None
    for line in text.splitlines():
        m = _FUNC.match(line)
        if m:
            current = funcs.setdefault(m.group(2), [])
            continue
        i = _INSN.match(line)
        if i and current is not None:
            operands = (i.group(4) or "").split("@")[0].split(";")[0].strip()
            current.append(Insn(int(i.group(1), 16), i.group(3), operands))
    return funcs


def _base(mnemonic: str) -> str:
    """The mnemonic without its width qualifier (``.n``/``.w``)."""
    return mnemonic.split(".")[0]


def is_conditional_branch(mn: str) -> bool:
    b = _base(mn)
    return b in ("cbz", "cbnz") or (len(b) == 3 and b[0] == "b" and b[1:] in _CONDS)


def branch_target(insn: Insn) -> tuple[int, str] | None:
    """Where a direct branch or call goes: (address, symbol), or None (through a register)."""
    ops = insn.operands.split(",")[-1].strip()
    m = _TARGET.match(ops)
    return (int(m.group(1), 16), m.group(2)) if m else None


def _regs(operands: str) -> list[str]:
    return [_ALIAS.get(r, r) for r in _REG.findall(operands)]


def _is_return(insn: Insn) -> bool:
    b = _base(insn.mnemonic)
    if b == "bx" and "lr" in insn.operands:
        return True
    if b in ("pop", "ldmia", "ldm"):
        return "{" in insn.operands and "pc" in insn.operands[insn.operands.index("{") :]
    return b == "ldr" and _regs(insn.operands)[:1] == ["pc"]


State = tuple[dict[str, frozenset[str]], frozenset[str]]  # register origins, flag origins


class _Flow:
    """The forward data-flow of one function (module docstring)."""

    def __init__(self, name: str, insns: list[Insn]) -> None:
        self.name = name
        self.insns = [i for i in insns if not i.mnemonic.startswith(".")]
        self.index = {i.address: k for k, i in enumerate(self.insns)}
        self.predicated = self._it_blocks()
        self.calls: dict[int, str] = {}
        self.sites: dict[int, tuple[str, dict[str, frozenset[str]]]] = {}  # call -> callee, origins of r0..r3
        self.indirect = sorted(
            f"{name} {i.text}"
            for i in self.insns
            if _base(i.mnemonic) in ("tbb", "tbh")
            or (_base(i.mnemonic) in ("bx", "blx") and branch_target(i) is None and "lr" not in i.operands)
            or (_base(i.mnemonic).startswith("mov") and _regs(i.operands)[:1] == ["pc"])
        )

    def _it_blocks(self) -> set[int]:
        out: set[int] = set()
        for k, insn in enumerate(self.insns):
            if _base(insn.mnemonic).startswith("it"):
                n = len(_base(insn.mnemonic)) - 1  # it, itt, ite, ittt...: 1 + the letters after "it"
                out.update(i.address for i in self.insns[k + 1 : k + 1 + n])
        return out

    def successors(self, k: int) -> list[int]:
        insn = self.insns[k]
        nxt = [k + 1] if k + 1 < len(self.insns) else []
        b = _base(insn.mnemonic)
        if _is_return(insn) and insn.address not in self.predicated:
            return []
        tgt = branch_target(insn)
        if b == "b" and insn.address not in self.predicated:
            if tgt and tgt[0] in self.index:
                return [self.index[tgt[0]]]
            if tgt:
                self.calls[insn.address] = tgt[1]  # a tail call
            return []
        if is_conditional_branch(insn.mnemonic) and tgt and tgt[0] in self.index:
            return [*nxt, self.index[tgt[0]]]
        return nxt

    def step(self, insn: Insn, state: State, known: str | None = None) -> State:
        """What ``insn`` does to the origins of the registers and the flags (``known``: the condition the flags are
        known to satisfy on this path, which decides a predicated instruction of that condition or its opposite)."""
        regs, flags = dict(state[0]), state[1]
        b, ops = _base(insn.mnemonic), insn.operands
        pred = insn.address in self.predicated
        if pred and b[-2:] in _CONDS and not b.startswith("it"):
            cond = _NORM.get(b[-2:], b[-2:])
            b = b[:-2]
            if known is not None and cond == known:
                pred = False  # it runs, decided by the branch the path took
            elif known is not None and cond == _OPPOSITE[known]:
                return regs, flags  # it does not run
        rs = _regs(ops)
        extra = flags if pred else frozenset()  # a predicated write: its condition decides it
        if b == "vmrs":
            return regs, frozenset({"float"}) if "APSR" in ops else flags
        if b in ("bl", "blx"):
            return self._call(insn, regs)
        if b.startswith("v"):
            for r in _leading_int_regs(ops) if b == "vmov" else []:
                regs[r] = frozenset({"float"}) | extra | (regs.get(r, frozenset()) if pred else frozenset())
            return regs, flags
        if b in _COMPARES:
            return regs, frozenset().union(*(regs.get(r, frozenset()) for r in rs)) | extra
        if b == "b" or is_conditional_branch(b):
            tgt = branch_target(insn)
            if tgt and tgt[0] not in self.index:  # a tail call (conditional or not): the callee gets these arguments
                self.calls[insn.address] = tgt[1]
                self.sites[insn.address] = (tgt[1], {f"r{i}": regs.get(f"r{i}", frozenset()) for i in range(4)})
            return regs, flags
        if b.startswith(_NO_WRITE) or is_conditional_branch(b) or b == "bx" or b.startswith("it"):
            return regs, flags
        if b.startswith(("ldr", "ldm", "pop")):
            for r in _load_dests(b, ops, rs):
                regs[r] = frozenset({MEM}) | extra | (regs.get(r, frozenset()) if pred else frozenset())
            return regs, flags
        return _alu(b, rs, regs, flags, extra, pred)

    def _call(self, insn: Insn, regs: dict[str, frozenset[str]]) -> State:
        callee = (branch_target(insn) or (0, "?"))[1]
        self.calls[insn.address] = callee
        self.sites[insn.address] = (callee, {f"r{i}": regs.get(f"r{i}", frozenset()) for i in range(4)})
        ret = frozenset() if callee in COPIES else frozenset({f"ret:{callee}"})
        for r in ("r0", "r1", "r2", "r3", "r12", "lr"):
            regs[r] = ret
        return regs, frozenset()

    def _targets(self) -> set[int]:
        if not hasattr(self, "_target_set"):
            self._target_set = {t[0] for t in map(branch_target, self.insns) if t}
        return self._target_set

    def _refine(self, k: int, succ: int, states: dict[int, State]) -> State | None:
        """The state on the edge from the branch ``k`` to ``succ``: the IT blocks since the flags were set, on the
        straight code before it, re-run with the condition the edge decides (``ite hi; movhi r7, #1; movls r7, #0;
        bhi``: r7 is 0 on the fall-through, whatever the float compare said; the branch itself is the data branch).
        None when the code since the flags were set is not straight."""
        cond = _base(self.insns[k].mnemonic)[1:]
        if cond not in _CONDS:
            return None  # cbz / cbnz
        cond = _NORM.get(cond, cond)
        known = cond if succ != k + 1 else _OPPOSITE[cond]
        j = k - 1
        while j >= 0 and not _sets_flags(self.insns[j], self.predicated):
            insn = self.insns[j]
            if (
                insn.address in self._targets()
                or _base(insn.mnemonic) in ("b", "bl", "blx", "bx")
                or is_conditional_branch(insn.mnemonic)
            ):
                return None
            j -= 1
        if j < 0 or j + 1 not in states:
            return None
        state = states[j + 1]
        for i in range(j + 1, k):
            state = self.step(self.insns[i], state, known)
        return state

    def run(self, entry: dict[str, frozenset[str]]) -> list[Branch]:
        """The fixed point from the entry state; every conditional branch with the origins that decide it."""
        if not self.insns:
            return []
        states: dict[int, State] = {0: (entry, frozenset())}
        work = deque([0])
        while work:
            k = work.popleft()
            out = self.step(self.insns[k], states[k])
            for s in self.successors(k):
                edge = self._refine(k, s, states) if is_conditional_branch(self.insns[k].mnemonic) else None
                merged = _join(states.get(s), edge or out)
                if merged != states.get(s):
                    states[s] = merged
                    work.append(s)
        branches = []
        for k, insn in enumerate(self.insns):
            if k not in states or not is_conditional_branch(insn.mnemonic):
                continue
            regs, flags = states[k]
            b = _base(insn.mnemonic)
            origins = regs.get(_regs(insn.operands)[0], frozenset()) if b in ("cbz", "cbnz") else flags
            tgt = branch_target(insn)
            nxt = self.insns[k + 1].address if k + 1 < len(self.insns) else -1
            branches.append(Branch(self.name, insn, origins, tgt[0] if tgt else -1, nxt))
        return branches


MEM = "mem"  # a loaded word: an address or a copy, not data (module docstring)


def _is_data(origins: frozenset[str]) -> bool:
    return bool(origins - {MEM})


def _alu(b: str, rs: list[str], regs: dict[str, frozenset[str]], flags: frozenset[str], extra: frozenset[str],
         pred: bool) -> State:  # fmt: skip
    """An integer operation: its destination (the first register) takes its sources' origins; a bit or multiply
    operation on a loaded word makes it ``bits``; an ``S`` form outside an IT block sets the flags."""
    if not rs:
        return regs, flags
    dest, srcs = rs[0], rs[1:]
    if (len(rs) == 1 and not b.startswith("mov")) or b.startswith(("movt", "bfi", "bfc")):
        srcs = rs
    origin = frozenset().union(*(regs.get(r, frozenset()) for r in srcs))
    if b.startswith(("adc", "sbc", "rrx")):
        origin |= flags
    if b.startswith(_BIT_OPS) and MEM in origin:
        origin |= {"bits"}
    regs[dest] = origin | extra | (regs.get(dest, frozenset()) if pred else frozenset())
    sets_flags = not pred and b.endswith("s") and b not in ("mls", "mrs", "cps")
    return regs, (regs[dest] if sets_flags else flags)


def _sets_flags(insn: Insn, predicated: set[int]) -> bool:
    """Whether ``insn`` writes the APSR flags: a compare, ``vmrs APSR_nzcv``, an ``S`` form outside an IT block."""
    b = _base(insn.mnemonic)
    if b in _COMPARES or (b == "vmrs" and "APSR" in insn.operands) or b in ("bl", "blx"):
        return True
    if insn.address in predicated or b.startswith(("v", "it")) or is_conditional_branch(b):
        return False
    return b.endswith("s") and b not in ("mls", "mrs", "cps") and not b.startswith(("ldr", "ldm", "pop", "str", "stm"))


def _leading_int_regs(ops: str) -> list[str]:
    """The integer registers a ``vmov`` writes: those before its first float register (``vmov r0, r1, d0``)."""
    out = []
    for part in (p.strip() for p in ops.split(",")):
        if not _REG.fullmatch(part):
            break
        out.append(_ALIAS.get(part, part))
    return out


def _load_dests(b: str, ops: str, rs: list[str]) -> list[str]:
    """The registers a load writes (its base's writeback keeps the base an address)."""
    if "{" in ops:  # ldm / pop: the list
        return [_ALIAS.get(r, r) for r in _REG.findall(ops[ops.index("{") :]) if r != "pc"]
    n = 2 if b.startswith("ldrd") else 1
    return [r for r in rs[:n] if r != "pc"]


def _join_regs(a: dict[str, frozenset[str]], b: dict[str, frozenset[str]]) -> dict[str, frozenset[str]]:
    regs = dict(a)
    for r, o in b.items():
        regs[r] = regs.get(r, frozenset()) | o
    return regs


def _join(a: State | None, b: State) -> State:
    return b if a is None else (_join_regs(a[0], b[0]), a[1] | b[1])


def analyse(elf: Path, root: str) -> Analysis:
    """Every conditional branch of ``root`` in ``elf`` and of every function it calls or tail-calls, classified."""
    return analyse_text(disassemble(elf), root)


def analyse_text(funcs: dict[str, list[Insn]], root: str) -> Analysis:
    """:func:`analyse` on a parsed disassembly (:func:`parse`)."""
    if root not in funcs:
        raise KeyError(f"no function {root} in the disassembly")
    entries: dict[str, dict[str, frozenset[str]]] = {root: {}}
    flows: dict[str, _Flow] = {}
    runs: dict[str, list[Branch]] = {}
    changed = True
    while changed:  # until no call site gives a callee's arguments new origins (the call graph has no cycle here)
        changed = False
        for name in list(entries):
            flow = flows[name] = _Flow(name, funcs[name])
            runs[name] = flow.run(entries[name])
            for callee, args in flow.sites.values():
                if callee not in funcs or callee in COPIES:
                    continue
                old = entries.get(callee)
                new = _join_regs(old or {}, args)
                if new != old:
                    entries[callee] = new
                    changed = True
    order = list(entries)
    result = Analysis(root=root, functions=order, branches=[b for f in order for b in runs[f]])
    for name in order:
        result.calls.update(flows[name].calls)
        result.indirect += flows[name].indirect
        for callee in flows[name].calls.values():
            if SOFT_FLOAT.match(callee):
                result.soft_float.append(f"{name} calls {callee}")
        for callee, args in flows[name].sites.values():
            used = ("r0", "r1", "r2") if callee in COPIES else tuple(args)  # a copy takes three arguments
            if (callee not in funcs or callee in COPIES) and any(_is_data(args[r]) for r in used):
                result.data_calls.append(f"{name} passes data to {callee}, which is not followed")
    result.soft_float = sorted(set(result.soft_float))
    return result


def straight_call(funcs: dict[str, list[Insn]], function: str, address: int, limit: int = 24) -> str | None:
    """The first function called (``bl``) or tail-called (``b`` out of ``function``) on the straight path from
    ``address`` in ``function``, before any other branch: where that side of a branch goes."""
    insns = [i for i in funcs[function] if not i.mnemonic.startswith(".")]
    addrs = {i.address: k for k, i in enumerate(insns)}
    k = addrs.get(address)
    lo = insns[0].address if insns else 0
    hi = insns[-1].address if insns else 0
    for _ in range(limit):
        if k is None or k >= len(insns):
            return None
        insn = insns[k]
        b = _base(insn.mnemonic)
        tgt = branch_target(insn)
        if b in ("bl", "blx") or (b == "b" and tgt and not lo <= tgt[0] <= hi):
            return tgt[1] if tgt else None
        if b == "b" and tgt:
            k = addrs.get(tgt[0])
            continue
        if is_conditional_branch(b) or _is_return(insn):
            return None
        k += 1
    return None
