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
"""

from __future__ import annotations

import json
import math
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

    def __init__(self, groups: list[tuple[list[int], bool]]):
        super().__init__()
        self.groups = groups


def json_texts(values: list) -> list[str]:
    """:func:`compact_json` of each of ``values``, made for the values of one structure at once."""
    return _texts(values, len(values))


def object_texts(columns: dict[str, Any], runs: int) -> list[str]:
    """:func:`compact_json` of the object each run ``i`` of ``runs`` would be, ``{key: columns[key][i]}`` (a value of
    ``columns`` itself a dict: an object of such columns, nested), without making the objects."""
    return _texts(columns, runs)


def _texts(node: dict | list, runs: int) -> list[str]:
    """The texts of ``runs`` runs of ``node`` (a column of values, or a dict of such nodes), a structure at a time."""
    out: list[str] = [""] * runs
    todo = [list(range(runs))] if runs else []
    while todo:
        rows = todo.pop()
        part = node if len(rows) == runs else _picked(node, rows)
        parts: list[str] = []
        columns: list[list[str]] = []
        try:
            _flat(part, parts, columns)
        except _Split as split:
            for positions, direct in split.groups:
                members = [rows[j] for j in positions]
                if direct or len(members) == len(rows):  # (no structure to split by: json writes them)
                    for i in members:
                        out[i] = compact_json(_value(node, i))
                elif members:
                    todo.append(members)
            continue
        template = "".join(parts)
        texts = list(map(template.__mod__, zip(*columns))) if columns else [template % ()] * len(rows)
        for i, text in zip(rows, texts):
            out[i] = text
    return out


def _picked(node: dict | list, rows: list[int]) -> dict | list:
    """``node`` (a column, or a dict of nodes) at runs ``rows`` only."""
    if isinstance(node, dict):
        return {key: _picked(sub, rows) for key, sub in node.items()}
    pick = itemgetter(*rows)
    return list(pick(node)) if len(rows) > 1 else [node[rows[0]]]


def _value(node: dict | list, i: int) -> Any:
    """Run ``i``'s value of ``node``."""
    return {key: _value(sub, i) for key, sub in node.items()} if isinstance(node, dict) else node[i]


def _flat(node: dict | list, parts: list[str], columns: list[list[str]]) -> None:
    """Append ``node``'s template text to ``parts`` (``%s`` where a value's text goes) and its varying texts to
    ``columns``; raise :class:`_Split` where its runs differ in structure."""
    if isinstance(node, dict):
        _object(sorted(node), [node[key] for key in sorted(node)], parts, columns)
        return
    kinds = set(map(type, node))
    if kinds <= _LEAVES:
        if len(kinds) == 1 and _same(node):  # a value the runs share (the block's own): its text once
            parts.append(_LEAF_TEXT[type(node[0])](node[0]).replace("%", "%%"))
            return
        texts = _leaf_texts(node, kinds)
        if texts.count(texts[0]) == len(texts):
            parts.append(texts[0].replace("%", "%%"))
        else:
            parts.append("%s")
            columns.append(texts)
    elif kinds == {dict}:
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
        _object(keys, [list(col) for col in zip(*rows)] if len(keys) > 1 else [rows], parts, columns)
    elif kinds == {list}:
        sizes = set(map(len, node))
        if len(sizes) > 1:
            raise _Split(_shapes(node))
        if not sizes.pop():
            parts.append("[]")
            return
        for k, col in enumerate(zip(*node)):
            parts.append("[" if k == 0 else ",")
            _flat(list(col), parts, columns)
        parts.append("]")
    else:
        raise _Split(_shapes(node))


def _object(keys: list[str], nodes: list, parts: list[str], columns: list[list[str]]) -> None:
    """An object of ``keys`` (sorted) and their nodes."""
    if not keys:
        parts.append("{}")
        return
    for k, (key, sub) in enumerate(zip(keys, nodes)):
        parts.append(("{" if k == 0 else ",") + encode_basestring_ascii(key).replace("%", "%%") + ":")
        _flat(sub, parts, columns)
    parts.append("}")


def _same(values: list) -> bool:
    """Whether ``values`` (of one leaf type) are all one value of one text: equal, and not a float zero (``-0.0``
    equals ``0.0``) or a NaN or an infinity (json refuses them: :func:`_leaf_texts` finds them)."""
    first = values[0]
    if type(first) is float and (first == 0.0 or not math.isfinite(first)):
        return False
    return values.count(first) == len(values)


def _leaf_texts(values: list, kinds: set) -> list[str]:
    """Each of ``values`` (of the leaf types ``kinds``) as json writes it; a NaN or an infinity raises :class:`_Split`
    (json itself writes those runs: it refuses them)."""
    floats = values if kinds == {float} else [v for v in values if type(v) is float] if float in kinds else ()
    if not all(map(math.isfinite, floats)):
        bad = [type(v) is float and not math.isfinite(v) for v in values]
        raise _Split([([j for j, b in enumerate(bad) if not b], False), ([j for j, b in enumerate(bad) if b], True)])
    if len(kinds) > 1:
        return [_LEAF_TEXT[type(v)](v) for v in values]
    (kind,) = kinds
    if kind is type(None):
        return ["null"] * len(values)
    if kind is float and len(values) >= ARROW_FLOATS:
        return float_texts(values)
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
