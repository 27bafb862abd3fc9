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
- ``ret:<f>``: what ``f`` returned;
- ``slot``: a word reloaded from the function's own frame where no slot is pinned (unknown).

**The frame** (stack-slot tracking): the state also holds sp's offset from its value at the function's entry (it
follows ``push``, ``pop``, ``stmdb sp!``, ``ldmia sp!``, ``vpush``, ``vpop``, ``sub sp`` and ``add sp`` by
immediates) and the origins of each word stored in a slot it pins: a store to ``[sp, #imm]``, or through a register
holding the entry sp + K exactly (a frame pointer: ``add r7, sp, #0``), carries the stored register's origins to the
slot, and a reload carries them back (a loop counter spilled across a call stays fixed; a float word spilled and
reloaded is data). A register made from a frame address carries it as a marker, stripped from a branch's origins and
from a call's arguments (a frame address is an address). What cannot be pinned is unknown, and a reload of it is
``slot`` (data): a slot not stored on every path to the reload, every slot once sp is moved by a register or differs
between two paths, a slot a store through a pointer formed from the frame may reach (its origins are joined into
each such slot), and every slot at or above a frame address passed to a call or stored outside a pinned slot (from
then on every call and every store through any pointer may write them). The words above the entry sp (the caller's
stack arguments) are loaded words, as any other. Premise: a pointer formed by adding an index to sp + K reaches sp +
K and above (the access's own negative offset aside): an index into a local array is not negative.

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


Regs = dict[str, frozenset[str]]
#: The frame: sp's offset from its value at the function's entry (None: changed by a register, or different on two
#: paths), the origins of the words stored in the stack slots the analysis pins (keyed by their offset from the entry
#: sp; a slot absent is unknown), and the lowest offset a frame address was passed or stored at (None: none escaped).
Frame = tuple[int | None, dict[int, frozenset[str]], int | None]
State = tuple[Regs, frozenset[str], Frame]  # register origins, flag origins, the frame


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
        """What ``insn`` does to the origins of the registers, the flags and the frame's slots (``known``: the
        condition the flags are known to satisfy on this path, which decides a predicated instruction of that
        condition or its opposite)."""
        regs, flags, frame = state
        b = _base(insn.mnemonic)
        pred = insn.address in self.predicated and b[-2:] in _CONDS and not b.startswith("it")
        if pred:
            cond = _NORM.get(b[-2:], b[-2:])
            b = b[:-2]
            if known is not None and cond == known:
                pred = False  # it runs, decided by the branch the path took
            elif known is not None and cond == _OPPOSITE[known]:
                return state  # it does not run
        before = {**regs, "sp": _sp_origin(frame)}
        after, flags = self._registers(insn, b, before, flags, pred)
        after, frame = _frame_effect(insn, b, before, after, frame, pred)
        after.pop("sp", None)
        return after, flags, frame

    def _registers(self, insn: Insn, b: str, regs: dict[str, frozenset[str]], flags: frozenset[str],
                   pred: bool) -> tuple[dict[str, frozenset[str]], frozenset[str]]:  # fmt: skip
        """The registers' and the flags' origins after ``insn`` (mnemonic ``b`` without its condition; ``pred``:
        whether its condition may not hold), a load's destination a loaded word (:data:`MEM`)."""
        regs, ops = dict(regs), insn.operands
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
                self.sites[insn.address] = (tgt[1], _arguments(regs))
            return regs, flags
        if b.startswith(_NO_WRITE) or is_conditional_branch(b) or b == "bx" or b.startswith("it"):
            return regs, flags
        if b.startswith(("ldr", "ldm", "pop")):
            for r in _load_dests(b, ops, rs):
                regs[r] = frozenset({MEM}) | extra | (regs.get(r, frozenset()) if pred else frozenset())
            return regs, flags
        return _alu(b, rs, regs, flags, extra, pred)

    def _call(self, insn: Insn, regs: Regs) -> tuple[Regs, frozenset[str]]:
        callee = (branch_target(insn) or (0, "?"))[1]
        self.calls[insn.address] = callee
        self.sites[insn.address] = (callee, _arguments(regs))
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
        states: dict[int, State] = {0: (entry, frozenset(), (0, {}, None))}
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
            regs, flags, _ = states[k]
            b = _base(insn.mnemonic)
            origins = regs.get(_regs(insn.operands)[0], frozenset()) if b in ("cbz", "cbnz") else flags
            origins = _plain(origins)  # a frame address is an address
            tgt = branch_target(insn)
            nxt = self.insns[k + 1].address if k + 1 < len(self.insns) else -1
            branches.append(Branch(self.name, insn, origins, tgt[0] if tgt else -1, nxt))
        return branches


MEM = "mem"  # a loaded word: an address or a copy, not data (module docstring)


SLOT = "slot"  # a word reloaded from the frame where the analysis pins no slot: unknown, so data
#: The origin a frame address carries: ``frame=K`` the entry sp + K exactly, ``frame>=K`` a pointer formed from it by
#: adding (it reaches sp + K and above: premise), ``frame>=*`` anywhere in the frame. Stripped from a branch's origins
#: and a call's arguments: a frame address is an address.
_AT, _FROM, _ANYWHERE = "frame=", "frame>=", "frame>=*"
_STORES = ("str", "stm", "push", "vst", "vpush", "stc")  # stc, ldc: how objdump shows MVE's vstrw, vldrw
_LOADS = ("ldr", "ldm", "pop", "vldr", "vldm", "vpop", "ldc")
_MEMORY = re.compile(r"\[(\w+)(?:,\s*#(-?\d+))?(?:,\s*(\w+)[^\]]*)?\](!)?(?:,\s*#(-?\d+))?")


def _is_data(origins: frozenset[str]) -> bool:
    return bool(_plain(origins) - {MEM})


def _plain(origins: frozenset[str]) -> frozenset[str]:
    """``origins`` without the frame-address markers."""
    return frozenset(o for o in origins if not o.startswith("frame"))


def _arguments(regs: Regs) -> Regs:
    """The origins of r0..r3 a call passes (a frame address is an address to the callee)."""
    return {f"r{i}": _plain(regs.get(f"r{i}", frozenset())) for i in range(4)}


def _sp_origin(frame: Frame) -> frozenset[str]:
    return frozenset({f"{_AT}{frame[0]}" if frame[0] is not None else _ANYWHERE})


def _exact(origins: frozenset[str]) -> int | None:
    """The frame offset a register holds exactly (one ``frame=K`` marker and no other frame marker), or None."""
    marks = [o for o in origins if o.startswith("frame")]
    return int(marks[0][len(_AT) :]) if len(marks) == 1 and marks[0].startswith(_AT) else None


def _lowest(origins: frozenset[str]) -> float | None:
    """The lowest frame offset a register's frame markers let it reach (None: it holds no frame address)."""
    floors = [
        -float("inf") if o == _ANYWHERE else int(o[len(_AT) :] if o.startswith(_AT) else o[len(_FROM) :])
        for o in origins
        if o.startswith("frame")
    ]
    return min(floors, default=None)


def _words(b: str, ops: str) -> list[str]:
    """The registers a list store or load moves, one a word in address order (a ``d`` register two words, marked
    ``float``; a range ``s16-s31`` expanded)."""
    if "{" not in ops:
        return []
    out: list[str] = []
    for part in ops[ops.index("{") + 1 : ops.index("}")].split(","):
        part = part.strip()
        m = re.fullmatch(r"([sd])(\d+)(?:-[sd](\d+))?", part)
        if m:
            n = int(m.group(3) or m.group(2)) - int(m.group(2)) + 1
            out += ["float"] * (n * (2 if m.group(1) == "d" else 1))
        else:
            out.append(_ALIAS.get(part, part))
    return out


def _frame_effect(insn: Insn, b: str, before: Regs, after: Regs, frame: Frame, pred: bool) -> tuple[Regs, Frame]:
    """What ``insn`` does to the frame (stack-slot tracking): a store to a pinned slot (``[sp, #imm]``, or through
    any register holding sp + K exactly, a frame pointer) carries the stored register's origins to the slot, a load
    from it back; sp's offset from the entry follows ``push``, ``pop``, ``sub sp`` and ``add sp``. A store through a
    pointer formed from the frame joins its origins into every pinned slot it may reach, a call or a store of a frame
    address anywhere but a pinned slot lets the frame escape (then every call and every store through any pointer may
    write it); what the analysis cannot pin falls back to unknown (:data:`SLOT`, data)."""
    depth, slots, esc = frame[0], dict(frame[1]), frame[2]
    ops = insn.operands
    after = dict(after)
    if b in ("bl", "blx"):
        marks = [_lowest(before.get(f"r{i}", frozenset())) for i in range(4)]
        marks += [_lowest(o) for o in slots.values()]
        esc = _min(esc, *marks)
        return after, (depth, _forget(slots, esc), esc)
    if b.startswith(_STORES) or b.startswith(_LOADS):
        return _memory_access(insn, b, before, after, (depth, slots, esc), pred)
    rs = _regs(ops)
    if not rs or b in ("b", "bx") or is_conditional_branch(b) or b.startswith(("v", "it", *_COMPARES, *_NO_WRITE)):
        return after, (depth, slots, esc)
    dest = rs[0]
    after[dest] = _pointer_arithmetic(b, ops, rs, before, after.get(dest, frozenset()))
    if dest == "sp":
        depth = _exact(after[dest]) if not pred else None
    return after, (depth, slots, esc)


def _memory_access(insn: Insn, b: str, before: Regs, after: Regs, frame: Frame, pred: bool) -> tuple[Regs, Frame]:
    """A store's or a load's effect on the frame, and a load's destinations' origins from it
    (:func:`_frame_effect`)."""
    access = _access(b, insn.operands)
    if access is None:  # a form not read here (a register list through a register index...): the frame is unknown
        return after, (frame[0], {}, frame[2]) if b.startswith(_STORES) else frame
    base, offset, words, wb = access
    depth, slots, esc = frame[0], dict(frame[1]), frame[2]
    origins = before.get(base, frozenset())
    k, low = _exact(origins), _lowest(origins)
    at = k + offset if k is not None and offset is not None else None
    reach = None if low is None else low + min(0, offset or 0)  # a register index: not negative (premise)
    store = b.startswith(_STORES)
    values = [frozenset({"float"}) if w == "float" else before.get(w, frozenset()) for w in words]
    sub_word = b[3:4] in ("b", "h") or b[3:5] in ("sb", "sh")
    for i, (w, v) in enumerate(zip(words, values)):
        if at is not None:
            slot = (at + 4 * i) // 4 * 4
            if store and not pred and not sub_word and (at + 4 * i) % 4 == 0:
                slots[slot] = v
            elif store:
                if slot in slots:
                    slots[slot] |= v
            elif w not in ("float", "pc"):
                got = slots.get(slot, frozenset({MEM if slot >= 0 else SLOT}))
                after[w] = got | (after.get(w, frozenset()) if pred else frozenset())
        elif store:
            floor = reach if reach is not None else esc
            if floor is not None:
                slots = {o: (x | v if o >= floor else x) for o, x in slots.items()}
        elif reach is not None and w not in ("float", "pc"):
            after[w] = frozenset({SLOT}) | (after.get(w, frozenset()) if pred else frozenset())
    if store and at is None:
        esc = _min(esc, *(_lowest(v) for v in values))
    if wb is not None and low is not None:
        moved = frozenset({f"{_AT}{k + wb}"}) if k is not None else origins if wb >= 0 else frozenset({_ANYWHERE})
        after[base] = _plain(after.get(base, frozenset())) | moved
        if base == "sp":
            depth = _exact(after[base]) if not pred else None
    return after, (depth, slots, esc)


def _access(b: str, ops: str) -> tuple[str, int | None, list[str], int | None] | None:
    """A store's or a load's base register, the offset of its first word from it (None: a register index), the
    registers of its words in address order (``float`` for a float register's) and the base's writeback (None: none);
    None for a form not read here."""
    if b.startswith(("push", "pop", "vpush", "vpop", "stm", "ldm", "vstm", "vldm")):
        words = _words(b, ops) if b.startswith("v") or "{" not in ops else _regs(ops[ops.index("{") :])
        implied = b.startswith(("push", "pop", "vpush", "vpop"))
        head = ops[: ops.index("{")] if "{" in ops else ""
        base = "sp" if implied else (_regs(head) or [""])[0]
        if not base:
            return None
        down = b.startswith(("push", "vpush")) or "db" in b
        n = 4 * len(words)
        wb = (-n if down else n) if implied or "!" in head else None
        return base, (-n if down else 0), words, wb
    m = _MEMORY.search(ops)
    if not m:
        return None
    base = _ALIAS.get(m.group(1), m.group(1))
    head = ops[: m.start()]
    if b.startswith(("stc", "ldc")):  # a vector register's words: how many is not read here
        return base, None, ["float"], int(m.group(5) or m.group(2) or 0) if m.group(5) or m.group(4) else None
    if b.startswith("v"):
        words = ["float"] * (2 if re.search(r"\bd\d+", head) else 1)
    else:
        words = _regs(head)[1:2] if b.startswith("strex") else _regs(head)[: 2 if b.startswith(("strd", "ldrd")) else 1]
    offset = None if m.group(3) else int(m.group(2) or 0)
    if m.group(5) is not None:  # post-indexed: the access at the base, then the base moves
        return base, 0, words, int(m.group(5))
    return base, offset, words, (offset if m.group(4) else None)


def _min(*values: float | None) -> int | None:
    found = [v for v in values if v is not None]
    if not found:
        return None
    low = min(found)
    return -(2**31) if low == -float("inf") else int(low)


def _forget(slots: dict[int, frozenset[str]], esc: int | None) -> dict[int, frozenset[str]]:
    """The pinned slots an escaped frame address cannot reach (those below it)."""
    return slots if esc is None else {o: v for o, v in slots.items() if o < esc}


def _pointer_arithmetic(b: str, ops: str, rs: list[str], before: Regs, written: frozenset[str]) -> frozenset[str]:
    """The frame markers of an integer operation's result: sp + K plus or minus an immediate, or a copy, is exact;
    a frame address plus a register reaches its K and above (premise: an index added to a frame address is not
    negative); anything else made from one may point anywhere in the frame."""
    srcs = rs[1:]
    if (len(rs) == 1 and not b.startswith("mov")) or b.startswith(("movt", "bfi", "bfc")):
        srcs = rs  # as _alu reads them
    plain = _plain(written)
    marked = [r for r in srcs if _lowest(before.get(r, frozenset())) is not None]
    if not marked:
        return plain
    imm = re.search(r"#(-?\d+)\s*$", ops)
    if len(srcs) == 1 and b.startswith("mov") and not imm:  # a copy: the same frame address (or addresses)
        return plain | {o for o in before.get(srcs[0], frozenset()) if o.startswith("frame")}
    if len(srcs) == 1 and (k := _exact(before.get(srcs[0], frozenset()))) is not None:
        if imm and b.startswith(("add", "sub")) and not b.startswith(("adc", "sbc")):
            sign = -1 if b.startswith("sub") else 1
            return plain | {f"{_AT}{k + sign * int(imm.group(1))}"}
    if b.startswith("add") and not b.startswith("adc"):
        low = min(_lowest(before[r]) for r in marked)  # type: ignore[type-var]
        return plain | {_ANYWHERE if low == -float("inf") else f"{_FROM}{int(low)}"}
    return plain | {_ANYWHERE}


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
    return b if a is None else (_join_regs(a[0], b[0]), a[1] | b[1], _join_frames(a[2], b[2]))


def _join_frames(a: Frame, b: Frame) -> Frame:
    """Two paths' frames met: a slot pinned on one only is unknown, sp's offset unknown unless the same."""
    slots = {o: a[1][o] | b[1][o] for o in a[1].keys() & b[1].keys()}
    esc = min((e for e in (a[2], b[2]) if e is not None), default=None)
    return (a[0] if a[0] == b[0] else None), slots, esc


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
