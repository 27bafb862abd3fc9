"""The typed spec: frozen dataclasses that a spec file is parsed into once, and that design and analysis take.

Every table of a spec has its class here, holding values that are already checked and in the form the design
uses (weights as matrices, poles in the z-plane, the tracked outputs as a selector matrix). Nothing downstream
reads the user's raw tables again.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..lti import StateSpaceModel
from .pairs import integer


@dataclass(frozen=True)
class TransferFunctionSource:
    """A transfer-function plant as the user wrote it (p x m numerators, denominators and dead times in seconds)."""

    num: list
    den: list
    delay: list


@dataclass(frozen=True, kw_only=True)
class PlantModel(StateSpaceModel):
    """The plant as specified: ``A, B, C, D`` continuous (``kind`` continuous, or a transfer function realised with
    Padé delays; ``Ts`` None) or discrete (``kind`` discrete, sampled at the spec's ``Ts``), with its signal names."""

    kind: str
    pade_order: int | None = None
    transfer_function: TransferFunctionSource | None = None


@dataclass(frozen=True)
class ControllerSpec:
    """``[controller]``: how the state-feedback gain is obtained.

    ``lqr``: ``Q`` (n x n, on the plant state; from Q, Q_diag, Bryson's state maxima or ``C' diag(1/y_max^2) C``) and
    ``R`` (m x m). ``place``/``ackermann``: ``poles_z``, the n + q closed-loop poles in the z-plane. ``given``: the
    user's discrete-time ``K`` (m x n) and ``Ki`` (m x q).
    """

    method: str
    Q: np.ndarray | None = None
    R: np.ndarray | None = None
    poles_z: np.ndarray | None = None
    K: np.ndarray | None = None
    Ki: np.ndarray | None = None


@dataclass(frozen=True)
class IntegralSpec:
    """``[integral]``: integral action on the tracked outputs.

    ``Ci`` (q x p) selects the tracked outputs (``outputs`` are their indices); ``Qz`` (q x q) weighs the integrators
    in an LQR design (None when the controller does not use weights); ``aw_gain`` is the back-calculation gain.
    """

    outputs: tuple[int, ...]
    Ci: np.ndarray
    Qz: np.ndarray | None
    aw_gain: float

    @property
    def q(self) -> int:
        """Number of integrators."""
        return self.Ci.shape[0]


@dataclass(frozen=True)
class ObserverSpec:
    """``[observer]``: how the estimate is formed.

    ``kalman``: ``W`` (process noise covariance, size of the noise input), ``V`` (p x p), ``G`` (n x w) or
    ``G_is_B`` (noise enters with the inputs: G = Bd, known only after discretisation). ``luenberger``:
    ``poles_z`` (n). ``given``: ``L`` (predictor) or ``M`` (current form, ``L = Ad M``).
    """

    method: str
    form: str
    W: np.ndarray | None = None
    V: np.ndarray | None = None
    G: np.ndarray | None = None
    G_is_B: bool = False
    G_given: bool = False
    poles_z: np.ndarray | None = None
    L: np.ndarray | None = None
    M: np.ndarray | None = None


@dataclass(frozen=True)
class LimitsSpec:
    """``[limits]``: absolute actuator limits, the anti-windup mode (none | clamp | backcalc) and the declared ranges.

    ``y_min``/``y_max`` (p) and ``r_min``/``r_max`` (q) are the absolute ranges of the samples and references (None
    when not declared). A fixed-point law needs them: every bound of its certificate holds for inputs within them,
    and samples outside are clipped to them and flagged.
    """

    u_min: np.ndarray
    u_max: np.ndarray
    anti_windup: str
    y_min: np.ndarray | None = None
    y_max: np.ndarray | None = None
    r_min: np.ndarray | None = None
    r_max: np.ndarray | None = None


@dataclass(frozen=True)
class OperatingPoint:
    """The point the plant model is a linearisation about (docs/design.md, "The control law").

    ``u_op`` (m) and ``y_op`` (p) are the absolute command and measurement there; the model, the
    estimate and the design are deviations from them. ``x_op`` (n) is the state there, kept for the
    record (``None`` when the spec does not give it): the law does not use it.
    """

    u_op: np.ndarray
    y_op: np.ndarray
    x_op: np.ndarray | None = None


@dataclass(frozen=True)
class ImplementationSpec:
    """``[implementation]``: how the C runs the design (coordinates of the estimate, the float32 check, the number
    format).

    ``numeric`` is ``float32`` (the float C law) or a fixed-point law, ``q31`` (32-bit words) or ``q15`` (16-bit
    coefficients, samples and commands; 32-bit states). ``fixed_point_max_error`` is the largest certified
    deviation of a fixed-point command from the float64 law that the design accepts, as a fraction of each input's
    limit span (default 1/4096: one step of a 12-bit actuator command).
    """

    realization: str = "as_designed"
    float32_check: bool = True
    numeric: str = "float32"
    fixed_point_max_error: float = 1.0 / 4096

    @property
    def fixed_point(self) -> bool:
        """True for a fixed-point law (q31, q15)."""
        return integer(self.numeric)


@dataclass(frozen=True)
class ScheduleSpec:
    """``[schedule]`` with its ``[[schedule.plant]]`` entries: the law scheduled on a variable sigma.

    ``sigma`` names a measured output (``source == "output"``, ``index`` into the plant's outputs) or one of the
    ``external`` scheduling signals (``source == "external"``, ``index`` into ``external``). ``points`` (N >= 2,
    increasing) are where the plant is given: ``plants[i]`` (same names and state coordinates everywhere),
    ``operating_points[i]`` and ``controllers[i]`` (the controller table parsed against that point's plant: shared
    weights, or Bryson's output maxima giving each point its own ``Q``). ``rate_max`` (sigma units per second,
    None: not limited by the spec) and ``filter_tau`` (seconds, 0: no filter) shape sigma before the law uses it.
    ``rate_certified`` False declares the spec's ``rate_max`` shipped even where no certificate covers it (the
    artifact then says it is not certified); ``certify_budget`` is the CPU seconds the design's certificate
    searches may take (None: the design's default).
    """

    sigma: str
    source: str
    index: int
    external: tuple[str, ...]
    points: np.ndarray
    plants: tuple[PlantModel, ...]
    operating_points: tuple[OperatingPoint, ...]
    controllers: tuple[ControllerSpec, ...]
    rate_max: float | None = None
    filter_tau: float = 0.0
    rate_certified: bool = True
    certify_budget: float | None = None

    @property
    def size(self) -> int:
        """Number of points N."""
        return len(self.points)


@dataclass(frozen=True)
class MpcBox:
    """A soft box of ``[mpc] boxes``: a state (``kind = "state"``) or an output (``"output"``) by index, its absolute
    bounds (either may be infinite, not both)."""

    name: str
    kind: str
    index: int
    lo: float
    hi: float


@dataclass(frozen=True)
class MpcSpec:
    """``[mpc]`` with ``[controller] method = "mpc"``: the constrained law of docs/design.md, "MPC (the fourth law)".

    ``horizon`` N moves (x0 the estimate, moves u0..u(N-1), states x1..xN, terminal cost on xN); ``max_iter`` the ADMM
    iteration cap; ``rho`` the input slacks' penalty and ``rho_state`` the state boxes' (None: the default rules,
    3 mean(diag R) and 1000 rho); ``tol`` the stopping tolerance relative to each constrained signal's scale;
    ``boxes`` the soft state or output boxes, each penalised by ``box_weight`` times its squared violation (None: the
    default rule, 1e4 max(diag Q))."""

    horizon: int
    max_iter: int = 10
    rho: float | None = None
    rho_state: float | None = None
    tol: float = 1e-3
    boxes: tuple[MpcBox, ...] = ()
    box_weight: float | None = None


@dataclass(frozen=True)
class PlantSpec:
    """A validated plant spec: the plant and every design choice, typed.

    ``integral`` is ``None`` without integral action; ``operating_point`` is ``None`` when the spec has no
    ``[operating_point]`` table (the plant is about the origin). With a ``[schedule]``, ``schedule`` holds every
    point, and ``plant``, ``operating_point`` and ``controller`` are those of the first point (:meth:`at_point`
    gives the unscheduled spec of any point).
    """

    name: str
    Ts: float
    discretization: str
    plant: PlantModel
    controller: ControllerSpec
    integral: IntegralSpec | None
    observer: ObserverSpec
    limits: LimitsSpec
    operating_point: OperatingPoint | None = None
    implementation: ImplementationSpec = ImplementationSpec()
    source_sha256: str = ""
    source: str = "<dict>"
    description: str = ""
    linearization: dict | None = None  # the record `gainlink linearize` wrote, as written (for the provenance)
    schedule: ScheduleSpec | None = None
    units: dict[str, str] = field(default_factory=dict)  # [units]: signal name (or "time") -> unit
    mpc: MpcSpec | None = None  # [controller] method = "mpc": the horizon, the solver's settings, the soft boxes

    def at_point(self, i: int) -> PlantSpec:
        """The unscheduled spec of schedule point ``i``: its plant, operating point and controller weights."""
        s = self.schedule
        return replace(
            self,
            plant=s.plants[i],
            operating_point=s.operating_points[i],
            controller=s.controllers[i],
            schedule=None,
        )

    @property
    def q(self) -> int:
        """Number of integrators (0 without integral action)."""
        return 0 if self.integral is None else self.integral.q

    @property
    def Ci(self) -> np.ndarray:
        """The tracked-output selector (q x p; 0 x p without integral action)."""
        return np.zeros((0, self.plant.p)) if self.integral is None else self.integral.Ci
