"""gainlink.hil: hardware-in-the-loop bridge between a plant (FMU or built-in model) and the firmware.

Sub-packages, by part:

- :mod:`.plants`: the plant base class and registry, built-in models, FMUs through fmpy, the
  project's FMUs built from source, linearisation of an FMU to a spec;
- :mod:`.links`: the transport base class and registry, CAN (python-can, DBC layout, firmware CAN
  node), MAVLink (pymavlink), reference controller nodes, a Linux VM with a real SocketCAN vcan0;
- :mod:`.loop`: scenario, faults, scheduling, the controller peer process, the bridge loop, metrics,
  report and the anti-windup study; SIL (:mod:`.loop.sil`, the host C loop in-process, no bus);
- :mod:`.campaign`: many SIL/HIL runs over plant uncertainty, design grids and fault matrices on Dask
  (``gainlink campaign run|show``).

Entry points: ``gainlink hil run|dbc|fmu|study``, ``gainlink linearize``, ``gainlink firmware run --can``.
The vehicle-side MAVLink parameter upload is :mod:`gainlink.mavlink`.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any


def run(
    scenario: Any,
    *,
    artifact: Any = None,
    report: str | Path | None = None,
    plots: bool = True,
    progress: Callable[[int, int], None] | None = None,
) -> Any:
    """Run one HIL scenario: plant on this side, the controller (firmware) on the other, and return the result.

    Parameters
    ----------
    scenario : str, Path, dict or Scenario
        A scenario file, the name of a built-in scenario (``pendulum_fmu``), a scenario as a dict
        (the parsed TOML; relative paths are taken from the working directory) or a parsed Scenario.
    artifact : str, Path or Artifact, optional
        Replaces the scenario's artifact (an Artifact object is written to a temporary file for
        the controller process).
    report : str or Path, optional
        Also write the report folder there (report.json, plots, summary).
    plots : bool
        With ``report``: draw the PNG plots too.
    progress : callable, optional
        ``progress(done, total)``, called every few hundred steps.

    Returns
    -------
    RunResult
        ``metrics`` (as in report.json), ``trace`` (numpy arrays per step), ``complete`` and ``reason``.

    A scheduled artifact (schema 2) with ``controller = "firmware"`` (or ``"qemu"``: the Cortex-M image's node) and a
    CAN or MAVLink transport runs the firmware's node on the scheduled law over the link
    (:mod:`gainlink.hil.loop.can_scheduled`, in lockstep or real time; external scheduling signals travel after the
    references);
    otherwise (``controller = "reference"``, another transport) it runs as
    software in the loop in this process (:mod:`gainlink.hil.loop.sil_scheduled`: the transport is not used), sigma
    from its measured output or ``[schedule_signal]``.

    Examples
    --------
    >>> import gainlink as gl
    >>> res = gl.hil.run("pendulum_fmu", artifact="out/pendulum/gains.json")  # doctest: +SKIP
    >>> res.complete, res.trace.y.shape  # doctest: +SKIP
    (True, (1000, 2))
    """
    import dataclasses
    import tempfile

    from gainlink.errors import ScenarioError
    from gainlink.shipping.artifact import Artifact, load

    from .loop.report import write_report
    from .loop.scenario import is_builtin_scenario

    sc = _as_scenario(scenario)
    if artifact is None and is_builtin_scenario(sc.path):
        raise ScenarioError(
            f"the built-in scenario {sc.path.stem} runs an artifact of yours: give it (--artifact gains.json, "
            "as `gainlink design SPEC --out DIR` writes)"
        )
    with tempfile.TemporaryDirectory(prefix="gainlink-run-") as tmp:
        if isinstance(artifact, Artifact):
            path = Path(tmp) / "gains.json"
            artifact.save(path)
            sc = dataclasses.replace(sc, artifact_path=path)
        elif artifact is not None:
            sc = dataclasses.replace(sc, artifact_path=Path(artifact))
        loaded = load(sc.artifact_path)
        result = _run_loaded(loaded, sc, progress=progress)
        if report is not None:
            write_report(result, Path(report), artifact=loaded, with_plots=plots)
    return result


def _as_scenario(scenario: Any) -> Any:
    """A parsed Scenario from a Scenario, a dict, a file or a built-in scenario's name."""
    from .loop.scenario import Scenario, load_scenario, parse_scenario, resolve_scenario_path

    if isinstance(scenario, Scenario):
        return scenario
    if isinstance(scenario, dict):
        return parse_scenario(scenario)
    return load_scenario(resolve_scenario_path(str(scenario)))


def _run_loaded(artifact: Any, sc: Any, *, progress: Callable[[int, int], None] | None) -> Any:
    """The run of ``sc`` with its artifact loaded: a scheduled law over its link (or in process without one), else
    the bridge."""
    if artifact.schedule is None:
        from .loop.bridge import run_scenario

        return run_scenario(sc, progress=progress)
    from .loop.can_scheduled import over_link, run_scheduled_can
    from .loop.sil import run_sil

    if over_link(sc):  # the firmware's CAN or MAVLink node on the scheduled law, over the link
        return run_scheduled_can(artifact, sc, progress=progress)
    return run_sil(artifact, sc, progress=progress)
