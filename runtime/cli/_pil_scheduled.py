"""``gainlink pil run`` on a scheduled artifact: the scheduled image in QEMU (``gl_sched_step``) against a plant in
Python (:mod:`gainlink.hil.loop.pil_scheduled`); ``firmware.py`` hands it here."""

from __future__ import annotations

import argparse
import json

from ..errors import GainlinkError


def parse_signals(items: list[str] | None) -> dict[str, tuple[float, float]]:
    """``NAME=START[,END]`` per ``--schedule-signal``: a constant or a linear ramp over the run."""
    out = {}
    for item in items or ():
        name, _, values = item.partition("=")
        try:
            nums = [float(v) for v in values.split(",")]
        except ValueError:
            nums = []
        if not name or len(nums) not in (1, 2):
            raise GainlinkError(f"--schedule-signal {item!r}: give NAME=START or NAME=START,END (numbers)")
        out[name] = (nums[0], nums[-1])
    return out


def run(args: argparse.Namespace, artifact, platform) -> int:
    """Run the scheduled PIL of ``artifact`` as ``args`` say; print (and with ``--out`` write) its summary."""
    import numpy as np
    from gainlink.fileio import publish_files
    from gainlink.hil.loop.model_twin import model_mismatch
    from gainlink.hil.loop.pil import make_plant, twin_figure
    from gainlink.hil.loop.pil_scheduled import external_ramps, run_scheduled_pil
    from gainlink.proof.twin_plot import png_bytes

    signals = external_ramps(artifact, parse_signals(args.schedule_signal), args.steps)
    x0 = None if args.x0 is None else np.array(args.x0)
    plant = make_plant(args.plant, artifact=artifact, x0=x0)
    twin = make_plant(args.plant, artifact=artifact, x0=x0)
    result = run_scheduled_pil(artifact, plant=plant, steps=args.steps, reference=args.reference, signals=signals,
                               target=platform.target.name, board=platform.board.name, twin=twin)  # fmt: skip
    summary = {"artifact": artifact.name, "sha256": artifact.sha256, "target": platform.target.name,
               "board": platform.board.name, "plant": args.plant, **result.summary()}  # fmt: skip
    if result.model_twin is not None:
        t = np.arange(args.steps) * artifact.Ts
        start = result.scheduled.model_twin_start
        mismatch = model_mismatch(t=t, y=result.y, r=result.reference, model_y=result.model_twin.y, artifact=artifact,
                                  start=start)  # fmt: skip
        summary["model_twin"] = mismatch.to_dict()
    text = json.dumps(summary, indent=2) + "\n"
    if args.out:
        title = f"PIL {artifact.name} ({result.scheduled.law}) on {platform.board.name}, plant {args.plant}"
        files = {"pil.csv": pil_csv(artifact, result), "pil.json": text,
                 "twin.png": png_bytes(twin_figure(result, artifact, title=title))}  # fmt: skip
        publish_files(args.out, files)
    from ._pil_output import print_pil_summary

    return print_pil_summary(args, summary, artifact=artifact, json_text=text)


def pil_csv(artifact, result) -> str:
    """pil.csv of a scheduled run: per step the samples, commands, flags, sigma and its flags, and the twins'."""
    from gainlink.proof.scheduled_reference import SIGMA_CLIPPED, SIGMA_HELD, SIGMA_RATE

    a, tw, mt = artifact, result.twin, result.model_twin
    cols = ([f"y{i}" for i in range(a.p)] + [f"u{i}" for i in range(a.m)] + [f"sat{i}" for i in range(a.m)]
            + ["status", "sigma", "held", "clipped", "rate"] + [f"twin_y{i}" for i in range(a.p)]
            + [f"twin_u{i}" for i in range(a.m)])  # fmt: skip
    if mt is not None:
        cols += [f"model_y{i}" for i in range(a.p)] + [f"model_u{i}" for i in range(a.m)]
    rows = [",".join(cols)]
    for k in range(result.y.shape[0]):
        f = int(result.sigma_flags[k])
        vals = [repr(float(v)) for v in (*result.y[k], *result.u[k])]
        vals += [str(int(s)) for s in result.saturated[k]] + [str(int(result.status[k])), repr(float(result.sigma[k]))]
        vals += [str(int(bool(f & bit))) for bit in (SIGMA_HELD, SIGMA_CLIPPED, SIGMA_RATE)]
        vals += [repr(float(v)) for v in (*tw.y[k], *tw.u[k])]
        if mt is not None:
            vals += [repr(float(v)) for v in (*mt.y[k], *mt.u[k])]
        rows.append(",".join(vals))
    return "\n".join(rows) + "\n"
