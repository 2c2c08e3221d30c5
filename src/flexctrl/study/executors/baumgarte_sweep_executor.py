"""The ``baumgarte_sweep`` study executor: constraint drift and stability as gamma = beta sweeps.

One run simulates a ``kind = "sliding_beam"`` scene (e.g. ``studies/scenes/bk_fast_push.toml``)
with :func:`flexctrl.analysis.baumgarte.run_point` and sets beside it the discrete theory of
:mod:`flexctrl.analysis.baumgarte`.  Grid axes are scene overrides
(``"scene.baumgarte"``, ``"scene.dt"``, ``"scene.feedback"``).

Scene keys read here on top of the sliding-beam keys of :mod:`flexctrl.spec.fem_scene`
    ``baumgarte`` (1/s, >= 0)
        Sets ``gamma = beta`` to this value (replacing the file's ``gamma`` and ``beta``).
    ``gamma``, ``beta`` (1/s, >= 0; default 5)
        Used when ``baumgarte`` is absent; 0 switches the term off (the scene reader of
        :mod:`flexctrl.spec.fem_scene` requires > 0; this executor allows 0).
    ``feedback`` (``"explicit"``, default: Eq 54, violations of step i; ``"implicit"``)
    ``reference_dt`` (s, default 5e-5), ``reference_gamma`` (1/s, default 5)
        The converged reference (explicit feedback, gamma = beta = reference_gamma) that
        the tip error is measured against.
    ``max_violation`` (m) is the blow-up bound: a run whose ``max|Phi|`` exceeds it is
    recorded as unstable (``bounded = 0``, ``blowup_time_s``), not failed.

Metrics (SI): ``gamma_per_s``, ``beta_per_s``, ``dt_s``, ``gamma_dt``, ``feedback_implicit``
(0/1), ``bounded`` (0/1), ``time_bounded_s``, ``blowup_time_s`` (unstable runs only),
``max_phi_m``, ``final_phi_m``, ``max_phidot_m_s``, ``final_phidot_m_s`` (over the bounded
part), ``tip_error_max_m``, ``tip_error_rms_m`` (against the reference, over the bounded
part), ``predicted_spectral_radius``, ``predicted_stable`` (0/1), ``predicted_gamma_dt_limit``
(only if finite), ``measured_growth_per_step`` (unstable runs), and the linear error model
driven by the step defects of the gamma = 0 run at the same dt: ``model_max_phi_m``,
``model_max_phidot_m_s``, ``model_time_bounded_s``, ``model_bounded``.
Trajectories: ``t``, ``phi_max`` (m), ``phidot_max`` (m/s), ``tip_y`` (m).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import cast

import numpy as np

from flexctrl.analysis.baumgarte import (
    FEEDBACKS,
    Feedback,
    constraint_states,
    propagate_errors,
    run_point,
    spectral_radius,
    stability_limit,
    step_defects,
)
from flexctrl.dynamics.fem.sliding_beam import SlidingBeamCase, SlidingBeamModel
from flexctrl.errors import SimulationError, SpecError
from flexctrl.sim.tip_error import tip_error
from flexctrl.study.executors.baumgarte_report import report_sections as report_sections
from flexctrl.study.outputs import RunOutput, overrides_for, per_worker_cache

OWN_KEYS = ("baumgarte", "gamma", "beta", "feedback", "reference_dt", "reference_gamma")
MAX_REFERENCE_STEPS = 2_000_000


@dataclass(frozen=True)
class SweepScene:
    """A validated scene of one run (SI units; see the module docstring)."""

    case: SlidingBeamCase
    n_elements: int
    dt: float
    duration: float
    gamma: float
    beta: float
    feedback: Feedback
    alpha: float
    delta: float
    axial_shortening: bool
    max_violation: float
    reference_dt: float
    reference_gamma: float


@per_worker_cache(maxsize=64)
def read_sweep_scene(
    path: str, overrides: tuple[str, ...] = (), digest: str | None = None
) -> SweepScene:
    """Read and validate a sliding-beam scene with this executor's keys (memoised per worker).

    Raises
    ------
    SpecError
        Naming the scene file, the key, the value and what is allowed.
    """
    from flexctrl.spec.fem_scene import MAX_STEPS, SlidingBeamScene, read_fem_scene
    from flexctrl.spec.overrides import apply_overrides
    from flexctrl.spec.reader import TableReader, read_toml

    source = path if not overrides else f"{path} (with overrides {', '.join(overrides)})"
    document = apply_overrides(read_toml(path), overrides, source=source)
    own = {k: document.pop(k) for k in OWN_KEYS if k in document}
    s = read_fem_scene(document, source)
    if not isinstance(s, SlidingBeamScene):
        raise SpecError(
            f"value {s.kind!r} is not allowed for the baumgarte_sweep executor; allowed: "
            "'sliding_beam'",
            source=source,
            key="kind",
        )
    r = TableReader(own, source)
    gamma = r.nonnegative("gamma", 5.0, unit="1/s")
    beta = r.nonnegative("beta", 5.0, unit="1/s")
    if r.has("baumgarte"):
        gamma = beta = r.nonnegative("baumgarte", unit="1/s (sets gamma = beta)")
    feedback = r.string("feedback", "explicit", choices=FEEDBACKS)
    reference_dt = r.positive("reference_dt", 5e-5, unit="s")
    reference_gamma = r.positive("reference_gamma", 5.0, unit="1/s")
    r.finish()
    if s.duration / reference_dt > MAX_REFERENCE_STEPS:
        raise r.error(
            "reference_dt",
            f"value {reference_dt!r} needs {s.duration / reference_dt:.3g} steps over "
            f"{s.duration!r} s; allowed: at most {MAX_REFERENCE_STEPS:g} steps",
        )
    if s.duration / s.dt > MAX_STEPS:  # read_fem_scene checks this too; kept for clarity
        raise r.error("dt", f"value {s.dt!r} gives too many steps")
    case = SlidingBeamCase(
        s.name,
        C1=s.C1,
        C2=s.C2,
        T=s.T,
        tracked_end=s.tracked_end,
        driven_end=s.driven_end,
        L=s.L,
        rho=s.rho,
        EI=s.EI,
        D=s.D,
        tip_deflection=s.tip_deflection,
    )
    return SweepScene(
        case=case,
        n_elements=s.n_elements,
        dt=s.dt,
        duration=s.duration,
        gamma=gamma,
        beta=beta,
        feedback=cast(Feedback, feedback),  # r.string checked it against FEEDBACKS
        alpha=s.alpha,
        delta=s.delta,
        axial_shortening=s.axial_shortening,
        max_violation=s.max_violation,
        reference_dt=reference_dt,
        reference_gamma=reference_gamma,
    )


def _scene_of(settings: dict) -> SweepScene:
    return read_sweep_scene(
        settings["scene"],
        tuple(overrides_for(settings, "scene")),
        settings.get("digests", {}).get("scene"),
    )


def check_settings(settings: dict) -> None:
    """Validate the run's scene with its overrides (called before the study starts)."""
    _scene_of(settings)


@per_worker_cache(maxsize=4)
def _reference(
    case: SlidingBeamCase,
    n_elements: int,
    duration: float,
    alpha: float,
    delta: float,
    axial_shortening: bool,
    dt: float,
    gamma: float,
    bound: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Times (s) and tip displacement (m) of the converged reference run (built once per worker)."""
    point = run_point(
        case,
        n_elements,
        dt,
        gamma,
        gamma,
        feedback="explicit",
        duration=duration,
        alpha=alpha,
        delta=delta,
        axial_shortening=axial_shortening,
        max_violation=bound,
    )
    if not point.bounded or point.result is None:
        raise SimulationError(
            f"the reference run (dt = {dt:g} s, gamma = beta = {gamma:g} 1/s) is not bounded: "
            f"{point.error}"
        )
    return point.result.t, point.tip


@per_worker_cache(maxsize=8)
def _defects(
    case: SlidingBeamCase,
    n_elements: int,
    duration: float,
    alpha: float,
    delta: float,
    axial_shortening: bool,
    dt: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Initial error state and step defects of the gamma = beta = 0 run at this dt (built once per
    worker)."""
    point = run_point(
        case,
        n_elements,
        dt,
        0.0,
        0.0,
        duration=duration,
        alpha=alpha,
        delta=delta,
        axial_shortening=axial_shortening,
        max_violation=math.inf,
    )
    if not point.bounded or point.result is None:
        raise SimulationError(f"the gamma = 0 run at dt = {dt:g} s did not finish: {point.error}")
    model = SlidingBeamModel(case, n_elements, axial_shortening)
    states = constraint_states(model, point.result)
    return states[0], step_defects(states, alpha, delta)


def execute(settings: dict) -> RunOutput:
    """The ``baumgarte_sweep`` executor: one (dt, gamma, beta, feedback) run with theory beside
    it."""
    s = _scene_of(settings)
    point = run_point(
        s.case,
        s.n_elements,
        s.dt,
        s.gamma,
        s.beta,
        feedback=s.feedback,
        duration=s.duration,
        alpha=s.alpha,
        delta=s.delta,
        axial_shortening=s.axial_shortening,
        max_violation=s.max_violation,
    )
    h = point.dt
    g, b = s.gamma * h, s.beta * h
    ratio = s.beta / s.gamma if s.gamma > 0 else 1.0
    metrics: dict[str, float] = {
        "gamma_per_s": s.gamma,
        "beta_per_s": s.beta,
        "dt_s": h,
        "gamma_dt": g,
        "feedback_implicit": float(s.feedback == "implicit"),
        "bounded": float(point.bounded),
        "time_bounded_s": point.time_bounded,
        "predicted_spectral_radius": spectral_radius(g, b, s.feedback, s.alpha, s.delta),
    }
    metrics["predicted_stable"] = float(metrics["predicted_spectral_radius"] <= 1.0)
    limit = stability_limit(ratio, s.feedback, s.alpha, s.delta) if s.gamma > 0 else math.inf
    if math.isfinite(limit):
        metrics["predicted_gamma_dt_limit"] = limit
    if point.blowup_time is not None:
        metrics["blowup_time_s"] = point.blowup_time
    growth = point.growth_per_step()
    if growth is not None:
        metrics["measured_growth_per_step"] = growth
    trajectories: dict[str, np.ndarray] = {}
    if point.result is not None:
        res = point.result
        metrics.update(
            max_phi_m=float(res.phi_violation.max()),
            final_phi_m=float(res.phi_violation[-1]),
            max_phidot_m_s=float(res.phidot_violation.max()),
            final_phidot_m_s=float(res.phidot_violation[-1]),
        )
        ref_t, ref_tip = _reference(
            s.case,
            s.n_elements,
            s.duration,
            s.alpha,
            s.delta,
            s.axial_shortening,
            s.reference_dt,
            s.reference_gamma,
            s.max_violation,
        )
        if res.t.size >= 2:
            err = tip_error(ref_t, ref_tip, res.t, point.tip)
            metrics.update(tip_error_max_m=err.max, tip_error_rms_m=err.rms)
        trajectories = {
            "t": res.t,
            "phi_max": res.phi_violation,
            "phidot_max": res.phidot_violation,
            "tip_y": point.tip,
        }
    x0, defects = _defects(
        s.case, s.n_elements, s.duration, s.alpha, s.delta, s.axial_shortening, s.dt
    )
    pred = propagate_errors(
        x0, defects, g, b, h, s.feedback, s.alpha, s.delta, bound=s.max_violation
    )
    metrics.update(
        model_max_phi_m=pred.max_phi,
        model_max_phidot_m_s=pred.max_phidot,
        model_time_bounded_s=pred.steps_bounded * h,
        model_bounded=float(not pred.exceeded),
    )
    return RunOutput(metrics=metrics, trajectories=trajectories)
