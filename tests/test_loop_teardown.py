"""A run's resources close whole when a Ctrl-C comes while they close (:class:`~gainlink.hil.loop.teardown.
ClosingStack`), and a Ctrl-C before that stops the run at once.

The signal is this process's own (``signal.raise_signal``: Python runs its handler before the call returns), sent
from inside the block or a closing callback; the oracle is what ran, in order, and where the interrupt came out.
"""

from __future__ import annotations

import signal
from contextlib import ExitStack

import pytest
from gainlink.hil.loop.teardown import ClosingStack


def _close(ran: list[str], name: str, *, interrupt: bool = False):
    def close() -> None:
        if interrupt:
            signal.raise_signal(signal.SIGINT)
        ran.append(name)

    return close


@pytest.mark.parametrize("closing", [True, False], ids=["said-closing", "on-its-way-out"])
def test_a_ctrl_c_while_the_resources_close_waits_until_every_one_has_closed(closing):
    """The first callback to run is interrupted at its start: it still runs to its end, so does the next, and the
    KeyboardInterrupt comes out of the block after them, through Python's own handler, which is in place again."""
    ran: list[str] = []
    with pytest.raises(KeyboardInterrupt):
        with ClosingStack() as stack:
            stack.callback(_close(ran, "plant"))
            stack.callback(_close(ran, "link", interrupt=True))
            if closing:
                stack.closing()
    assert ran == ["link", "plant"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_plain_exit_stack_cuts_the_interrupted_callback_short():
    """What the stack mends: an ExitStack's callback interrupted at its start never finishes (a link's buses left
    open, python-can's finaliser then logs that they were not shut down)."""
    ran: list[str] = []
    with pytest.raises(KeyboardInterrupt):
        with ExitStack() as stack:
            stack.callback(_close(ran, "plant"))
            stack.callback(_close(ran, "link", interrupt=True))
    assert ran == ["plant"]


def test_a_ctrl_c_before_the_resources_close_stops_the_block_at_once_and_they_close():
    """Before :meth:`closing`, a Ctrl-C is raised where it lands (the run stops); every resource still closes."""
    ran: list[str] = []
    with pytest.raises(KeyboardInterrupt):
        with ClosingStack() as stack:
            stack.callback(_close(ran, "plant"))
            signal.raise_signal(signal.SIGINT)
            ran.append("after the interrupt")
    assert ran == ["plant"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
