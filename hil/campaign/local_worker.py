"""The set-up of a LocalCluster worker process (a Dask preload, named by module): it ignores SIGINT.

A Ctrl-C in a terminal reaches every process of the foreground group, the LocalCluster's worker processes too:
each printed the traceback of its interrupted event loop (some 70 lines for two workers) while the campaign's
client was about to stop them anyway. The client alone takes the interrupt: it stops the cluster, keeps every
finished run and says how to resume (:class:`.runner.CampaignInterrupted`). Workers you start yourself
(``dask worker``) keep Dask's own handling.
"""

from __future__ import annotations

import signal
import threading
from typing import Any


def dask_setup(worker: Any) -> None:
    """Called by Dask in each worker process as it starts: SIGINT is ignored there from now on."""
    if threading.current_thread() is threading.main_thread():  # only the main thread may set a handler
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    # forked from a fork server started with SIGINT blocked (:func:`.cluster._start_fork_server`): ignored now, so
    # the processes a run starts (firmware, QEMU) get the usual mask, SIGINT ignored as before
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
