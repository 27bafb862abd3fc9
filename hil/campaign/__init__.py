"""Campaigns: many SIL/HIL runs over plant uncertainty, design grids and fault matrices, on Dask.

``gl.campaign.run("campaign.toml", out="DIR")`` (``gainlink campaign run``) plans the runs
(:mod:`.config`, :mod:`.plan`), runs those without a result on a Dask LocalCluster or any scheduler
(:mod:`.cluster`, :mod:`.runner`; a task is :func:`.worker.execute_block`: a HIL run, or a block of SIL runs
stepped together, :mod:`gainlink.hil.loop.block`, each run's record the one :func:`.worker.execute` gives it
alone), stores each run by its content address (:mod:`.store`) and merges the report
(:mod:`.report`): pass/fail per run (:mod:`.criteria`), percentile envelopes, scatter plots, a failure table.
:func:`show_run` replays one run with its full HIL report; :func:`stored_run` gives its stored record and verdict.

From a script, call :func:`run` under ``if __name__ == "__main__":``: the LocalCluster's worker processes import
the script again, and :func:`run` refuses an unguarded call (:class:`UnguardedMainError`) before any starts.
"""

from .cluster import UnguardedMainError
from .config import Campaign, CampaignError, Criteria, load_campaign, parse_campaign
from .runner import CampaignInterrupted, CampaignResult, run
from .show import show_run, stored_run

__all__ = [
    "Campaign",
    "CampaignError",
    "CampaignInterrupted",
    "CampaignResult",
    "Criteria",
    "UnguardedMainError",
    "load_campaign",
    "parse_campaign",
    "run",
    "show_run",
    "stored_run",
]
