"""Random stabilizable plant specs, for verification across many designs (tests, golden vectors, benchmarks).

Random Gaussian matrices are controllable and observable with probability one; the generator
also makes some modes unstable so that every design has real work to do.
"""

from __future__ import annotations

import numpy as np


def random_spec(
    seed: int,
    *,
    n: int,
    m: int,
    p: int,
    q: int = 0,
    form: str = "predictor",
    anti_windup: str = "none",
    feedthrough: bool = False,
    u_limit: float = 1.0,
    Ts: float = 0.02,
) -> dict:
    """A spec dict (for :func:`gainlink.spec.parse_spec`) of a random continuous plant.

    Parameters
    ----------
    seed : int
        Seed of the generator: the same arguments give the same spec.
    n, m, p : int
        States, inputs, outputs.
    q : int
        Number of tracked outputs with integral action (the first q outputs); q <= min(m, p).
    form : {"predictor", "current"}
        Observer form.
    anti_windup : {"none", "clamp", "backcalc"}
        Anti-windup mode.
    feedthrough : bool
        Give the plant a random D (predictor form only).
    u_limit : float
        Symmetric actuator limit, small enough that ordinary inputs saturate.
    Ts : float
        Sample time.
    """
    if q > min(m, p):
        raise ValueError("q must not exceed min(m, p)")
    if feedthrough and form == "current":
        raise ValueError("the current observer form needs D = 0")
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n)) / np.sqrt(n)
    A -= 0.3 * np.eye(n)  # most modes stable, a few unstable
    B = rng.standard_normal((n, m))
    C = rng.standard_normal((p, n))
    plant = {"kind": "continuous", "A": A.tolist(), "B": B.tolist(), "C": C.tolist()}
    if feedthrough:
        plant["D"] = (0.1 * rng.standard_normal((p, m))).tolist()
    spec = {
        "name": f"random_{seed}",
        "Ts": Ts,
        "plant": plant,
        "controller": {"method": "lqr", "Q_diag": [1.0] * n, "R_diag": [0.5] * m},
        "observer": {"method": "kalman", "form": form, "W_diag": [0.01] * n, "V_diag": [0.01] * p},
        "limits": {"u_min": [-u_limit] * m, "u_max": [u_limit] * m, "anti_windup": anti_windup},
    }
    if q:
        spec["integral"] = {"outputs": list(range(q)), "Q_diag": [1.0] * q}
    return spec
