"""gainlink.hil: hardware-in-the-loop bridge between a plant (FMU or built-in model) and the firmware.

Sub-packages, by part:

- :mod:`.plants`: the plant base class and registry, built-in models, FMUs through fmpy, the
  project's FMUs built from source, linearisation of an FMU to a spec;
- :mod:`.links`: the transport base class and registry, CAN (python-can, DBC layout, firmware CAN
  node), MAVLink (pymavlink), reference controller nodes, a Linux VM with a real SocketCAN vcan0;
- :mod:`.loop`: scenario, plan, faults, scheduling, the controller peer process, the one closed loop and its
  endpoints (in process: SIL; over a link: HIL), the twins, metrics, report and the studies;
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
    """Run one scenario: the plant on this side, the law on the other (in process without a ``[transport]``, over
    the link with one), and return the result.

    Parameters
    ----------
    scenario : str, Path, dict or Scenario
        A scenario file, the name of a built-in scenario (``pendulum_fmu``), a scenario as a dict
        (the parsed TOML; relative paths are taken from the working directory) or a parsed Scenario.
    artifact : str, Path or Artifact, optional
        Replaces the scenario's artifact (an Artifact object runs as it is; a peer process that reads a file gets
        one written once).
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

    Every law runs every way (:func:`gainlink.laws.law_of` says which law the artifact runs): the controller
    ``reference`` is the law's float64 reference, ``firmware`` its C (the host library in process, or the
    firmware's host app for the link), ``qemu`` the Cortex-M image's node on its UART; a scheduled law takes sigma
    from its measured output or ``[schedule_signal]``, its external signals travel after the references
    (:mod:`gainlink.hil.loop.bridge`).

    Examples
    --------
    >>> import gainlink as gl
    >>> res = gl.hil.run("pendulum_fmu", artifact="out/pendulum/gains.json")  # doctest: +SKIP
    >>> res.complete, res.trace.y.shape  # doctest: +SKIP
    (True, (1000, 2))
    """
    from gainlink.errors import ScenarioError

    from .loop.bridge import run_scenario
    from .loop.report import write_report
    from .loop.scenario import is_builtin_scenario

    sc = _as_scenario(scenario)
    if artifact is None and is_builtin_scenario(sc.path):
        raise ScenarioError(
            f"the built-in scenario {sc.path.stem} runs an artifact of yours: give it (--artifact gains.json, "
            "as `gainlink design SPEC --out DIR` writes)"
        )
    result = run_scenario(sc, artifact=artifact, progress=progress)
    if report is not None:
        write_report(result, Path(report), with_plots=plots)
    return result


def _as_scenario(scenario: Any) -> Any:
    """A parsed Scenario from a Scenario, a dict, a file or a built-in scenario's name."""
    from .loop.scenario import Scenario, load_scenario, parse_scenario, resolve_scenario_path

    if isinstance(scenario, Scenario):
        return scenario
    if isinstance(scenario, dict):
        return parse_scenario(scenario)
    return load_scenario(resolve_scenario_path(str(scenario)))
