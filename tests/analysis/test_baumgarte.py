"""Baumgarte stabilisation under Newmark: discrete theory against the beam-over-supports runs (issue
7)."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest
from support import DATA

from flexctrl.analysis.baumgarte import (
    EXPLICIT_LIMIT,
    constraint_states,
    defect_gain,
    error_amplification,
    fastest_decay,
    propagate_errors,
    run_point,
    spectral_radius,
    stability_limit,
    steady_drift_response,
    step_defects,
)
from flexctrl.dynamics.fem.sliding_beam import FAST_PUSH, SlidingBeamModel
from flexctrl.errors import SpecError
from flexctrl.study.executors.baumgarte_sweep_executor import read_sweep_scene

STUDY = DATA / "studies" / "baumgarte_sweep.toml"
SCENE = DATA / "studies" / "scenes" / "bk_fast_push.toml"
DT = 1e-3


@pytest.fixture(scope="module")
def unstabilised():
    """gamma = beta = 0 at 1 ms over the whole push and 0.3 s after it (no bound)."""
    return run_point(FAST_PUSH, 4, DT, 0.0, 0.0, duration=1.0, max_violation=math.inf)


# -- theory ---------------------------------------------------------------------------------


@pytest.mark.parametrize("g, b", [(0.3, 0.3), (1.0, 2.0), (2.5, 0.7)])
def test_characteristic_polynomials(g, b):
    """np.poly of G equals the hand-derived polynomials (explicit: one step of lag; implicit:
    trapezoidal)."""
    pm = np.polynomial.polynomial
    lag, damping, stiffness = (
        pm.polypow([-1, 1], 2),
        g * np.array([-1.0, 0.0, 1.0]),
        b * b / 4 * pm.polypow([1, 1], 2),
    )
    # ascending coefficients; np.poly gives descending ones of the monic polynomial
    explicit = pm.polyadd(pm.polyadd(pm.polymul([0, 1], lag), damping), stiffness)[::-1]
    quad = pm.polyadd(pm.polyadd(lag, damping), stiffness)
    implicit = pm.polymul([0, 1], quad / quad[-1])[::-1]
    np.testing.assert_allclose(np.poly(error_amplification(g, b, "explicit")), explicit, atol=1e-12)
    np.testing.assert_allclose(np.poly(error_amplification(g, b, "implicit")), implicit, atol=1e-12)


def test_implicit_feedback_is_the_trapezoidal_rule_on_the_error_ode():
    """Eigenvalues = (1 + s h/2) / (1 - s h/2) for the roots s of s^2 + 2 gamma s + beta^2
    (A-stable)."""
    gamma, beta, h = 30.0, 20.0, 0.01
    s = np.roots([1.0, 2 * gamma, beta**2])
    expected = sorted((1 + s * h / 2) / (1 - s * h / 2), key=lambda z: (z.real, z.imag))
    got = [
        z
        for z in np.linalg.eigvals(error_amplification(gamma * h, beta * h, "implicit"))
        if abs(z) > 1e-12
    ]
    np.testing.assert_allclose(sorted(got, key=lambda z: (z.real, z.imag)), expected, atol=1e-12)
    assert stability_limit(1.0, "implicit") == math.inf
    assert spectral_radius(1e3, 1e3, "implicit") < 1.0 < spectral_radius(1e3, 1e3, "explicit")


def test_explicit_limit_is_three_minus_sqrt5_and_decay_saturates_before_it():
    """Bisection on the spectral radius finds Jury's closed form; the fastest decay lies below the
    limit."""
    assert stability_limit(1.0, "explicit") == pytest.approx(3.0 - math.sqrt(5.0), rel=1e-9)
    assert EXPLICIT_LIMIT == pytest.approx(3.0 - math.sqrt(5.0), rel=1e-15)
    g_opt, rho_min = fastest_decay(1.0, "explicit")
    assert 0.0 < g_opt < EXPLICIT_LIMIT and rho_min < 1.0
    for g in (0.5 * g_opt, 0.5 * (g_opt + EXPLICIT_LIMIT)):
        assert spectral_radius(g, g) > rho_min
    # below gamma h ~ 0.01 the discrete decay is the continuous exp(-gamma h) (critically damped)
    assert spectral_radius(1e-3, 1e-3) == pytest.approx(math.exp(-1e-3), abs=1e-4)


@pytest.mark.parametrize("feedback", ["explicit", "implicit"])
def test_steady_drift_response_by_iteration(feedback):
    """A constant position defect d per step settles at e = 2 gamma d / (beta^2 h), h e' = -d
    (either feedback)."""
    g = b = 0.2
    G, M = error_amplification(g, b, feedback), defect_gain(g, b, feedback)
    x, d = np.zeros(3), np.array([1.0, 0.0, 0.0])
    for _ in range(2000):
        x = G @ x + M @ d
    np.testing.assert_allclose(x, steady_drift_response(g, b), atol=1e-9)
    np.testing.assert_allclose(steady_drift_response(g, b), [2 * g / b**2, -1.0, 0.0], atol=1e-12)


# -- measured ---------------------------------------------------------------------------------


def test_unstabilised_drift_grows_linearly_once_the_motion_stops(unstabilised):
    """gamma = beta = 0: G has the Jordan block of eigenvalue 1, so after T (constant constraint
    rows,
    no defects) the velocity violation stays frozen and |Phi| grows linearly at that rate."""
    p = unstabilised
    assert p.bounded and p.result.t[-1] == pytest.approx(1.0)
    G0 = error_amplification(0.0, 0.0)
    assert np.allclose(np.linalg.matrix_power(G0, 10)[0, 1], 10.0)  # e_n = e_0 + n h e'_0 + ...
    x = constraint_states(SlidingBeamModel(FAST_PUSH, 4), p.result)
    after = p.result.t >= FAST_PUSH.T - 1e-12
    e, ed = x[after, 0, :], x[after, 1, :] / p.dt
    t = p.result.t[after]
    scale = np.max(np.abs(e))
    np.testing.assert_allclose(ed, np.broadcast_to(ed[0], ed.shape), atol=1e-9 * np.max(np.abs(ed)))
    np.testing.assert_allclose(e, e[0] + np.outer(t - t[0], ed[0]), atol=1e-7 * scale)
    assert np.max(np.abs(ed[0])) > 0
    # the drift only grows: the largest violation of the run is its last one
    assert p.result.phi_violation[-1] == pytest.approx(np.max(p.result.phi_violation))


def test_moderate_gamma_cuts_the_violation_as_the_linear_error_model_predicts(unstabilised):
    """gamma h = 0.5 (below the limit) lowers max|Phi| by more than 10x; the linear model driven by
    the
    step defects of the gamma = 0 run predicts the stabilised run's max|Phi| and max|Phidot| to 1
    %."""
    gamma = 0.5 / DT
    p = run_point(FAST_PUSH, 4, DT, gamma, gamma, duration=1.0)
    assert p.bounded
    x0 = constraint_states(SlidingBeamModel(FAST_PUSH, 4), unstabilised.result)
    pred = propagate_errors(x0[0], step_defects(x0), gamma * DT, gamma * DT, DT)
    assert np.max(p.result.phi_violation) == pytest.approx(pred.max_phi, rel=0.01)
    assert np.max(p.result.phidot_violation) == pytest.approx(pred.max_phidot, rel=0.01)
    assert np.max(p.result.phi_violation) < np.max(unstabilised.result.phi_violation) / 10


def test_explicit_feedback_blows_up_just_above_the_predicted_limit_and_not_below():
    """Explicit (Eq 54) feedback: bounded at 0.9x the limit, recorded blow-up at 1.3x with the
    predicted
    per-step growth; implicit feedback at the same gamma stays bounded."""
    safe, bad = 0.9 * EXPLICIT_LIMIT / DT, 1.3 * EXPLICIT_LIMIT / DT
    ok = run_point(FAST_PUSH, 4, DT, safe, safe, duration=1.0)
    assert ok.bounded and ok.blowup_time is None
    blown = run_point(FAST_PUSH, 4, DT, bad, bad, duration=1.0, max_violation=1e-3)
    assert not blown.bounded
    assert 0.0 < blown.blowup_time < 1.0
    assert (
        np.all(np.isfinite(blown.result.phi_violation)) and blown.result.t[-1] < blown.blowup_time
    )
    assert blown.growth_per_step() == pytest.approx(spectral_radius(bad * DT, bad * DT), rel=0.05)
    assert run_point(FAST_PUSH, 4, DT, bad, bad, feedback="implicit", duration=0.3).bounded


# -- executor, study and report -----------------------------------------------------------------


def test_scene_keys_are_validated():
    with pytest.raises(SpecError) as info:
        read_sweep_scene(str(SCENE), ('feedback="sideways"',))
    assert "bk_fast_push.toml" in str(info.value) and "'feedback'" in str(info.value)
    assert "sideways" in str(info.value) and "'explicit'" in str(info.value)
    with pytest.raises(SpecError, match=r"baumgarte.*-1\.0.*>= 0"):
        read_sweep_scene(str(SCENE), ("baumgarte=-1",))
    with pytest.raises(SpecError, match="gama"):
        read_sweep_scene(str(SCENE), ("gama=3",))
    s = read_sweep_scene(str(SCENE), ("baumgarte=0", 'feedback="implicit"'))
    assert (s.gamma, s.beta, s.feedback) == (0.0, 0.0, "implicit")


def test_reduced_study_writes_csv_and_report(tmp_path):
    from flexctrl.study.runner import run_study
    from flexctrl.study.study_file import load_study

    unstable = 2.0 * EXPLICIT_LIMIT / DT
    spec = load_study(
        STUDY,
        [
            'grid.scene.feedback=["explicit"]',
            "grid.scene.dt=[1e-3]",
            f"grid.scene.baumgarte=[0.0, 50.0, {unstable!r}]",
            "set.scene.duration=0.3",
            "set.scene.reference_dt=2e-4",
        ],
    )
    assert len(spec.runs) == 3
    run_study(spec, tmp_path / "out", workers=0, progress="none")
    with open(tmp_path / "out" / "baumgarte.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [float(r["gamma_per_s"]) for r in rows] == [0.0, 50.0, unstable]
    assert [r["bounded"] for r in rows] == ["1", "1", "0"]
    assert rows[2]["predicted_regime"] == "unstable" and float(rows[2]["blowup_time_s"]) > 0
    assert float(rows[1]["max_phi_m"]) < float(rows[0]["max_phi_m"])
    report = (tmp_path / "out" / "report.md").read_text()
    assert "## Baumgarte sweep" in report and "blew up @" in report and "### Findings" in report
    assert f"{EXPLICIT_LIMIT:.4g}" in report
    assert (tmp_path / "out" / "figures" / "baumgarte_violation.png").stat().st_size > 0
