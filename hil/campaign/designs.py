"""The laws a campaign runs, designed once a process: a campaign planned again, or another over the same specs (the
block benchmark's warm-up and its timed campaigns, a notebook's second campaign), takes each law's artifact from
here instead of designing it again (~0.1 s a law for the shipped pendulum, most of it the float32 fidelity check's
simulations; serial on the client before the first run can start).

A spec's text names its artifact: the spec dict holds everything its design takes (matrices, weights, limits; a
linearised FMU's numbers as ``gainlink linearize`` wrote them, not the FMU), and a design is deterministic (the run ids
that name a resumed campaign's runs rest on it). What the spec was read from (``source``) only words a refusal, and a
refusal is not kept: a spec that fails is designed (and refused) again.
"""

from __future__ import annotations

import threading
from collections import OrderedDict

from gainlink.shipping.artifact import canonical_json, render

#: Artifacts kept, the least recently planned dropped first: enough for every grid point of a campaign whose grid
#: changes the spec a few dozen ways; a draw axis that changes the spec designs each run, and only the last ones stay.
KEPT = 64

_designed: OrderedDict[str, bytes] = OrderedDict()
_lock = threading.Lock()  # two threads planning at once: neither sees the other's entry half moved or dropped


def designed(spec: dict, *, source: str) -> bytes:
    """The artifact (rendered JSON) of the law ``spec`` asks for, designed at its first call in this process."""
    key = canonical_json(spec)
    with _lock:
        art = _designed.get(key)
        if art is not None:
            _designed.move_to_end(key)
            return art
    art = _design(spec, source=source)  # not under the lock: a design takes ~0.1 s, and two alike give the same bytes
    with _lock:
        _designed[key] = art
        _designed.move_to_end(key)
        while len(_designed) > KEPT:
            _designed.popitem(last=False)
    return art


def _design(spec: dict, *, source: str) -> bytes:
    from gainlink.laws import design
    from gainlink.spec import parse_spec

    sealed = design(parse_spec(spec, source=source)).artifact
    return render(sealed).encode("utf-8")
