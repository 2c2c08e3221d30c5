"""Stability where methods fail: the largest stable steps of rk4, euler and newmark.

Every expected value is computed here by a second route: the stability
boundaries from the amplification factors by hand or by scanning, the
frequencies from the mass and stiffness matrices (not from the Jacobian the
library uses), the Newmark boundary from the spectral radius of its
single-mode step matrix.  The often quoted 2.785 is used where a bound of RK4
is asked for (within 5 % of 2.785/omega_max).
"""

from __future__ import annotations

import csv
import json
import math

import casadi as ca
import numpy as np
import pytest
import scipy.linalg
from support import DATA
from support_models import spring_pendulum

from flexctrl.analysis.stability.probe import StabilityCriterion, StabilityProbe
from flexctrl.analysis.stability.step_search import largest_stable_step
from flexctrl.analysis.stability.theory import (
    EXPLICIT_POLYNOMIALS,
    RK4_IMAGINARY_AXIS_LIMIT,
    RK4_REAL_AXIS_LIMIT,
    amplification_factor,
    ray_limit,
    theoretical_step_limit,
)
from flexctrl.errors import SpecError
from flexctrl.linear import equilibrium, stiffness_matrix
from flexctrl.sim import INTEGRATORS, simulate
from flexctrl.sim.newmark_model import newmark_critical_step
from flexctrl.sim.rk4 import RK4, RK4_STABILITY_LIMIT

STUDY = DATA / "studies" / "stability_limits.toml"


# -- independent references -------------------------------------------------------------


def _frequencies(model, q: np.ndarray) -> np.ndarray:
    """Undamped frequencies (rad/s) at a static equilibrium: K_t phi = omega^2 M phi.

    K_t = d(g + K q)/dq from CasADi, M from the model: a route apart from the
    Jacobian of f the library linearises (at rest Coriolis terms vanish).
    """
    qs = ca.SX.sym("q", model.n_q)
    potential = model.functions["g"](qs) + ca.mtimes(stiffness_matrix(model, qs), qs)
    k_t = np.array(ca.Function("Kt", [qs], [ca.jacobian(potential, qs)])(q), dtype=float)
    mass = model.mass_matrix(q)
    w2 = scipy.linalg.eigh(0.5 * (k_t + k_t.T), mass, eigvals_only=True)
    return np.sqrt(np.clip(w2, 0.0, None))


def _newmark_step_matrix(alpha: float, delta: float, omega_h: float, zeta: float) -> np.ndarray:
    """One Newmark step on q'' + 2 zeta q' + q = 0 with step omega_h, as a matrix on (q, q') (built
    column by column)."""
    h = omega_h
    step = np.empty((2, 2))
    for j, (q, v) in enumerate(((1.0, 0.0), (0.0, 1.0))):
        a = -(2 * zeta * v + q)
        q_pred = q + h * v + h * h * (0.5 - alpha) * a
        v_pred = v + h * (1 - delta) * a
        a_new = -(2 * zeta * v_pred + q_pred) / (1 + 2 * zeta * delta * h + alpha * h * h)
        step[:, j] = (q_pred + alpha * h * h * a_new, v_pred + delta * h * a_new)
    return step


def _newmark_radius(alpha: float, delta: float, omega_h: float, zeta: float) -> float:
    """Spectral radius of :func:`_newmark_step_matrix`."""
    return float(
        np.max(np.abs(np.linalg.eigvals(_newmark_step_matrix(alpha, delta, omega_h, zeta))))
    )


@pytest.fixture(scope="module")
def toy():
    """The spring pendulum without gravity, held (torque-free) at q = (0.3, -0.2) rad."""
    model = spring_pendulum(k=1.0e4, gravity=(0.0, 0.0))
    return model, equilibrium(model, [0.3, -0.2])


@pytest.fixture(scope="module")
def arm_amm1():
    """The Subedi arm at amm:1 with 2 kg, held horizontal against gravity (static deflection)."""
    from flexctrl.dynamics.build import build_model
    from flexctrl.spec.arm import load_arm

    arm = load_arm(DATA / "models" / "subedi3link.toml").with_payload(2.0)
    model = build_model(arm, "amm:1", reference_q=(0.0, 0.0, 0.0))
    return model, equilibrium(model, (0.0, 0.0, 0.0))


# -- theory -----------------------------------------------------------------------------


def test_rk4_limits_on_both_axes_by_hand():
    # |R(iy)|^2 = 1 - y^6/72 + y^8/576 (expanded by hand): = 1 at y^2 = 8.
    y = ray_limit(EXPLICIT_POLYNOMIALS["rk4"], 1j)
    assert y == pytest.approx(math.sqrt(8.0), rel=1e-12)
    assert RK4_IMAGINARY_AXIS_LIMIT == pytest.approx(y, rel=1e-12)
    assert (
        abs(amplification_factor("rk4", 1j * y * (1 - 1e-6)))
        < 1
        < abs(amplification_factor("rk4", 1j * y * (1 + 1e-6)))
    )
    # negative real axis: bisect |R(-x)| = 1 directly
    lo, hi = 2.0, 3.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if abs(amplification_factor("rk4", -mid)) <= 1 else (lo, mid)
    assert RK4_REAL_AXIS_LIMIT == pytest.approx(lo, rel=1e-12)
    assert amplification_factor("rk4", -lo).real == pytest.approx(
        1.0, abs=1e-9
    )  # R = +1 there (x^3 - 4x^2 + 12x - 24 = 0)
    assert np.polynomial.polynomial.polyval(lo, [-24, 12, -4, 1]) == pytest.approx(0.0, abs=1e-9)
    # the real-axis limit (the often quoted 2.785) is 1.5 % below the imaginary-axis one
    assert 0.015 < 1 - RK4_REAL_AXIS_LIMIT / RK4_IMAGINARY_AXIS_LIMIT < 0.016


def test_the_integrators_rk4_limit_is_the_real_axis_root_and_safe_for_undamped_modes():
    # RK4_STABILITY_LIMIT, the one constant the integrators use (step choice, advice), against the
    # root of |R(-x)| = 1 computed from RK4's polynomial (checked by bisection above) ...
    assert RK4.stability_limit == RK4_STABILITY_LIMIT
    assert abs(RK4_STABILITY_LIMIT - RK4_REAL_AXIS_LIMIT) <= 5e-4
    # ... and below the imaginary-axis exit 2 sqrt 2, so it bounds every undamped mode safely
    imaginary = ray_limit(EXPLICIT_POLYNOMIALS["rk4"], 1j)
    assert imaginary == pytest.approx(2.0 * math.sqrt(2.0), rel=1e-12)
    assert RK4_STABILITY_LIMIT < imaginary
    assert abs(amplification_factor("rk4", 1j * RK4_STABILITY_LIMIT)) <= 1.0


@pytest.mark.parametrize("method", ["rk4", "euler"])
def test_ray_limit_matches_a_dense_scan(method):
    s = np.linspace(1e-4, 4.0, 400_001)
    for theta in np.linspace(0.5 * np.pi + 0.05, np.pi, 12):
        d = np.exp(1j * theta)
        exits = np.nonzero(np.abs(amplification_factor(method, s * d)) > 1 + 1e-12)[0]
        assert ray_limit(EXPLICIT_POLYNOMIALS[method], d) == pytest.approx(s[exits[0]], abs=2e-5)


def test_euler_theory_is_zero_undamped_and_two_zeta_over_omega_damped():
    omega = 300.0
    assert theoretical_step_limit([1j * omega, -1j * omega], "euler").h == 0.0
    for zeta in (0.01, 0.1, 0.5):
        lam = omega * (-zeta + 1j * math.sqrt(1 - zeta**2))
        assert theoretical_step_limit([lam, np.conj(lam)], "euler").h == pytest.approx(
            2 * zeta / omega, rel=1e-10
        )


@pytest.mark.parametrize(
    "alpha, delta, zeta", [(0.0, 0.5, 0.0), (0.1, 0.6, 0.0), (0.1, 0.6, 0.05), (0.2, 0.55, 0.2)]
)
def test_newmark_critical_step_matches_its_step_matrix(alpha, delta, zeta):
    crit = newmark_critical_step(alpha, delta, zeta)
    assert _newmark_radius(alpha, delta, crit * (1 - 1e-6), zeta) <= 1 + 1e-9
    assert _newmark_radius(alpha, delta, crit * (1 + 1e-4), zeta) > 1


def test_newmark_average_acceleration_is_unconditionally_stable():
    assert newmark_critical_step(0.25, 0.5) == math.inf
    for omega_h in (0.1, 10.0, 1e3):  # (the matrix loses omega_h^2 * 1e-16 to rounding)
        # undamped: det = 1 and |trace| <= 2, so both eigenvalues lie on the unit circle
        step = _newmark_step_matrix(0.25, 0.5, omega_h, 0.0)
        assert np.linalg.det(step) == pytest.approx(1.0, abs=1e-9) and abs(np.trace(step)) <= 2.0
    assert theoretical_step_limit([5j, -5j, -1 + 3j, -1 - 3j], "newmark").h == math.inf


# -- the new integrators ----------------------------------------------------------------


def test_euler_and_newmark_are_registered_integrators():
    assert {"euler", "newmark"} <= set(INTEGRATORS)


def test_euler_integrator_is_forward_euler(toy):
    model, op = toy
    x0 = op.x + np.array([0.01, -0.02, 0.003, 0.1, 0.0, -0.2])
    u = np.array([[0.5, -0.1], [0.2, 0.3], [0.0, 0.0], [-0.4, 0.1]])
    dt = 1e-3
    traj = simulate(model, x0, 4 * dt, dt=dt, method="euler", u=u)
    x = x0.copy()
    for k in range(4):
        x = x + dt * np.array(model.functions["f"](x, u[k]), dtype=float).ravel()
        np.testing.assert_allclose(traj.states[k + 1], x, rtol=1e-12, atol=1e-14)


def test_newmark_integrator_matches_simulate_model_newmark(toy):
    from flexctrl.dynamics.fem.newmark import simulate_model_newmark

    model, op = toy
    x0 = op.x + np.array([0.01, -0.02, 0.003, 0.1, 0.0, -0.2])
    dt, n = 2e-3, 30
    traj = simulate(model, x0, n * dt, dt=dt, method="newmark", alpha=0.3, delta=0.6, chunk=7)
    ref = simulate_model_newmark(model, x0, n * dt, dt, alpha=0.3, delta=0.6)
    np.testing.assert_allclose(traj.states[:, : model.n_q], ref.q, rtol=0, atol=1e-11)
    np.testing.assert_allclose(traj.states[:, model.n_q :], ref.qd, rtol=0, atol=1e-9)
    with pytest.raises(SpecError, match="alpha"):
        INTEGRATORS["newmark"](model, dt, alpha=0.7)


def test_scene_accepts_the_newmark_integrator_and_its_parameters():
    from flexctrl.spec.scene import load_scene

    scene = load_scene(
        DATA / "studies" / "scenes" / "free_vibration.toml",
        ["integrator='newmark'", "solver.alpha=0.3", "solver.delta=0.6"],
    )
    assert (scene.integrator, scene.solver) == ("newmark", {"alpha": 0.3, "delta": 0.6})
    with pytest.raises(SpecError, match="alpha.*does not apply to integrator 'euler'"):
        load_scene(
            DATA / "studies" / "scenes" / "free_vibration.toml",
            ["integrator='euler'", "solver.alpha=0.3"],
        )


# -- measurement on the linear oscillator ----------------------------------------------


def test_probe_frequency_matches_mass_and_stiffness(toy):
    model, op = toy
    probe = StabilityProbe(model, "rk4", op.x, op.u)
    assert probe.omega_max == pytest.approx(_frequencies(model, op.q).max(), rel=1e-9)


def test_rk4_bisection_brackets_the_exact_limit_on_the_oscillator(toy):
    model, op = toy
    omega = _frequencies(model, op.q).max()
    result = largest_stable_step(model, "rk4", op.x, op.u)
    exact = math.sqrt(8.0) / omega
    assert result.outcome == "bracketed"
    assert result.h_theory == pytest.approx(exact, rel=1e-9)
    # the criterion resolves RK4's boundary to ~1e-6; the bisection stops at 1e-4
    assert result.h_measured <= exact * (1 + 2e-6) and result.h_unstable >= exact * (1 - 2e-6)
    assert result.h_unstable / result.h_measured - 1 <= 1e-4


def test_euler_bisection_finds_two_zeta_over_omega_on_a_damped_oscillator():
    model = spring_pendulum(k=1.0e4, zeta=0.2, gravity=(0.0, 0.0))
    op = equilibrium(model, [0.3, -0.2])
    # the damped modes from M, D and K (quadratic eigenproblem), not from df/dx
    q = op.q
    mass, damping = model.mass_matrix(q), np.array(model.functions["D"]()["D"], dtype=float)
    stiffness = stiffness_matrix(model, q)
    n = model.n_q
    companion = np.block(
        [
            [np.zeros((n, n)), np.eye(n)],
            [-np.linalg.solve(mass, stiffness), -np.linalg.solve(mass, damping)],
        ]
    )
    lam = np.linalg.eigvals(companion)
    lam = lam[np.abs(lam) > 1e-6 * np.abs(lam).max()]
    expected = float(np.min(-2 * lam.real / np.abs(lam) ** 2))
    result = largest_stable_step(model, "euler", op.x, op.u)
    assert result.h_theory == pytest.approx(expected, rel=1e-8)
    assert result.outcome == "bracketed"
    assert result.h_measured == pytest.approx(expected, rel=5e-4)
    assert result.h_measured <= expected * (1 + 5e-4) <= result.h_unstable * (1 + 1e-3)


# -- measurement on the arm (amm:1) -----------------------------------------------------


def test_rk4_on_amm1_within_5_percent_of_2785_and_tightly_of_theory(arm_amm1):
    model, op = arm_amm1
    result = largest_stable_step(model, "rk4", op.x, op.u)
    omega = _frequencies(model, op.q).max()
    assert result.omega_max == pytest.approx(omega, rel=1e-7)
    assert (
        abs(result.h_measured / (RK4_STABILITY_LIMIT / result.omega_max) - 1) < 0.05
    )  # within 5 % of the real-axis bound
    assert abs(result.h_measured / result.h_theory - 1) < 0.01  # and within 1 % of the exact theory
    assert result.h_theory == pytest.approx(
        RK4_IMAGINARY_AXIS_LIMIT / omega, rel=1e-7
    )  # undamped: 2 sqrt 2 / omega
    assert (
        result.h_measured <= result.h_theory * (1 + 2e-6) <= result.h_unstable * (1 + 4e-6)
    )  # ... and much tighter
    assert result.ratio == pytest.approx(1.0, abs=1.5e-4)


def test_newmark_stable_at_100x_the_rk4_limit_where_rk4_is_not(arm_amm1):
    model, op = arm_amm1
    newmark = StabilityProbe(model, "newmark", op.x, op.u)
    h = 100 * RK4_STABILITY_LIMIT / newmark.omega_max
    probe = newmark(h)
    assert probe.stable and probe.growth <= StabilityCriterion().growth
    rk4 = StabilityProbe(model, "rk4", op.x, op.u)
    assert not rk4(
        1.01 * RK4_IMAGINARY_AXIS_LIMIT / rk4.omega_max
    ).stable  # the criterion sees 1 % beyond the limit
    assert rk4(0.99 * RK4_IMAGINARY_AXIS_LIMIT / rk4.omega_max).stable


def test_euler_unstable_on_undamped_arm_at_every_tested_step(arm_amm1):
    model, op = arm_amm1
    result = largest_stable_step(model, "euler", op.x, op.u)
    assert result.outcome == "unstable_at_floor" and result.h_measured == 0.0
    assert result.theory.h == 0.0 and result.theory.n_damped == 0
    assert all(not p.stable for p in result.probes)
    assert min(p.h for p in result.probes) == pytest.approx(result.h_floor, rel=1e-12)
    # at the floor the fastest mode grows by (omega h)^2 / 2 per step: resolvable by the criterion
    y = result.omega_max * result.h_floor
    assert 0.5 * y**2 > 5 * result.criterion.rate_tolerance


# -- refusals ---------------------------------------------------------------------------


def test_probe_refuses_states_it_cannot_probe():
    model = spring_pendulum(k=1.0e4)  # with gravity
    up = equilibrium(model, [0.5 * math.pi, 0.0])  # held upright: an inverted pendulum
    with pytest.raises(SpecError, match="equilibrium is unstable"):
        StabilityProbe(model, "rk4", up.x, up.u)
    down = equilibrium(model, [-0.5 * math.pi + 0.3, 0.2])
    with pytest.raises(SpecError, match="not an equilibrium"):
        StabilityProbe(model, "rk4", down.x, np.zeros(2))
    with pytest.raises(SpecError, match="growth"):
        StabilityCriterion(growth=1.0)
    with pytest.raises(SpecError, match="chunk"):
        StabilityProbe(model, "rk4", up.x, up.u, integrator_options={"chunk": 10})


def test_study_refuses_adaptive_integrators():
    from flexctrl.study.executors.stability_limits_executor import check_settings
    from flexctrl.study.study_file import load_study

    settings = load_study(STUDY, ["grid.fidelity=['amm:1']"], check_executor=False).runs[0].settings
    settings["overrides"] = ['scene.integrator="cvodes"']
    with pytest.raises(
        SpecError,
        match=r"stability_probe.toml.*integrator.*'cvodes'.*allowed: 'rk4', 'euler', 'newmark'",
    ):
        check_settings(settings)


# -- the study interface ----------------------------------------------------------------


def test_study_writes_stability_limits_csv(tmp_path):
    from flexctrl.study.report import write_report
    from flexctrl.study.runner import run_study
    from flexctrl.study.study_file import load_study

    spec = load_study(STUDY, ["grid.fidelity=['amm:1']"])
    run_study(spec, tmp_path, workers=0, progress="none")
    path = tmp_path / "stability_limits.csv"
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        assert reader.fieldnames[:5] == [
            "integrator",
            "fidelity",
            "omega_max",
            "h_measured",
            "h_theory",
        ]
        rows = {row["integrator"]: row for row in reader}
    assert set(rows) == {"rk4", "euler", "newmark"}
    for row in rows.values():
        assert row["fidelity"] == "amm:1" and row["status"] == "ok"
        assert float(row["omega_max"]) == pytest.approx(float(rows["rk4"]["omega_max"]))
    rk4 = rows["rk4"]
    assert abs(float(rk4["h_measured"]) * float(rk4["omega_max"]) / RK4_STABILITY_LIMIT - 1) < 0.05
    assert abs(float(rk4["h_measured"]) / float(rk4["h_theory"]) - 1) < 1e-3
    assert rows["newmark"]["h_theory"] == "inf" and rows["newmark"]["outcome"] == "stable_at_cap"
    assert float(rows["newmark"]["h_measured"]) >= 100 * RK4_STABILITY_LIMIT / float(
        rows["newmark"]["omega_max"]
    )
    assert float(rows["euler"]["h_measured"]) == 0.0 and float(rows["euler"]["h_theory"]) == 0.0
    report = (tmp_path / "report.md").read_text()
    assert (
        "Largest stable step" in report
        and (tmp_path / "figures" / "stability_limits.png").is_file()
    )
    # `flexctrl report DIR` redraws it from the files alone
    before = path.read_text()
    path.unlink()
    write_report(tmp_path)
    assert path.read_text() == before
    record = json.loads(next((tmp_path / "runs").glob("*.json")).read_text())
    assert record["metrics"]["probe_steps"] == StabilityCriterion().steps
