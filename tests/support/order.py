"""The order `make test` hands the tests out in: the slow ones first, the dearest first, an xdist group together.

``conftest.py``'s ``pytest_collection_modifyitems`` calls :func:`slow_first`.
"""

from __future__ import annotations

import pytest


def _weight(item: pytest.Item) -> tuple[bool, float]:
    slow = item.get_closest_marker("slow")
    return slow is None, -float(slow.kwargs.get("cpu", 0.0)) if slow else 0.0


def _group(item: pytest.Item) -> str | None:
    mark = item.get_closest_marker("xdist_group")
    if mark is None:
        return None
    return str(mark.args[0] if mark.args else mark.kwargs.get("name"))


def slow_first(items: list[pytest.Item]) -> None:
    """Sort ``items`` in place: the tests marked ``slow`` first, the dearest first by ``slow(cpu=N)``, the rest in
    their order; the tests of one ``xdist_group`` stay together, in their order, where their dearest one goes.

    A group is together because its tests share module fixtures: in one process (``-n 0``) a module fixture is torn
    down when the next test is another module's, so a group split by the weights of its tests made its fixtures twice
    or three times (the campaign module's two clusters, the trim module's designs). Under pytest-xdist's loadgroup a
    group is one unit, handed to one worker where its first test falls: that place is unchanged."""
    index = {id(item): i for i, item in enumerate(items)}
    groups: dict[str, tuple[tuple[bool, float], int]] = {}
    for item in items:
        name = _group(item)
        if name is not None:
            key = (_weight(item), index[id(item)])
            groups[name] = min(groups.get(name, key), key)

    def key(item: pytest.Item) -> tuple[tuple[bool, float], int, int]:
        name = _group(item)
        if name is None:
            return _weight(item), index[id(item)], 0
        weight, first = groups[name]
        return weight, first, index[id(item)]

    items.sort(key=key)
