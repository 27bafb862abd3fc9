"""The firmware's targets and the QEMU boards that run the Cortex-M images.

A *target* is what the code is compiled for (``host`` or a Cortex-M core; the compiler flags of each
core live in ``firmware/cmake/cortex-m-cpu.cmake``), a *board* is a QEMU machine carrying that core
(its board file and linker script are in ``firmware/ports/cortex-m/``). :func:`resolve` turns what a
user typed (a target, a board, both or neither) into one :class:`Platform`, or refuses in one line.

=============  ================  =====================================================================
target         boards            arithmetic
=============  ================  =====================================================================
cortex-m0      microbit          soft float; multiply-adds through gl_fmaf (integer, rounded once)
cortex-m3      mps2-an385        soft float; gl_fmaf
cortex-m4      mps2-an386,       FPv4 single precision, vfma.f32
               netduinoplus2
cortex-m7      mps2-an500        FPv5 double precision, vfma.f32
cortex-m33     mps2-an505        FPv5 single precision, vfma.f32 (Secure image)
cortex-m55     mps3-an547        FPv5 with double and half precision, Helium (Secure image)
=============  ================  =====================================================================

Every target's float32 law equals the host build bit for bit: each multiply-add is rounded once
(``fmaf``), by the FPU or by gl_fmaf where there is none.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from ..errors import ToolchainError, did_you_mean
from ..shipping.law_c import LABELS

HOST = "host"


@dataclass(frozen=True)
class Board:
    """A QEMU machine (``-M name``) that runs a Cortex-M image.

    ``serves``: the image carries the MAVLink and slcan nodes on its UART (``firmware run --target``);
    the micro:bit's 16 KiB of RAM holds the loop, replay and PIL but not both nodes. ``slcan_laws``: the laws
    (``structure/numeric``) whose image on this board still carries the slcan node (the integer laws' node is
    small), not the MAVLink node: the board's per-law capability, declared here.
    """

    name: str
    core: str
    serves: bool = True
    slcan_laws: tuple[str, ...] = ()

    def serving_refusal(self, protocol: str, *, law: str) -> str | None:
        """Why this board's image of the law ``law`` (``structure/numeric``) cannot serve ``protocol`` (None: it
        can)."""
        if self.serves or (protocol == "slcan" and law in self.slcan_laws):
            return None
        if self.slcan_laws:
            laws = " and ".join(LABELS[law] for law in self.slcan_laws)
            return (
                f"the {self.name} image carries no bus node for this artifact and link (its RAM holds only the "
                f"slcan node, for the {laws} laws); choose another board"
            )
        return f"the {self.name} image carries no bus node on its UART; choose another board"


@dataclass(frozen=True)
class Target:
    """A compile target: ``host`` or a Cortex-M core, with its QEMU boards (the first is the default)."""

    name: str
    boards: tuple[str, ...] = ()
    hardware_fma: bool = True

    @property
    def is_cortex_m(self) -> bool:
        """A Cortex-M image (``.elf .bin .hex .map``) rather than host libraries."""
        return bool(self.boards)

    @property
    def default_board(self) -> str | None:
        """The board used when none is named."""
        return self.boards[0] if self.boards else None


BOARDS: dict[str, Board] = {
    b.name: b
    for b in (
        Board("microbit", "cortex-m0", serves=False, slcan_laws=("lq/q31", "lq/q15")),
        Board("mps2-an385", "cortex-m3"),
        Board("mps2-an386", "cortex-m4"),
        Board("netduinoplus2", "cortex-m4"),
        Board("mps2-an500", "cortex-m7"),
        Board("mps2-an505", "cortex-m33"),
        Board("mps3-an547", "cortex-m55"),
    )
}

TARGETS: dict[str, Target] = {
    t.name: t
    for t in (
        Target(HOST),
        Target("cortex-m0", ("microbit",), hardware_fma=False),
        Target("cortex-m3", ("mps2-an385",), hardware_fma=False),
        Target("cortex-m4", ("mps2-an386", "netduinoplus2")),
        Target("cortex-m7", ("mps2-an500",)),
        Target("cortex-m33", ("mps2-an505",)),
        Target("cortex-m55", ("mps3-an547",)),
    )
}

CORTEX_M_TARGETS = tuple(name for name, t in TARGETS.items() if t.is_cortex_m)
DEFAULT_TARGET = "cortex-m4"
DEFAULT_BOARD = TARGETS[DEFAULT_TARGET].default_board


@dataclass(frozen=True)
class Platform:
    """A resolved target and board (``board`` is None for the host)."""

    target: Target
    board: Board | None

    @property
    def name(self) -> str:
        """``target`` or ``target/board``."""
        return self.target.name + (f"/{self.board.name}" if self.board else "")


def resolve(target: str | None = None, board: str | None = None, *, default_target: str = DEFAULT_TARGET) -> Platform:
    """The platform a user means by ``target`` and ``board``.

    A board alone implies its core; a target alone takes its default board; neither gives
    ``default_target`` on its default board.

    Raises
    ------
    ToolchainError
        An unknown target or board, a board that does not carry the target's core, or a board for the host.
    """
    _known_names(target=target, board=board, targets=TARGETS)
    if target is None:
        target = BOARDS[board].core if board is not None else default_target
    t = TARGETS[target]
    if not t.is_cortex_m:
        if board is not None:
            raise ToolchainError(f"--board {board} is for a Cortex-M target, not {target}")
        return Platform(target=t, board=None)
    name = board or t.default_board
    if name not in t.boards:
        raise ToolchainError(
            f"board {name} carries a {BOARDS[name].core}, not a {target} ({target} boards: {', '.join(t.boards)})"
        )
    return Platform(target=t, board=BOARDS[name])


def resolve_cortex_m(target: str | None = None, board: str | None = None) -> Platform:
    """:func:`resolve` for what only runs on a Cortex-M image (QEMU replay, PIL): the host is refused."""
    _known_names(target=target, board=board, targets=CORTEX_M_TARGETS)
    platform = resolve(target, board)
    if platform.board is None:
        raise ToolchainError(
            f"{platform.target.name} is not a Cortex-M target (choose from {', '.join(CORTEX_M_TARGETS)})"
        )
    return platform


def _known_names(*, target: str | None, board: str | None, targets: Iterable[str]) -> None:
    """Refuse a target not among ``targets`` or an unknown board, in one line naming the choices."""
    choices = list(targets)
    if target is not None and target not in choices:
        if target in TARGETS:  # a known target that is not a choice here (the host, for an image)
            raise ToolchainError(f"{target} is not a Cortex-M target (choose from {', '.join(choices)})")
        raise ToolchainError(
            f"unknown target {target!r}{did_you_mean(target, choices)} (choose from {', '.join(choices)})"
        )
    if board is not None and board not in BOARDS:
        raise ToolchainError(f"unknown board {board!r}{did_you_mean(board, BOARDS)} (choose from {', '.join(BOARDS)})")
