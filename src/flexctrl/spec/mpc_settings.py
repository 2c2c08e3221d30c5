"""Typed, validated settings of the optimising controllers: linear MPC (with OSQP's) and NMPC.

Frozen dataclasses checked when built; :mod:`flexctrl.spec.controller_settings` describes the
conventions they share with the other controllers' settings (units, Bryson's-rule weights).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Literal

from flexctrl.errors import SpecError, keywords_checked
from flexctrl.spec.arrival import ArrivalSettings
from flexctrl.spec.controller_shared import (  # noqa: F401  (re-exported)
    BadMeasurement,
    ControllerKind,
    EstimatorSettings,
    Fallback,
    Formulation,
    FrequencySource,
    GravityCompensation,
    NLPSolver,
    NMPCMode,
    PredictionBasis,
    PredictionMap,
    QPBackend,
    RTIQPSolver,
    Scaling,
    Sensitivities,
    SensorSettings,
    Shaper,
    SoftConstraint,
    WarmStart,
    Weights,
)
from flexctrl.spec.field_checks import (
    boolean_field,
    choice_field,
    integer_field,
    number_field,
)
from flexctrl.spec.mpc_constraints import Bound, checked_bounds
from flexctrl.spec.payload_settings import PayloadSettings
from flexctrl.spec.raw_weights import Matrix, weight_matrix


@dataclass(frozen=True)
class OSQPSettings:
    """Settings passed to OSQP (names and meanings as in OSQP 1.x).

    ``scaling`` (OSQP's Ruiz equilibration) is off by default: the MPC scales its states
    itself, and Ruiz scaling on top of that multiplies OSQP's cold-start iterations on the
    flexible arms (``flexctrl bench mpc``, variant ``osqp_sparse_ruiz``).

    Attributes
    ----------
    eps_abs, eps_rel : float
        Absolute and relative tolerances of the residuals (scaled units of the QP).
    rho, sigma, alpha : float
        ADMM step size, regularisation and relaxation (``0 < alpha < 2``).
    adaptive_rho : bool
        Adapt ``rho`` during the iterations.
    adaptive_rho_interval : int
        Iterations between adaptations (0: OSQP's automatic choice).
    adaptive_rho_tolerance : float
        Factor of change below which ``rho`` is kept (>= 1).
    polishing : bool
        Polish the solution by one linear solve on the active set.
    max_iter : int
        Iteration limit per solve.
    time_limit : float
        Wall-time limit per solve, s; 0: none.
    check_termination : int
        Iterations between termination checks (0: never before ``max_iter``).
    scaling : int
        Ruiz equilibration iterations (0: off, the default).
    """

    eps_abs: float = 1e-3
    eps_rel: float = 1e-3
    rho: float = 0.1
    sigma: float = 1e-6
    alpha: float = 1.6
    adaptive_rho: bool = True
    adaptive_rho_interval: int = 0
    adaptive_rho_tolerance: float = 5.0
    polishing: bool = False
    max_iter: int = 1000
    time_limit: float = 0.0
    check_termination: int = 5
    scaling: int = 0

    def __post_init__(self) -> None:
        for name in ("eps_abs", "eps_rel"):
            number_field(name, getattr(self, name), low=0.0)
        for name in ("rho", "sigma"):
            number_field(name, getattr(self, name), low=0.0, low_open=True)
        number_field("alpha", self.alpha, low=0.0, high=2.0, low_open=True)
        boolean_field("adaptive_rho", self.adaptive_rho)
        integer_field("adaptive_rho_interval", self.adaptive_rho_interval, low=0)
        number_field("adaptive_rho_tolerance", self.adaptive_rho_tolerance, low=1.0)
        boolean_field("polishing", self.polishing)
        integer_field("max_iter", self.max_iter, low=1)
        number_field("time_limit", self.time_limit, low=0.0, unit="s")
        integer_field("check_termination", self.check_termination, low=0)
        integer_field("scaling", self.scaling, low=0)

    def as_dict(self) -> dict:
        """Keyword arguments for ``osqp.OSQP.setup``."""
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        out["time_limit"] = out["time_limit"] or 1e10
        return out


@keywords_checked
@dataclass(frozen=True)
class MPCSettings:
    """Linear MPC on the discretised linearization at the target, solved as one QP per sample.

    Attributes
    ----------
    kind : str
        ``"mpc"``, the controller this describes (fixed by the class).
    sample_time : float
        s.
    horizon : int
        Prediction steps N.
    weights : Weights
        Stage weights; the terminal weight is the DARE solution (``terminal = "dare"``).
    Q : array_like, optional
        Raw state weight on the design model's state ``(q, qd)`` in SI units (rad, m,
        rad/s, m/s), in the order of ``fc.linearize(model, op).state_labels`` or a designed
        controller's ``state_names``: a square matrix or a list (its diagonal), symmetric
        and positive semidefinite (:mod:`flexctrl.spec.raw_weights`).  Replaces the state
        magnitudes of ``weights`` (which still set the scaling).  Stored as a tuple of rows.
    R : array_like, optional
        Raw torque weight (per (N m)^2), one row per joint, symmetric positive definite;
        replaces ``weights.torque``.
    terminal : {"dare", "stage"}
        Terminal weight: the DARE solution at the target, or the stage weight.
    constraints : tuple of Bound
        Bounds on joint angles, joint rates, link deflections, the tip position and torque
        rates over the horizon, each hard or soft, named by signal
        (:mod:`flexctrl.spec.mpc_constraints`; ``[constraints]`` in files).  Torque-rate
        bounds need a backend other than HPIPM.
    soft : {"none", "deflection", "tip"}
        Soft constraint: every link's tip deflection ``|w_i| <= deflection_limit``, or the
        tip position error ``|p - p_target| <= tip_limit`` per component; with slack.
    deflection_limit, tip_limit : float
        m.
    slack_l1, slack_l2 : float
        Exact (L1, per m) and quadratic (per m^2) slack penalty, in units of the cost
        ``1/2 sum (x'Qx + u'Ru)``.
    formulation : {"sparse", "condensed"}
        States as variables (sparse) or eliminated (dense QP in the inputs).
    backend : {"osqp", "hpipm", "daqp", "qpoases"}
        QP solver: OSQP directly, or a solver shipped with CasADi via ``casadi.conic``.
    scaling : {"auto", "bryson", "none"}
        State scaling to O(1): from the LQR response, by the weights, or none
        (see :mod:`flexctrl.control.mpc.controller`).
    warm_start : {"shift", "previous", "none"}
        OSQP's start: the previous solution shifted by one stage, as it was, or cold.
    fallback : {"shift", "lqr", "hold"}
        When the QP is not solved: the previous plan shifted (then LQR once it runs out),
        LQR, or hold the previous torque.
    blocks : tuple of int
        Move blocking (condensed only): the horizon's samples in blocks over which the
        torque is held, e.g. ``[1, 1, 5, 10, ...]`` adding up to ``horizon``; empty: every
        move free.  A long horizon that covers a whole manoeuvre stays a small QP.
    constraint_stride : int
        Soft constraints on every ``constraint_stride``-th predicted state (condensed only).
    accept_inaccurate : bool
        Use an OSQP "solved inaccurate" solution instead of falling back.
    arrival : ArrivalSettings
        Minimum-time arrival (condensed only; :mod:`flexctrl.control.mpc.arrival_search`).
    osqp : OSQPSettings
        OSQP's settings (backend ``"osqp"``).
    sensors, estimator, on_bad_measurement
        As for LQR (a held sample solves the QP on the estimator's prediction).
    payload : PayloadSettings or None
        A payload range instead of the design model's one payload: the controller is
        payload-aware (:mod:`flexctrl.control.payload`).
    """

    kind: Literal["mpc"] = "mpc"
    sample_time: float = 0.01
    horizon: int = 20
    weights: Weights = field(default_factory=Weights)
    terminal: Literal["dare", "stage"] = "dare"
    soft: SoftConstraint = "deflection"
    deflection_limit: float = 0.05
    tip_limit: float = 0.05
    slack_l1: float = 1.0e5
    slack_l2: float = 1.0e7
    formulation: Formulation = "sparse"
    backend: QPBackend = "osqp"
    scaling: Scaling = "auto"
    warm_start: WarmStart = "shift"
    fallback: Fallback = "shift"
    accept_inaccurate: bool = True
    blocks: tuple[int, ...] = ()
    constraint_stride: int = 1
    arrival: ArrivalSettings = field(default_factory=ArrivalSettings)
    osqp: OSQPSettings = field(default_factory=OSQPSettings)
    sensors: SensorSettings = field(default_factory=SensorSettings)
    estimator: EstimatorSettings = field(default_factory=EstimatorSettings)
    on_bad_measurement: BadMeasurement = "raise"
    Q: Matrix | None = None
    R: Matrix | None = None
    constraints: tuple[Bound, ...] = ()
    payload: PayloadSettings | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "Q", weight_matrix("Q", self.Q))
        object.__setattr__(self, "R", weight_matrix("R", self.R))
        object.__setattr__(self, "constraints", checked_bounds(self.constraints))
        choice_field("kind", self.kind, Literal["mpc"])
        choice_field("on_bad_measurement", self.on_bad_measurement, BadMeasurement)
        number_field("sample_time", self.sample_time, low=0.0, low_open=True, unit="s")
        integer_field("horizon", self.horizon, low=1, high=1000)
        choice_field("terminal", self.terminal, Literal["dare", "stage"])
        choice_field("soft", self.soft, SoftConstraint)
        number_field("deflection_limit", self.deflection_limit, low=0.0, unit="m")
        number_field("tip_limit", self.tip_limit, low=0.0, unit="m")
        number_field("slack_l1", self.slack_l1, low=0.0)
        number_field("slack_l2", self.slack_l2, low=0.0, low_open=True)
        choice_field("formulation", self.formulation, Formulation)
        choice_field("backend", self.backend, QPBackend)
        choice_field("scaling", self.scaling, Scaling)
        choice_field("warm_start", self.warm_start, WarmStart)
        choice_field("fallback", self.fallback, Fallback)
        boolean_field("accept_inaccurate", self.accept_inaccurate)
        if self.backend == "hpipm" and self.formulation != "sparse":
            raise SpecError(
                f"value {self.formulation!r} is not allowed with backend 'hpipm'; "
                "allowed: 'sparse'",
                key="formulation",
            )
        if self.backend == "hpipm" and any(b.kind == "du" for b in self.constraints):
            raise SpecError(
                "torque-rate bounds couple two stages, which HPIPM's stage-wise QP cannot "
                "hold; allowed: backend 'osqp', 'daqp' or 'qpoases' with them",
                key="constraints",
            )
        if not isinstance(self.blocks, tuple) or not all(
            isinstance(b, int) and not isinstance(b, bool) and b >= 1 for b in self.blocks
        ):
            raise SpecError(
                f"value {self.blocks!r} is not allowed; allowed: a list of whole numbers >= 1 "
                "(samples per block)",
                key="blocks",
            )
        if self.blocks and sum(self.blocks) != self.horizon:
            raise SpecError(
                f"value {list(self.blocks)!r} covers {sum(self.blocks)} samples; allowed: "
                f"blocks that add up to the horizon ({self.horizon})",
                key="blocks",
            )
        if self.blocks and self.formulation != "condensed":
            raise SpecError(
                f"value {self.formulation!r} is not allowed with move blocking; "
                "allowed: 'condensed'",
                key="formulation",
            )
        integer_field("constraint_stride", self.constraint_stride, low=1, high=self.horizon)
        if self.constraint_stride > 1 and self.formulation != "condensed":
            raise SpecError(
                f"value {self.formulation!r} is not allowed with constraint_stride > 1; allowed: "
                "'condensed'",
                key="formulation",
            )
        if self.arrival.enabled and self.formulation != "condensed":
            raise SpecError(
                f"value {self.formulation!r} is not allowed with a minimum-time arrival; allowed: "
                "'condensed'",
                key="formulation",
            )


@keywords_checked
@dataclass(frozen=True)
class NMPCSettings:
    """Nonlinear MPC in CasADi: multiple shooting with RK4 on the full model.

    Attributes
    ----------
    kind : str
        ``"nmpc"``, the controller this describes (fixed by the class).
    sample_time : float
        s.
    horizon : int
        Shooting intervals N.
    substeps : int
        RK4 steps per interval; 0 (default): the fewest with ``|lambda|_max h <= 2.5`` for the
        linearization at the target (RK4 is stable on the imaginary axis up to 2.83).
    sensitivities : {"frozen", "midpoint", "exact"}
        RTI Jacobians of each shooting interval: of RK4 applied to the dynamics linearized
        at the start of each RK4 step (``"frozen"``: one Jacobian of ``f`` per RK4 step); of
        RK4 applied to the dynamics linearized once per interval at its middle RK4 node
        (``"midpoint"``: second order in the sample time, half the Jacobians of ``"frozen"``
        with 2 substeps); or exact derivatives of the nonlinear RK4 map (one Jacobian of
        ``f`` per RK4 stage).  The shooting gaps always use the nonlinear RK4 map
        (:mod:`flexctrl.control.nmpc.interval`).
    weights : Weights
        Stage weights; terminal weight from the DARE at the target.
    mode : {"rti", "full"}
        Real-time iteration (one SQP step per sample, Gauss-Newton QP) or a full NLP solve.
    nlp_solver : {"ipopt"}
        For ``full`` and for the RTI initialisation.
    qp_solver : {"hpipm", "osqp", "qpoases"}
        QP of the RTI (through ``casadi.conic``).
    max_iter : int
        NLP iterations (full mode).
    init_iter : int
        NLP iterations of the RTI initialisation at the first sample (0, default: start
        from the nonlinear rollout under the LQR law only).
    soft, deflection_limit, tip_limit, slack_l1, slack_l2
        As in :class:`MPCSettings`.
    compile : bool
        Generate and compile C for the sensitivities (cached on disk).
    prediction_modes : int
        Elastic modes per link of the model the NMPC predicts with: the lowest ones of the
        design model, a Galerkin truncation (:mod:`flexctrl.control.nmpc.prediction_model`); 0
        (default): all of them.  Fewer modes need fewer RK4 substeps (the fastest mode
        bounds the step); the estimator keeps the design model.
    prediction_basis : {"assumed", "coupled"}
        The reduced model's coordinates: the first ``prediction_modes`` assumed modes per
        link (``"assumed"``) or the joints and as many directions spanning the elastic
        parts of the design model's slowest coupled modes at the target (``"coupled"``,
        default; :func:`flexctrl.control.nmpc.prediction_model.coupled_basis`).
    prediction_map : {"modal", "select"}
        How a reduced prediction model (``prediction_modes > 0``) sees the design model's
        state: ``"modal"`` (default) removes the dropped (fast) modes of the linearization
        at the target before selecting the kept coordinates, so the fast modes are not fed
        back (:func:`flexctrl.control.nmpc.prediction_model.modal_map`); ``"select"`` takes the kept
        coordinates as they are (their fast-mode content destabilises the tuned loop,
        ``docs/guide/design-a-controller.md``).
    jacobian_every : int
        ``sensitivities = "frozen"`` only: one Jacobian of ``f`` per this many RK4 steps
        (1, default: every step), frozen over them (the transition of the frozen
        linearization over the steps is exact).
    stages_per_jacobian : int
        RTI only: one interval Jacobian ``(A, B)`` per this many consecutive shooting
        intervals of the horizon, taken at the middle interval of each group and held over
        it (1, default: every interval its own); the shooting ends stay nonlinear on every
        interval (:func:`flexctrl.control.nmpc.interval.symbolic_linearization`).
    qp_warm_start : bool
        HPIPM only: start its interior point from the shifted previous solution
        (HPIPM's ``warm_start = 1``, fewer iterations) instead of its default start.  The
        other QP solvers are always given it.
    sensors, estimator, on_bad_measurement
        As for LQR (a held sample solves on the estimator's prediction).
    """

    kind: Literal["nmpc"] = "nmpc"
    sample_time: float = 0.01
    horizon: int = 20
    substeps: int = 0
    sensitivities: Sensitivities = "frozen"
    weights: Weights = field(default_factory=Weights)
    mode: NMPCMode = "rti"
    nlp_solver: NLPSolver = "ipopt"
    qp_solver: RTIQPSolver = "hpipm"
    max_iter: int = 50
    init_iter: int = 0
    soft: SoftConstraint = "deflection"
    deflection_limit: float = 0.05
    tip_limit: float = 0.05
    slack_l1: float = 1.0e5
    slack_l2: float = 1.0e7
    compile: bool = True
    prediction_modes: int = 0
    prediction_basis: PredictionBasis = "coupled"
    prediction_map: PredictionMap = "modal"
    jacobian_every: int = 1
    stages_per_jacobian: int = 1
    qp_warm_start: bool = False
    sensors: SensorSettings = field(default_factory=SensorSettings)
    estimator: EstimatorSettings = field(default_factory=EstimatorSettings)
    on_bad_measurement: BadMeasurement = "raise"

    def __post_init__(self) -> None:
        choice_field("kind", self.kind, Literal["nmpc"])
        choice_field("on_bad_measurement", self.on_bad_measurement, BadMeasurement)
        number_field("sample_time", self.sample_time, low=0.0, low_open=True, unit="s")
        integer_field("horizon", self.horizon, low=1, high=1000)
        integer_field("substeps", self.substeps, low=0, high=200)
        choice_field("sensitivities", self.sensitivities, Sensitivities)
        choice_field("mode", self.mode, NMPCMode)
        choice_field("nlp_solver", self.nlp_solver, NLPSolver)
        choice_field("qp_solver", self.qp_solver, RTIQPSolver)
        integer_field("max_iter", self.max_iter, low=1)
        integer_field("init_iter", self.init_iter, low=0)
        choice_field("soft", self.soft, SoftConstraint)
        number_field("deflection_limit", self.deflection_limit, low=0.0, unit="m")
        number_field("tip_limit", self.tip_limit, low=0.0, unit="m")
        number_field("slack_l1", self.slack_l1, low=0.0)
        number_field("slack_l2", self.slack_l2, low=0.0, low_open=True)
        boolean_field("compile", self.compile)
        integer_field("prediction_modes", self.prediction_modes, low=0, high=6)
        choice_field("prediction_basis", self.prediction_basis, PredictionBasis)
        choice_field("prediction_map", self.prediction_map, PredictionMap)
        integer_field("jacobian_every", self.jacobian_every, low=1, high=200)
        integer_field("stages_per_jacobian", self.stages_per_jacobian, low=1, high=1000)
        boolean_field("qp_warm_start", self.qp_warm_start)


__all__ = ["MPCSettings", "NMPCSettings", "OSQPSettings"]
