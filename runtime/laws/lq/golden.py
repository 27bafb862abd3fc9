"""Golden vectors: random stabilizable designs and sample sequences, answered by the float64 reference.

Nothing here is pasted: plants are drawn from a seeded generator, designed with
:func:`gainlink.design.design` like any user spec, and the expected outputs come from
:class:`gainlink.proof.reference.ReferenceLoop`. ``scripts/gen_golden.py`` writes them to files; the tests
call :func:`random_cases` / :func:`example_cases` directly.
"""

from __future__ import annotations

import functools
import itertools
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import DesignError, SpecError
from ...proof.reference import ReferenceLoop, Trace
from ...shipping.artifact import Artifact, from_dict, render
from ...spec import load_spec, parse_spec
from ...synthesis.pipeline import synthesize_lq
from .design import float32_check

EXAMPLES = ("pendulum", "quadrotor_lateral", "wood_berry")
FORMS = ("predictor", "current")
ANTI_WINDUP = ("none", "clamp", "backcalc")


@dataclass(frozen=True)
class GoldenCase:
    """One artifact, its input samples and the reference's answer."""

    label: str
    artifact: Artifact
    Y: np.ndarray  # (N, p)
    R: np.ndarray  # (N, q)
    expected: Trace


def _signals(rng: np.random.Generator, *, N: int, width: int, scale: float) -> np.ndarray:
    """Smooth random signals: a few sinusoids plus white noise, ``scale`` in amplitude."""
    t = np.arange(N)[:, None]
    out = np.zeros((N, width))
    for _ in range(3):
        freq = rng.uniform(0.002, 0.05, size=width)
        phase = rng.uniform(0, 2 * np.pi, size=width)
        out += rng.uniform(0.2, 1.0, size=width) * np.sin(2 * np.pi * freq * t + phase)
    out += 0.1 * rng.standard_normal((N, width))
    return scale * out / 3.0


def random_spec(
    seed: int,
    *,
    n: int,
    m: int,
    p: int,
    q: int,
    form: str,
    anti_windup: str,
    feedthrough: bool,
    u_limit: np.ndarray | None = None,
    operating_point: dict | None = None,
) -> dict:
    """A random discrete plant spec (a few unstable modes) with LQR(I) + Kalman design choices.

    With ``operating_point`` (``{"u_op": [...], "y_op": [...]}``) the plant is about that point and the
    limits are ``u_op -+ u_limit``.
    """
    rng = np.random.default_rng(seed)
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    radii = rng.uniform(0.5, 1.08, size=n)
    A = Q @ np.diag(radii) @ Q.T + 0.05 * rng.standard_normal((n, n))
    B = rng.standard_normal((n, m))
    C = rng.standard_normal((p, n))
    D = 0.1 * rng.standard_normal((p, m)) if feedthrough else np.zeros((p, m))
    limit = np.full(m, 1e6) if u_limit is None else np.asarray(u_limit)
    centre = np.zeros(m) if operating_point is None else np.asarray(operating_point["u_op"], dtype=float)
    spec = {
        "name": f"rand{seed}",
        "Ts": 0.01,
        "plant": {"kind": "discrete", "A": A.tolist(), "B": B.tolist(), "C": C.tolist(), "D": D.tolist()},
        "controller": {"method": "lqr", "Q_diag": [1.0] * n, "R_diag": [1.0] * m},
        "observer": {"method": "kalman", "form": form, "W_diag": [1e-2] * n, "V_diag": [1e-2] * p},
        "limits": {"u_min": (centre - limit).tolist(), "u_max": (centre + limit).tolist(), "anti_windup": anti_windup},
    }
    if operating_point is not None:
        spec["operating_point"] = {k: list(map(float, v)) for k, v in operating_point.items()}
    if q > 0:
        spec["integral"] = {"outputs": sorted(rng.choice(p, size=q, replace=False).tolist()), "Q_diag": [0.5] * q}
    return spec


def _design(spec: dict) -> Artifact:
    return from_dict(synthesize_lq(parse_spec(spec), float32_check).artifact)


def random_operating_point(seed: int, *, m: int, p: int) -> dict:
    """A non-zero operating point drawn from ``seed``: entries of a few units, each sign."""
    rng = np.random.default_rng(seed + 20_000)
    return {"u_op": rng.uniform(-4.0, 4.0, size=m).tolist(), "y_op": rng.uniform(-6.0, 6.0, size=p).tolist()}


def random_case(
    seed: int,
    *,
    n: int,
    m: int,
    p: int,
    q: int,
    form: str,
    anti_windup: str,
    N: int = 400,
    operating_point: bool = False,
) -> GoldenCase:
    """A random stabilizable design whose inputs saturate on part of the golden samples.

    The plant is designed once with wide limits to see the size of the command, then again with
    limits at 60 % of the largest unsaturated command, so the replay visits both regimes. With
    ``operating_point`` the plant is about a random non-zero point (:func:`random_operating_point`), the
    limits are centred on ``u_op`` and the samples are absolute: ``y_op`` plus the same signals, and
    references ``Ci y_op`` plus the same signals.
    """
    feedthrough = form == "predictor" and seed % 2 == 0
    kw = dict(n=n, m=m, p=p, q=q, form=form, anti_windup=anti_windup, feedthrough=feedthrough)
    wide = _design({**random_spec(seed, **kw), "implementation": {"float32_check": False}})  # sizing only
    rng = np.random.default_rng(seed + 10_000)
    Y = _signals(rng, N=N, width=p, scale=1.0)
    R = _signals(rng, N=N, width=q, scale=1.0) if q else np.zeros((N, 0))
    free = ReferenceLoop(wide).run(Y, R)
    limit = 0.6 * np.max(np.abs(free.u), axis=0) + 1e-3
    op = random_operating_point(seed, m=m, p=p) if operating_point else None
    art = _design(random_spec(seed, u_limit=limit, operating_point=op, **kw))
    Y, R = Y + art.y_op, R + art.r_op
    label = f"rand{seed}-n{n}m{m}p{p}q{q}-{form}-{anti_windup}" + ("-op" if operating_point else "")
    return GoldenCase(label=label, artifact=art, Y=Y, R=R, expected=ReferenceLoop(art).run(Y, R))


def random_cases(count: int = 30, *, first_seed: int = 1, N: int = 400) -> tuple[GoldenCase, ...]:
    """``count`` random designs covering n up to 12, m and p up to 4, q = 0 or more, both forms, every
    anti-windup mode (cycled so every combination of form and mode appears), every second block of six
    about a non-zero operating point. Cached per arguments."""
    return _random_cases(count, first_seed, N)


@functools.lru_cache(maxsize=4)
def _random_cases(count: int, first_seed: int, N: int) -> tuple[GoldenCase, ...]:
    combos = list(itertools.product(FORMS, ANTI_WINDUP))
    cases = []
    seed = first_seed
    while len(cases) < count:
        rng = np.random.default_rng(seed)
        i = len(cases)
        n = [2, 3, 4, 6, 8, 12][i % 6]
        m = int(rng.integers(1, 5))
        p = int(rng.integers(1, 5))
        q = int(rng.integers(0, min(m, p) + 1)) if i % 3 else 0
        form, aw = combos[i % len(combos)]
        if q == 0 and aw != "none":
            q = 1 if min(m, p) >= 1 else 0
        try:
            case = random_case(
                seed, n=n, m=m, p=p, q=q, form=form, anti_windup=aw, N=N, operating_point=(i // len(combos)) % 2 == 1
            )
        except (DesignError, SpecError):
            case = None  # an unlucky draw (e.g. a plant zero at z = 1 with integral action)
        if case is not None and bounded(case):
            cases.append(case)
        seed += 1
    return tuple(cases)


def bounded(case: GoldenCase, *, limit: float = 1e3) -> bool:
    """Whether the reference replay stays bounded (|xh|, |z| below ``limit`` for unit-size samples).

    Replaying arbitrary measurements opens the loop; with heavy saturation and a large default
    back-calculation gain some random controllers then have unstable internal dynamics, and comparing
    two divergent trajectories says nothing about the implementation. Such draws are skipped.
    """
    e = case.expected
    return bool(np.all(np.abs(e.xh) < limit) and np.all(np.abs(e.z) < limit))


def closed_loop_case(
    seed: int,
    *,
    n: int,
    m: int,
    p: int,
    q: int,
    form: str,
    anti_windup: str,
    N: int = 300,
    operating_point: bool = False,
) -> GoldenCase:
    """A random continuous plant (:func:`gainlink.synthesis.random_plants.random_spec`), designed, and a record of
    its own closed loop (:func:`gainlink.proof.simulation.simulate_linear`: initial state, reference, noise).

    Unlike :func:`random_cases`, nothing is filtered: such designs often have an unstable compensator.
    The limits are set below the unsaturated run's peak command (80 %, else 90 %, else wide) so the
    record saturates during the initial transient and still stays bounded. With ``operating_point`` the
    plant is about a random non-zero point, the limits are centred on ``u_op`` and the record is absolute.
    """
    from ...proof.simulation import simulate_linear
    from ...synthesis.random_plants import random_spec as continuous_spec

    op = random_operating_point(seed, m=m, p=p) if operating_point else None

    def spec(limit: float, **extra) -> dict:
        out = {
            **continuous_spec(
                seed,
                n=n,
                m=m,
                p=p,
                q=q,
                form=form,
                anti_windup=anti_windup,
                u_limit=limit,
                feedthrough=form == "predictor" and seed % 2 == 0,
            ),
            **extra,
        }
        if op is not None:
            out["operating_point"] = op
            out["limits"] = dict(
                out["limits"], u_min=[u - limit for u in op["u_op"]], u_max=[u + limit for u in op["u_op"]]
            )
        return out

    rng = np.random.default_rng(seed + 20_000)
    x0, ref = rng.standard_normal(n), rng.uniform(-0.5, 0.5, size=q)

    def record(art: Artifact):
        return simulate_linear(art, steps=N, x0=x0, reference=art.r_op + ref, noise_std=0.01, seed=seed)

    wide = _design(spec(1e6, implementation={"float32_check": False}))
    free = record(wide)
    peak = float(np.max(np.abs(free.u - wide.u_op)))
    excursion = max(1.0, float(np.max(np.abs(free.y - wide.y_op))))
    for fraction in (0.8, 0.9, None):
        art = _design(spec(1e6 if fraction is None else fraction * peak))
        sim = record(art)
        if np.all(np.abs(sim.y - art.y_op) < 10.0 * excursion):
            break
    label = f"loop{seed}-n{n}m{m}p{p}q{q}-{form}-{anti_windup}" + ("-op" if operating_point else "")
    return GoldenCase(label=label, artifact=art, Y=sim.y, R=sim.r, expected=ReferenceLoop(art).run(sim.y, sim.r))


def closed_loop_cases(count: int = 12, *, first_seed: int = 100, N: int = 300) -> tuple[GoldenCase, ...]:
    """``count`` :func:`closed_loop_case` designs cycling through both forms, every anti-windup mode and
    q = 0 / q > 0, n from 3 to 8; every second block of six is about a non-zero operating point. Cached
    per arguments."""
    return _closed_loop_cases(count, first_seed, N)


@functools.lru_cache(maxsize=2)
def _closed_loop_cases(count: int, first_seed: int, N: int) -> tuple[GoldenCase, ...]:
    combos = list(itertools.product(FORMS, ANTI_WINDUP))
    cases = []
    seed = first_seed
    while len(cases) < count:
        i = len(cases)
        form, aw = combos[i % len(combos)]
        n = [3, 5, 7, 4, 6, 8][i % 6]
        m, p = 1 + i % 2, 2 + i % 2
        q = 0 if (aw == "none" and i % 4 == 0) else 1 + (i % min(m, p))
        try:
            cases.append(
                closed_loop_case(
                    seed,
                    n=n,
                    m=m,
                    p=p,
                    q=q,
                    form=form,
                    anti_windup=aw,
                    N=N,
                    operating_point=(i // len(combos)) % 2 == 1,
                )
            )
        except (DesignError, SpecError):
            pass  # an unlucky draw
        seed += 1
    return tuple(cases)


def example_cases(examples_dir: Path, *, N: int = 600, seed: int = 7) -> tuple[GoldenCase, ...]:
    """Golden samples for the shipped examples (``examples/*.toml``), scaled up until some inputs saturate."""
    return _example_cases(Path(examples_dir).resolve(), N, seed)


@functools.lru_cache(maxsize=4)
def _example_cases(examples_dir: Path, N: int, seed: int) -> tuple[GoldenCase, ...]:
    cases = []
    for name in EXAMPLES:
        art = from_dict(synthesize_lq(load_spec(examples_dir / f"{name}.toml"), float32_check).artifact)
        rng = np.random.default_rng(seed)
        Y0 = _signals(rng, N=N, width=art.p, scale=1.0)
        R0 = _signals(rng, N=N, width=art.q, scale=1.0) if art.q else np.zeros((N, 0))
        scale = 0.5
        for _ in range(12):
            Y, R = scale * Y0, 4.0 * scale * R0
            expected = ReferenceLoop(art).run(Y, R)
            if expected.saturated.any(axis=1).mean() >= 0.05:
                break
            scale *= 2.0
        cases.append(GoldenCase(label=name, artifact=art, Y=Y, R=R, expected=expected))
    return tuple(cases)


def write_case(case: GoldenCase, out_dir: Path) -> Path:
    """Write ``<label>.gains.json`` and ``<label>.npz`` (Y, R and the reference's u, sat, xh, z, fault)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / f"{case.label}.gains.json").write_text(render(case.artifact.data), "utf-8")
    e = case.expected
    path = out_dir / f"{case.label}.npz"
    np.savez(path, Y=case.Y, R=case.R, u=e.u, saturated=e.saturated, xh=e.xh, z=e.z, fault=e.fault)
    return path


def write_index(cases: list[GoldenCase] | tuple[GoldenCase, ...], out_dir: Path) -> Path:
    """Write ``index.json`` listing the cases with their dimensions and artifact sha256."""
    index = [
        {
            "label": c.label,
            "sha256": c.artifact.sha256,
            "n": c.artifact.n,
            "m": c.artifact.m,
            "p": c.artifact.p,
            "q": c.artifact.q,
            "observer_form": c.artifact.observer_form,
            "anti_windup": c.artifact.anti_windup,
            "steps": int(c.Y.shape[0]),
            "saturated_steps": int(c.expected.saturated.any(axis=1).sum()),
            "operating_point": c.artifact.has_operating_point,
        }
        for c in cases
    ]
    path = out_dir / "index.json"
    path.write_text(json.dumps(index, indent=2) + "\n", "utf-8")
    return path
