"""A block file's runs judged at once, and the texts ``campaign.csv`` and the report hold of each
(:func:`judge_part`: a :class:`~.store.ReportPart` in, a :class:`JudgedPart` out): what the client's
:class:`.rows.Verdicts` is made of. A function of the block file alone and the campaign's criteria, so a cluster's
worker judges the block it ran (:func:`.worker.execute_block`) and the client only files its verdicts in."""

from __future__ import annotations

import csv
import functools
import io
import json
from json.encoder import encode_basestring_ascii  # the encoder json.dumps uses for a string (ensure_ascii)
from typing import Any, NamedTuple

import numpy as np

from .block_layout import MEASURE_CELLS, METRIC_CELLS
from .criteria import evaluate_columns

# after each field of a spilled line (JSON and CSV cells hold no NUL: json escapes it, reasons are text)
SEP = "\x00"


def csv_field(text: str) -> str:
    """``text`` as one field of ``csv.writer``'s row (its default dialect: minimal quoting, a quote doubled): as it is,
    or in quotes when it holds a comma, a quote or a line end; one with a carriage return as the writer itself writes
    it (whether it quotes one depends on the Python: 3.11's does not)."""
    if "\r" in text:
        out = io.StringIO()
        csv.writer(out, lineterminator="\n").writerow([text, ""])
        return out.getvalue()[:-2]
    if "," not in text and '"' not in text and "\n" not in text:
        return text
    return '"' + text.replace('"', '""') + '"'


# :data:`.block_layout.ROW_BITS`' bits of the keys a head names
ROW_BITS = {"complete": 1, "run_reason": 2, "worker": 4}


_CELL = {"null": "", "true": "True", "false": "False"}  # a value's JSON text -> its cell, where they differ


def _cells(texts: list[str]) -> list[str]:
    """Values' JSON texts as ``csv.writer`` writes the values: ``null`` empty, booleans by ``str``, numbers as they
    are (a float's JSON text is its ``repr``)."""
    cell = _CELL.get
    return [cell(t, t) for t in texts]


def part_cells(part: Any) -> list[str]:
    """The ``campaign.csv`` cells of ``part``'s runs after the reasons, as CSV text (numbers and booleans: no field
    quoted): ``complete`` and the measures, then each tracked output's metrics and each output's final value in the
    run's own sorted order; each column's texts made once (the measures' shared with the row's JSON text), the runs
    of one (tracked outputs, outputs) joined at once."""
    fixed = [_cells(part.texts["complete"]), *(_cells(part.texts[k]) for k in MEASURE_CELLS)]
    tracked = {t: [_cells(cols[k]) for k in METRIC_CELLS] for t, cols in part.tracked.items()}
    final = {o: _cells(v) for o, v in part.outputs_final.items()}
    out = [""] * len(part.ids)
    for s, (names, outs) in enumerate(part.shapes):
        rows = np.flatnonzero(part.shape == s).tolist()
        columns = [*fixed, *(col for t in names for col in tracked[t]), *(final[o] for o in outs)]
        if len(rows) < len(out):
            columns = [[col[i] for i in rows] for col in columns]
        for i, text in zip(rows, map(",".join, zip(*columns))):
            out[i] = text
    return out


def tracked_iae(part: Any) -> np.ndarray:
    """Each run's IAE summed over its tracked outputs in their sorted order (as ``sum`` of the row's values); NaN
    without one, or when one has none."""
    total = np.full(len(part.ids), np.nan)
    for s, (tracked, _) in enumerate(part.shapes):
        mine = part.shape == s
        if tracked and mine.any():
            acc = np.zeros(int(mine.sum()))
            for t in tracked:
                acc = acc + part.judged.tracked[t]["iae"][mine]
            total[mine] = acc
    return total


def verdict_form(part: Any, i: int, failed: list[tuple[str, str]]) -> tuple[tuple, list[str]]:
    """What run ``i`` of ``part`` (a :class:`~.store.ReportPart`) says beyond its stored ``row``, given the criteria it
    ``failed`` (name, reason): its form (its status, ``pass``, ``fail`` or ``error``; the criteria it failed, sorted;
    which of ``complete``, ``run_reason``, ``worker`` the row lacks, each ``None`` in the verdict: an error's only
    ``worker``) and its reasons."""
    keys = int(part.keys[i])
    if part.error[i]:
        return ("error", ("error",), () if keys & ROW_BITS["worker"] else ("worker",)), [part.reasons[i]]
    missing = tuple(k for k, bit in ROW_BITS.items() if not keys & bit)
    return ("fail" if failed else "pass", tuple(sorted({k for k, _ in failed})), missing), [t for _, t in failed]


def verdict_head(part: Any, i: int, failed: list[tuple[str, str]]) -> dict:
    """Run ``i``'s verdict (:func:`verdict_form`) as a dict: its status, the criteria it failed and the reasons, and
    ``None`` for each key its row lacks."""
    (status, names, missing), reasons = verdict_form(part, i, failed)
    return {"status": status, "failed": list(names), "reasons": reasons} | dict.fromkeys(missing)


class JudgedPart(NamedTuple):
    """The runs of a block file judged (:func:`judge_part`), in the file's order: what :class:`.rows.Verdicts` keeps of
    each. ``lines``: each run's verdict as JSON text (empty for a run that passed), its ``campaign.csv`` status and
    reasons and its cells, each field followed by :data:`SEP`, the runs' lines one after the other (``sizes``: each
    one's bytes)."""

    ids: np.ndarray  # ASCII bytes
    shapes: list[tuple[tuple[str, ...], tuple[str, ...]]]  # the distinct (tracked outputs, outputs) of the runs
    shape: np.ndarray  # each run's, into ``shapes``
    forms: list[tuple]  # the verdict forms (:func:`verdict_form`) of the runs that did not pass, in the order met
    form: np.ndarray  # int16: each run's, into ``forms``; -1 for a run that passed
    iae: np.ndarray  # :func:`tracked_iae`
    model: np.ndarray  # the model twin's mismatch, NaN where none
    warning: np.ndarray  # bool: the model twin's warning
    lines: bytes
    sizes: np.ndarray  # int64


def judge_part(part: Any, criteria: Any) -> JudgedPart:
    """The runs of ``part`` (a :class:`~.store.ReportPart`) judged against ``criteria`` at once
    (:func:`.criteria.evaluate_columns` over the typed columns): each run's verdict, its ``campaign.csv`` texts and its
    numbers."""
    failed = evaluate_columns(criteria, part.judged)
    cells = part_cells(part)
    bad = np.fromiter(map(bool, failed), bool, len(failed)) | part.error
    texts, verdicts = [""] * len(cells), ["pass,"] * len(cells)
    form, forms, number = np.full(len(cells), -1, np.int16), [], {}
    for i in np.flatnonzero(bad).tolist():
        key, reasons = verdict_form(part, i, failed[i])
        if key not in number:
            number[key] = len(forms)
            forms.append(key)
        before, after, status = form_texts(key)
        texts[i] = before + ", ".join(map(encode_basestring_ascii, reasons)) + after
        verdicts[i] = status + csv_field("; ".join(reasons))
        form[i] = number[key]
    lines, sizes = _encoded(
        [text + SEP + verdict + SEP + cell + SEP for text, verdict, cell in zip(texts, verdicts, cells)]
    )
    return JudgedPart(
        ids=part.ids,
        shapes=part.shapes,
        shape=part.shape,
        forms=forms,
        form=form,
        iae=tracked_iae(part),
        model=part.model_mismatch,
        warning=part.model_warning,
        lines=lines,
        sizes=sizes,
    )


def _encoded(lines: list[str]) -> tuple[bytes, np.ndarray]:
    """``lines`` as UTF-8, one after the other, and each one's bytes: ASCII (the usual) encoded at once, a line's bytes
    its characters; else a line at a time."""
    spill = "".join(lines)
    if spill.isascii():
        return spill.encode("ascii"), np.array([len(x) for x in lines], np.int64)
    pieces = [x.encode("utf-8") for x in lines]
    return b"".join(pieces), np.array([len(x) for x in pieces], np.int64)


@functools.lru_cache(maxsize=1024)
def form_texts(key: tuple) -> tuple[str, str, str]:
    """The texts of the verdicts of form ``key`` (:func:`verdict_form`), made once: ``json.dumps`` of the verdict with
    its keys sorted around its reasons (each run's written in by json's own string encoder), and its CSV status."""
    status, names, missing = key
    text = json.dumps({"status": status, "failed": list(names), "reasons": []} | dict.fromkeys(missing),
                      sort_keys=True)  # fmt: skip
    before, after = text.split('"reasons": []')
    return before + '"reasons": [', "]" + after, status + ","
