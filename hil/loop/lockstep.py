"""A campaign block's loop over all its steps in one C call (``native/lockstep.c``, built on first use by
:mod:`gainlink.firmware.c_kernel`): the plants' samples plus each run's noise, the law's block step, the commands plus
the disturbances to the plants, their compiled RK4, a failed plant ending its run, every record written run-major.

It strings together C functions that exist already, reached through their addresses: the law's block step
(``c_law()`` of a block law: any law of a host law library, :class:`gainlink.laws.block.NativeBlock`; the lq law's
float64 reference, :class:`gainlink.laws.lq.native_block.NativeReferenceBlock`) and the plants' RK4
(:meth:`~..plants.models.OdeBatch.c_plant`). The numpy loop (:func:`.block._python_lockstep`) is its oracle, and the
block's loop wherever :func:`why_not` says the C cannot step it.
"""

from __future__ import annotations

import ctypes
import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from gainlink.errors import ToolchainError

SOURCE = Path(__file__).resolve().parent / "native" / "lockstep.c"
LIBRARY = "libgainlink_lockstep.so"
IN_C = "one C call for the block's steps (hil/loop/native/lockstep.c)"
_P, _I, _D = ctypes.c_void_p, ctypes.c_int64, ctypes.c_double


def _fields(kind: Any, *names: str) -> list[tuple[str, Any]]:
    return [(n, kind) for n in names]


class _Plan(ctypes.Structure):
    _fields_ = (_fields(_I, "runs", "steps") + _fields(_P, "noise", "r", "s", "d") + _fields(_I, "p", "q", "e", "m")
                + _fields(_P, "disturbed"))  # fmt: skip


class _Plant(ctypes.Structure):
    _fields_ = (_fields(_P, "fn", "X", "U", "P", "failed") + _fields(_I, "nx", "nu", "npar", "substeps")
                + _fields(_D, "hh")
                + _fields(_P, "out_idx", "in_idx"))  # fmt: skip


class _Law(ctypes.Structure):
    _fields_ = (_fields(_I, "kind") + _fields(_P, "fn", "laws") + _fields(_I, "law_bytes")
                + _fields(_P, "samples", "records")
                + _fields(_I, "sample_bytes", "y_off", "r_off", "s_off", "law_q", "law_e", "record_bytes", "flags_off",
                          "sat_off", "u_off", "sigma_off", "fault")
                + _fields(_P, "dims", "mats", "state") + _fields(_I, "state_width", "kept_from", "kept")
                + _fields(_P, "sat", "flags", "r"))  # fmt: skip


class _Record(ctypes.Structure):
    _fields_ = _fields(_P, "Y", "U", "sat", "flags", "sigma", "X", "L", "done", "failed_at", "tick", "lat", "alive")


@dataclass
class Steps:
    """What a block's lockstep recorded: row i = run i, then step k (a run's rows are contiguous, a view)."""

    Y: np.ndarray
    U: np.ndarray
    sat: np.ndarray | None  # None for the twin's (its trace has none)
    flags: np.ndarray | None
    sigma: np.ndarray | None  # None: the law has no sigma (every run's is NaN)
    X: np.ndarray | None  # the plants' states (the run's, when its twin is on)
    L: np.ndarray | None  # the columns kept of the laws' states (the twin's integrators)
    steps: np.ndarray  # per run: steps taken (a plant that fails ends its run after that step)
    failed_at: np.ndarray  # per run: the step whose advance failed (-1: none)
    tick: np.ndarray  # (N,): when step k started, ns from the loop's start (the C: on the block's own clock)
    lat: np.ndarray  # (N,): the law's call for the block, ns, shared by its runs
    loop: str  # where the loop ran: IN_C, or why it ran in numpy


@functools.cache
def _kernel() -> Any:
    from gainlink.firmware.c_kernel import kernel_library

    # CDLL: the call is the whole block's loop (seconds) and touches no Python object; it releases the GIL
    lib = ctypes.CDLL(str(kernel_library(SOURCE, name=LIBRARY, what="the campaign block's loop")))
    lib.gl_lockstep_sizes.restype, lib.gl_lockstep_sizes.argtypes = _I, [_I]
    for which, struct in enumerate((_Plan, _Plant, _Law, _Record)):
        if lib.gl_lockstep_sizes(which) != ctypes.sizeof(struct):
            raise ToolchainError(f"{SOURCE.name}: its {struct.__name__[1:].lower()} struct is not lockstep.py's")
    lib.gl_lockstep.restype, lib.gl_lockstep.argtypes = _I, [_P, _P, _P, _P, _P]
    return lib.gl_lockstep


def why_not(batch: Any, controller: Any) -> str | None:
    """Why the C cannot step ``controller`` around ``batch`` (the numpy loop does), or None: a plant batch without
    the compiled RK4 (linear plants, a user's vectorised model), a block law without a C step (a law's float64
    reference stepped one by one or as numpy columns), the kernel not built (its one line)."""
    if getattr(batch, "c_plant", None) is None or batch.c_plant(dt=1.0) is None:
        return f"numpy: the {type(batch).__name__} of {batch.name} has no compiled RK4"
    if getattr(controller, "c_law", None) is None:
        return f"numpy: the law's block ({type(controller).__name__}) has no C step"
    try:
        _kernel()
    except ToolchainError as exc:
        return f"numpy: {exc}"
    return None


def address(a: np.ndarray) -> int:
    """Where ``a``'s first element lies: through ctypes for a writable array (~1 us: the buffer of its first element,
    a view contiguous whatever ``a``'s strides; a block's record rows), else its ``__array_interface__`` (~3.4 us:
    the dict it builds; a plan's read-only arrays, an empty one)."""
    try:
        return ctypes.addressof(ctypes.c_char.from_buffer(a if a.flags.c_contiguous else a[(slice(0, 1),) * a.ndim]))
    except (TypeError, ValueError, BufferError):
        return a.__array_interface__["data"][0]


def run(runs: list, batch: Any, controller: Any, *, Ts: float, steps: int, disturbed: np.ndarray | bool,
        plant_state: bool, law_state: slice | None) -> Steps:  # fmt: skip
    """The block's loop in C (:func:`why_not` None), with the arguments of :func:`.block._python_lockstep`
    (``disturbed``: per run (B, 1), or one answer for all; ``law_state``: the columns of the laws' states kept) and
    the same record."""
    B, kept = len(runs), []  # kept: every array whose address the C holds, alive until it returns

    def at(a: np.ndarray) -> int:
        kept.append(a)
        return address(a)

    plan = _plan(runs, steps=steps, disturbed=disturbed, at=at)
    plant = _struct(_Plant, batch.c_plant(dt=Ts), at)
    law_args = dict(controller.c_law())
    law_args |= {"sat": np.zeros(B, np.int64), "flags": np.zeros(B, np.int64),
                 "r": np.zeros((B, max(int(law_args["law_q"]), 1)))}  # fmt: skip
    if law_state is not None:
        first, stop, _ = law_state.indices(int(law_args["state_width"]))
        law_args |= {"kept_from": first, "kept": max(stop - first, 0)}
    law = _struct(_Law, law_args, at)
    rec = _records(B, steps, widths=(plan.p, plan.m, plant.nx), law=law_args, plant_state=plant_state,
                   law_state=law_state)  # fmt: skip
    record = _struct(_Record, rec, at)
    taken = _kernel()(ctypes.byref(plan), ctypes.byref(plant), ctypes.byref(law), ctypes.byref(record),
                      at(np.empty((B, plan.m))))  # fmt: skip
    if taken < 0:
        raise ValueError(f"{SOURCE.name} refused the law's kind {law_args['kind']}")
    cut = {k: (v[:, :taken] if k in _RECORDS else v) for k, v in rec.items()}
    return Steps(Y=cut["Y"], U=cut["U"], sat=cut.get("sat"), flags=cut.get("flags"), sigma=cut.get("sigma"),
                 X=cut.get("X"), L=cut.get("L"), steps=rec["done"], failed_at=rec["failed_at"], tick=rec["tick"],
                 lat=rec["lat"], loop=IN_C)  # fmt: skip


def _plan(runs: list, *, steps: int, disturbed: np.ndarray | bool, at: Any) -> _Plan:
    """What the runs are fed: the address of each run's plan arrays (asked once per array: a block's runs share
    their references, disturbances and signals), their widths, and whether each
    run's command goes to its plant with its disturbance."""
    args: dict[str, Any] = {"runs": len(runs), "steps": steps}
    for name, field, width in (("noise", "noise", "p"), ("R", "r", "q"), ("S", "s", "e"), ("D", "d", "m")):
        where: dict[int, int] = {}  # by id: each run's plan holds its array until the call returns
        for r in runs:
            given = getattr(r.plan, name)
            if id(given) not in where:
                where[id(given)] = at(np.ascontiguousarray(given, dtype=np.float64))
        args[field] = at(np.array([where[id(getattr(r.plan, name))] for r in runs], dtype=np.uintp))
        args[width] = getattr(runs[0].plan, name).shape[1]
    flags = np.broadcast_to(np.asarray(disturbed, dtype=np.uint8).reshape(-1), (len(runs),))
    return _Plan(**args, disturbed=at(np.ascontiguousarray(flags)))


def _records(B: int, steps: int, *, widths: tuple, law: dict, plant_state: bool, law_state: slice | None) -> dict:
    """The arrays the C writes (run-major records of the numpy loop's dtypes; the per-run and per-step figures):
    saturation and flags but for the twin's loop (``law_state``: the columns kept of the laws' states instead),
    sigma when the law has one, the plants' states when asked."""
    p, m, nx = widths
    rec = {"Y": np.empty((B, steps, p)), "U": np.empty((B, steps, m)), "done": np.empty(B, np.int64),
           "failed_at": np.empty(B, np.int64), "tick": np.zeros(steps), "lat": np.zeros(steps),
           "alive": np.empty(B, np.uint8)}  # fmt: skip
    if law_state is None:
        rec |= {"sat": np.empty((B, steps), np.int64), "flags": np.empty((B, steps), np.int64)}
    if law["records_sigma"]:
        rec["sigma"] = np.empty((B, steps))
    if plant_state:
        rec["X"] = np.empty((B, steps, nx))
    if law_state is not None:
        rec["L"] = np.empty((B, steps, int(law["kept"])))
    return rec


#: the run-major records (B, steps, ...), cut to the steps taken
_RECORDS = ("Y", "U", "sat", "flags", "sigma", "X", "L")


def _struct(kind: type, values: dict[str, Any], at: Any) -> Any:
    """``kind`` with its fields from ``values`` (an array given as its address, kept alive by ``at``); fields not in
    ``values`` zero (a NULL pointer: not recorded)."""
    names = {name for name, _ in kind._fields_}  # type: ignore[attr-defined]
    return kind(**{k: (at(v) if isinstance(v, np.ndarray) else v) for k, v in values.items() if k in names})
