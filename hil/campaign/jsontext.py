"""Compact JSON texts of many values of one structure at once, equal to ``json.dumps(value, sort_keys=True,
separators=(",", ":"), allow_nan=False)`` of each (its oracle).

A block's runs share their metrics' and their records' structure (the same keys, nested the same way); only the
numbers and a few strings differ. :func:`json_texts` walks the values a level at a time for all of them (the keys of
a level read by one :func:`operator.itemgetter` over the runs, the values transposed by ``zip``), writes the keys and
punctuation of a structure once into a ``%`` template, makes each leaf's texts a column at a time as json's encoder
makes them (``float.__repr__``, ``int.__repr__``, ``true``/``false``/``null``, ``encode_basestring_ascii``; a column
whose texts are all the same written into the template) and fills the template once a run. Values of different
structures (a key missing, another type) are split into groups of one structure each; a value the template cannot
give exactly (a NaN or an infinity, which json refuses; a key that is not a string; a type other than dict, list,
str, int, float, bool and None, subclasses included) is given to ``json.dumps`` itself, which raises as it would.

:func:`json_forms` stops short of the texts: each structure's template, which values of its runs are floats and the
runs' values, floats as numbers (a block file stores them so, :mod:`.store`), which :func:`form_texts` makes the same
texts of when they are read.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from json.encoder import encode_basestring_ascii  # the encoder json.dumps uses for a string (ensure_ascii)
from operator import itemgetter
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

_TRUTH = {True: "true", False: "false"}
_LEAVES = frozenset({float, int, bool, str, type(None)})
_LEAF_TEXT = {float: float.__repr__, int: int.__repr__, bool: _TRUTH.__getitem__, str: encode_basestring_ascii,
              type(None): lambda _: "null"}  # fmt: skip


def compact_json(value: Any) -> str:
    """``value`` as compact JSON text, keys sorted, NaN and infinities refused: what :func:`json_texts` equals."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=False)


class _Split(Exception):
    """Raised where the values of a level differ in structure: ``groups`` lists (positions, whether json itself must
    write them)."""

    def __init__(self, groups: list[tuple[list[int], bool]] | None):
        super().__init__()
        self.groups = groups  # None: every run, each written by json (a Shared value it refuses)


def json_texts(values: list) -> list[str]:
    """:func:`compact_json` of each of ``values``, made for the values of one structure at once."""
    return _texts(values, len(values))


def object_texts(columns: dict[str, Any], runs: int) -> list[str]:
    """:func:`compact_json` of the object each run ``i`` of ``runs`` would be, ``{key: columns[key][i]}`` (a value of
    ``columns`` itself a dict: an object of such columns, nested; or a :class:`Shared` value, every run's), without
    making the objects."""
    return _texts(columns, runs)


class Shared:
    """A node of a column tree (:func:`object_texts`) that every run holds, one value: its text made once, not a
    column of runs walked for it (a scenario's tables that a grid point's runs share)."""

    __slots__ = ("value",)

    def __init__(self, value: Any) -> None:
        self.value = value


@dataclass(frozen=True)
class Form:
    """Runs of one structure (:func:`json_forms`): their positions, the ``%`` template of their JSON text (a ``%s``
    a slot), each slot's kind (``kinds``: ``t`` a text, ``f`` a float) and the slots' columns in order, a text column a
    list of JSON texts, a float column a list of finite floats (their texts made by :meth:`texts`)."""

    rows: list[int]
    template: str
    kinds: str
    columns: list[list]

    def texts(self) -> list[str]:
        """Each run's JSON text."""
        if not self.columns:
            return [self.template % ()] * len(self.rows)
        cols = [_float_column_texts(col) if kind == "f" else col for kind, col in zip(self.kinds, self.columns)]
        return list(map(self.template.__mod__, zip(*cols)))


def json_forms(values: list) -> tuple[list[Form], dict[int, str]]:
    """The values of :func:`json_texts` as the forms of their structures (:class:`Form`), and the texts of those
    json writes itself (by position: a value the template cannot give exactly; a NaN raises as json raises)."""
    return _forms(values, len(values))


def tree_forms(node: dict, runs: int) -> tuple[list[Form], dict[int, str]]:
    """:func:`json_forms` of ``runs`` values given as a column tree (a dict of trees, or a column of values: what
    :func:`object_texts` takes), without the values made: the same forms as of the values."""
    return _forms(node, runs)


def form_texts(template: str, kinds: str, texts: list[list[str]], floats: np.ndarray) -> list[str]:
    """The JSON texts of runs of one :class:`Form` given by its slots as stored: ``texts`` each text slot's column,
    ``floats`` (runs, float slots) their numbers."""
    columns, text, number = [], iter(texts), iter(floats.T.tolist())
    for kind in kinds:
        columns.append(next(number) if kind == "f" else next(text))
    return Form(list(range(floats.shape[0])), template, kinds, columns).texts()


def _float_column_texts(values: list[float]) -> list[str]:
    """``float.__repr__`` of each of a column's floats (finite), through Arrow for a long column."""
    return float_texts(values) if len(values) >= ARROW_FLOATS else list(map(float.__repr__, values))


def _texts(node: dict | list, runs: int) -> list[str]:
    """The texts of ``runs`` runs of ``node`` (a column of values, or a dict of such nodes), a structure at a time."""
    out: list[str] = [""] * runs
    forms, whole = _forms(node, runs)
    for form in forms:
        for i, text in zip(form.rows, form.texts()):
            out[i] = text
    for i, text in whole.items():
        out[i] = text
    return out


def _forms(node: dict | list, runs: int) -> tuple[list[Form], dict[int, str]]:
    """:func:`json_forms` of ``runs`` runs of ``node`` (a column of values, or a dict of such nodes)."""
    forms: list[Form] = []
    whole: dict[int, str] = {}
    todo = [list(range(runs))] if runs else []
    while todo:
        rows = todo.pop()
        part = node if len(rows) == runs else _picked(node, rows)
        parts: list[str] = []
        columns: list[list] = []
        kinds: list[str] = []
        try:
            _flat(part, parts, columns, kinds)
        except _Split as split:
            for positions, direct in split.groups or [(list(range(len(rows))), True)]:
                members = [rows[j] for j in positions]
                if direct or len(members) == len(rows):  # (no structure to split by: json writes them)
                    for i in members:
                        whole[i] = compact_json(_value(node, i))
                elif members:
                    todo.append(members)
            continue
        forms.append(Form(rows, "".join(parts), "".join(kinds), columns))
    return forms, whole


def _picked(node: dict | list, rows: list[int]) -> dict | list:
    """``node`` (a column, or a dict of nodes) at runs ``rows`` only."""
    if isinstance(node, Shared):
        return node
    if isinstance(node, dict):
        return {key: _picked(sub, rows) for key, sub in node.items()}
    pick = itemgetter(*rows)
    return list(pick(node)) if len(rows) > 1 else [node[rows[0]]]


def _value(node: dict | list, i: int) -> Any:
    """Run ``i``'s value of ``node``."""
    if isinstance(node, Shared):
        return node.value
    return {key: _value(sub, i) for key, sub in node.items()} if isinstance(node, dict) else node[i]


def _flat(node: dict | list, parts: list[str], columns: list[list], kinds: list[str]) -> None:
    """Append ``node``'s template text to ``parts`` (``%s`` where a value goes), its varying values to ``columns``
    (a column of finite floats as they are, another as texts) and their kinds (``f``, ``t``) to ``kinds``; raise
    :class:`_Split` where its runs differ in structure."""
    if isinstance(node, Shared):
        try:
            parts.append(compact_json(node.value).replace("%", "%%"))
        except (TypeError, ValueError):  # json refuses it (a NaN, a key it cannot sort): it raises for every run
            raise _Split(None) from None
        return
    if isinstance(node, dict):
        _object(sorted(node), [node[key] for key in sorted(node)], parts, columns, kinds)
        return
    types = set(map(type, node))
    if types <= _LEAVES:
        if len(types) == 1 and _same(node):  # a value the runs share (the block's own): its text once
            parts.append(_LEAF_TEXT[type(node[0])](node[0]).replace("%", "%%"))
            return
        if types == {float}:
            _finite(node, node)
            parts.append("%s")
            columns.append(node)
            kinds.append("f")
            return
        texts = _leaf_texts(node, types)
        if texts.count(texts[0]) == len(texts):
            parts.append(texts[0].replace("%", "%%"))
        else:
            parts.append("%s")
            columns.append(texts)
            kinds.append("t")
    elif types == {dict}:
        keys = sorted(node[0]) if all(type(k) is str for k in node[0]) else None
        if keys is None or set(map(len, node)) != {len(keys)}:
            raise _Split(_shapes(node))
        if not keys:
            parts.append("{}")
            return
        try:
            rows = list(map(itemgetter(*keys), node))  # a key another run lacks: KeyError
        except KeyError:
            raise _Split(_shapes(node)) from None
        _object(keys, [list(col) for col in zip(*rows)] if len(keys) > 1 else [rows], parts, columns, kinds)
    elif types == {list}:
        sizes = set(map(len, node))
        if len(sizes) > 1:
            raise _Split(_shapes(node))
        if not sizes.pop():
            parts.append("[]")
            return
        for k, col in enumerate(zip(*node)):
            parts.append("[" if k == 0 else ",")
            _flat(list(col), parts, columns, kinds)
        parts.append("]")
    else:
        raise _Split(_shapes(node))


def _object(keys: list[str], nodes: list, parts: list[str], columns: list[list], kinds: list[str]) -> None:
    """An object of ``keys`` (sorted) and their nodes."""
    if not keys:
        parts.append("{}")
        return
    for k, (key, sub) in enumerate(zip(keys, nodes)):
        parts.append(("{" if k == 0 else ",") + encode_basestring_ascii(key).replace("%", "%%") + ":")
        _flat(sub, parts, columns, kinds)
    parts.append("}")


def _same(values: list) -> bool:
    """Whether ``values`` (of one leaf type) are all one value of one text: equal, and of one sign when a float zero
    (``-0.0`` equals ``0.0``), not a NaN or an infinity (json refuses them: :func:`_finite` finds them)."""
    first = values[0]
    if type(first) is float and not math.isfinite(first):
        return False
    if values.count(first) != len(values):
        return False
    return type(first) is not float or first != 0.0 or len({math.copysign(1.0, v) for v in values}) == 1


def _finite(values: list, floats: list) -> None:
    """Raise :class:`_Split` when one of ``floats`` (the floats of ``values``) is a NaN or an infinity (json itself
    writes those runs: it refuses them)."""
    if not all(map(math.isfinite, floats)):
        bad = [type(v) is float and not math.isfinite(v) for v in values]
        raise _Split([([j for j, b in enumerate(bad) if not b], False), ([j for j, b in enumerate(bad) if b], True)])


def _leaf_texts(values: list, kinds: set) -> list[str]:
    """Each of ``values`` (of the leaf types ``kinds``, not floats alone: :func:`_flat` keeps those as numbers) as
    json writes it; a NaN or an infinity raises :class:`_Split`."""
    if float in kinds:
        _finite(values, [v for v in values if type(v) is float])
    if len(kinds) > 1:
        return [_LEAF_TEXT[type(v)](v) for v in values]
    (kind,) = kinds
    if kind is type(None):
        return ["null"] * len(values)
    return list(map(_LEAF_TEXT[kind], values))


#: Floats in a column from which their texts are Arrow's (:func:`float_texts`): below, ``float.__repr__`` each.
ARROW_FLOATS = 64


def float_texts(values: list[float], arr: pa.Array | None = None) -> list[str]:
    """``float.__repr__`` of each of ``values`` (floats; ``arr``: the same as an Arrow float64 array without a null,
    when made already), those of a column mostly of numbers with a fraction of magnitude in [1e-4, 1e16) made by
    Arrow's cast to text (a value that is not finite is never one of them).

    Both write a float's shortest digits that read back as it (the closest such, ties to even: David Gay's dtoa in
    Python, double-conversion in Arrow) and write such a number positionally, Arrow at ~0.6 us a value against ~1.2
    for ``repr`` here (minimum of 15, loaded). They differ in the other forms (Arrow writes ``20`` for ``20.0``,
    ``0.00001`` for ``1e-05``, ``1.5e-7`` for ``1.5e-07``), and putting Arrow's text in Python's form a value at a time
    cost more than ``repr`` (1.1-1.4 against 0.9 us a value of ~1e-6), so every other value is ``float.__repr__``'s,
    and so is Arrow's text that has an exponent or does not read back as the value."""
    arr = pa.array(values, pa.float64()) if arr is None else arr
    x = arr.to_numpy(zero_copy_only=True)
    size = np.abs(x)
    ok = (size >= 1e-4) & (size < 1e16) & (np.trunc(x) != x)
    if 2 * ok.sum() < ok.size:
        return list(map(float.__repr__, values))
    texts = pc.cast(arr, pa.string())
    ok &= ~np.asarray(pc.match_substring(texts, "e").to_numpy(zero_copy_only=False), bool)
    ok &= np.asarray(pc.cast(texts, pa.float64()).to_numpy(zero_copy_only=False)) == x
    out = texts.to_pylist()
    for j in np.flatnonzero(~ok).tolist():
        out[j] = float.__repr__(values[j])
    return out


def _shapes(values: list) -> list[tuple[list[int], bool]]:
    """The positions of ``values`` grouped by structure (a dict's keys, a list's length, a leaf); those json must write
    itself (another type, a key that is not a string) as one group."""
    groups: dict[Any, list[int]] = {}
    for j, v in enumerate(values):
        kind = type(v)
        if kind is dict:
            shape: Any = tuple(sorted(v)) if all(type(k) is str for k in v) else None
        elif kind is list:
            shape = len(v)
        else:
            shape = "leaf" if kind in _LEAVES else None
        groups.setdefault(shape, []).append(j)
    return [(positions, shape is None) for shape, positions in groups.items()]
