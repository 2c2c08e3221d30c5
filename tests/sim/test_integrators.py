"""Integrators on the analytic spring pendulum: order, compiled vs VM, cache, fall-backs, agreement.

No stored numbers: convergence order from step halving, agreement between
independent integrators, energy conservation of an exact Lagrangian system.
"""

from __future__ import annotations

import math
import os

import casadi as ca
import numpy as np
import pytest
from support_models import spring_pendulum

from flexctrl.errors import SimulationError, SpecError
from flexctrl.sim import (
    CVODES,
    IDAS,
    INTEGRATORS,
    RK4,
    Integrator,
    ScipyIntegrator,
    get_integrator,
    simulate,
)
from flexctrl.sim.compile import compile_function

X0 = np.array([0.4, -0.3, 0.02, 0.5, 0.0, 0.0])


@pytest.fixture(scope="module")
def smooth():
    """omega_max = 30 rad/s: smooth enough for a clean order estimate at dt ~ 1e-2."""
    return spring_pendulum(k=900.0)


@pytest.fixture(scope="module")
def stiff():
    """omega_max = 1000 rad/s."""
    return spring_pendulum(k=1.0e6)


def _held_torques(n: int, dt: float) -> np.ndarray:
    """Piecewise-constant torques that change every 0.05 s (steps on the grid)."""
    t = np.arange(n) * dt
    level = np.floor(t / 0.05 + 1e-9)
    return np.column_stack([2.0 * np.cos(level), -1.5 * np.sin(0.7 * level)])


def test_rk4_is_fourth_order(smooth, tmp_path):
    duration = 0.8
    finals = []
    for dt in (0.02, 0.01, 0.005, 0.0025):
        traj = simulate(smooth, X0, duration, dt=dt, cache_dir=tmp_path)
        assert traj.time[-1] == pytest.approx(duration)
        finals.append(traj.states[-1])
    diffs = [np.linalg.norm(a - b) for a, b in zip(finals[:-1], finals[1:])]
    orders = [math.log2(diffs[i] / diffs[i + 1]) for i in range(len(diffs) - 1)]
    assert all(3.8 <= p <= 4.2 for p in orders), orders


def test_compiled_and_vm_agree(smooth, tmp_path):
    u = _held_torques(300, 1e-3)
    compiled = RK4(smooth, 1e-3, compile=True, cache_dir=tmp_path).run(X0, 0.3, u=u)
    vm = RK4(smooth, 1e-3, compile=False).run(X0, 0.3, u=u)
    assert compiled.meta["compiled"] and not vm.meta["compiled"]
    scale = np.max(np.abs(vm.states))
    assert np.max(np.abs(compiled.states - vm.states)) <= 1e-12 * scale
    assert np.max(np.abs(compiled.energies["E_total"] - vm.energies["E_total"])) <= 1e-12 * np.max(
        np.abs(vm.energies["E_kin"])
    )


def test_second_build_hits_the_cache(tmp_path):
    first = RK4(spring_pendulum(k=2500.0), 1e-3, compile=True, cache_dir=tmp_path).setup()
    c1 = first.compiled
    assert c1.compiled and not c1.cache_hit and c1.path.is_file()
    mtime = c1.path.stat().st_mtime_ns
    files = sorted(os.listdir(tmp_path))
    # a new model object built the same way, and another step: same library (h is an input)
    second = RK4(spring_pendulum(k=2500.0), 5e-4, compile=True, cache_dir=tmp_path).setup()
    c2 = second.compiled
    assert c2.compiled and c2.cache_hit and c2.compile_seconds == 0.0
    assert c2.path == c1.path and c2.path.stat().st_mtime_ns == mtime
    assert sorted(os.listdir(tmp_path)) == files
    # a different model is a different key
    third = RK4(spring_pendulum(k=3600.0), 1e-3, compile=True, cache_dir=tmp_path).setup()
    assert not third.compiled.cache_hit and third.compiled.path != c1.path


def test_vm_fallback_by_environment(smooth, tmp_path, monkeypatch):
    monkeypatch.setenv("FLEXCTRL_NO_COMPILE", "1")
    integ = RK4(smooth, 1e-3, cache_dir=tmp_path)
    traj = integ.run(X0, 0.05)
    assert not traj.meta["compiled"] and "switched off" in traj.meta["vm_reason"]
    assert not list(tmp_path.glob("*.so"))
    monkeypatch.delenv("FLEXCTRL_NO_COMPILE")
    again = RK4(smooth, 1e-3, cache_dir=tmp_path).run(X0, 0.05)
    assert again.meta["compiled"]
    assert np.allclose(again.states, traj.states, rtol=0, atol=1e-12)


def test_vm_fallback_without_compiler(smooth, tmp_path, monkeypatch):
    monkeypatch.delenv("CC", raising=False)
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    traj = RK4(smooth, 1e-3, compile=True, cache_dir=tmp_path).run(X0, 0.02)
    assert not traj.meta["compiled"] and "no C compiler" in traj.meta["vm_reason"]
    assert np.all(np.isfinite(traj.states))


def test_failing_compiler_warns_and_falls_back(tmp_path, monkeypatch):
    monkeypatch.setenv("CC", "false")  # exits with status 1
    x = ca.SX.sym("x")
    with pytest.warns(UserWarning, match="failed"):
        result = compile_function(ca.Function("twice", [x], [2 * x]), cache_dir=tmp_path)
    assert not result.compiled and float(result.function(3.0)) == 6.0


def test_energy_conserved_at_small_step(stiff, tmp_path):
    # omega_max dt = 0.02: RK4's energy error ~ (omega dt)^6 / 72 per step
    traj = simulate(stiff, X0, 0.5, dt=2e-5, cache_dir=tmp_path)
    assert traj.energy_figures()["max_error_rel"] < 1e-6


def test_damping_never_adds_energy(tmp_path):
    model = spring_pendulum(k=1.0e4, zeta=0.05, friction=0.3)
    traj = simulate(model, X0, 1.0, dt=1e-4, cache_dir=tmp_path)
    e = traj.energies["E_total"]
    assert np.all(np.diff(e) <= 1e-12 * np.max(np.abs(e)))
    assert e[-1] < e[0] - 0.01 * abs(e[0])


def test_divergence_names_step_and_omega_max(stiff, tmp_path):
    dt = 5e-3  # omega_max dt = 5 > 2.785
    with pytest.raises(SimulationError) as err:
        simulate(stiff, X0, 1.0, dt=dt, cache_dir=tmp_path)
    text = str(err.value)
    assert "dt = 0.005" in text and "omega_max = 1000 rad/s" in text
    assert "2.785" in text and "'cvodes'" in text
    import re

    advised = float(re.search(r"use dt <= ([0-9.e-]+) s", text).group(1))
    assert 0.5 * 2.785 / 1000.0 < advised <= 2.785 / 1000.0


def test_divergence_detected_in_the_virtual_machine_too(stiff):
    with pytest.raises(SimulationError, match="diverged at t ="):
        simulate(stiff, X0, 0.5, dt=4e-3, compile=False)


@pytest.mark.parametrize(
    "method, options",
    [
        ("cvodes", {"rtol": 1e-10, "atol": 1e-12}),
        ("idas", {"rtol": 1e-10, "atol": 1e-12}),
        ("scipy", {"scipy_method": "DOP853", "rtol": 1e-11, "atol": 1e-12}),
        ("scipy", {"scipy_method": "Radau", "rtol": 1e-8, "atol": 1e-10}),
    ],
)
def test_other_integrators_agree_with_fine_rk4(method, options, tmp_path):
    model = spring_pendulum(k=1.0e4)
    dt, duration = 1e-3, 0.4
    n = int(round(duration / dt))
    u = _held_torques(n, dt)
    fine_u = np.repeat(u, 10, axis=0)  # the same held torques on the finer grid
    ref = simulate(model, X0, duration, dt=dt / 10, u=fine_u, cache_dir=tmp_path)
    traj = simulate(model, X0, duration, dt=dt, method=method, u=u, **options)
    scale = np.max(np.abs(ref.states), axis=0)
    err = np.max(np.abs(traj.states - ref.states[::10]) / scale)
    tol = 1e-5 if options.get("scipy_method") == "Radau" else 1e-7
    assert err < tol, err
    assert traj.meta["counters"]["rhs_evaluations"] > 0


def test_time_function_input_matches_scipy(tmp_path):
    model = spring_pendulum(k=1.0e4)
    t = ca.SX.sym("t")
    u_fun = ca.Function("u", [t], [ca.vertcat(3.0 * ca.sin(7.0 * t), 0.5)])
    ref = simulate(model, X0, 0.3, dt=1e-4, u_function=u_fun, cache_dir=tmp_path)
    other = simulate(
        model,
        X0,
        0.3,
        dt=1e-3,
        method="scipy",
        scipy_method="DOP853",
        rtol=1e-11,
        atol=1e-12,
        u_function=u_fun,
    )
    cv = simulate(
        model, X0, 0.3, dt=1e-3, method="cvodes", rtol=1e-10, atol=1e-12, u_function=u_fun
    )
    scale = np.max(np.abs(ref.states), axis=0)
    assert np.max(np.abs(other.states - ref.states[::10]) / scale) < 1e-7
    assert np.max(np.abs(cv.states - ref.states[::10]) / scale) < 1e-6
    assert other.inputs[:, 0] == pytest.approx(3.0 * np.sin(7.0 * other.time))


def test_stiff_case_implicit_where_rk4_diverges(tmp_path):
    model = spring_pendulum(k=1.0e8)  # omega_max = 1e4 rad/s: omega dt = 10 at 1 ms
    x0 = X0.copy()
    x0[2] = 1e-4
    with pytest.raises(SimulationError):
        simulate(model, x0, 0.2, dt=1e-3, compile=False)
    traj = simulate(model, x0, 0.2, dt=1e-3, method="cvodes", rtol=1e-8, atol=1e-10)
    ref = simulate(model, x0, 0.2, dt=5e-6, cache_dir=tmp_path)  # omega dt = 0.05
    joints = slice(0, 2)
    scale = np.max(np.abs(ref.q[:, joints]))
    assert np.max(np.abs(traj.q[:, joints] - ref.q[::200, joints])) < 2e-5 * scale
    assert traj.energy_figures()["max_error_rel"] < 1e-3


def test_trajectory_save_header_and_pandas(smooth, tmp_path):
    traj = simulate(smooth, X0, 0.05, dt=1e-3, u=[1.0, -1.0], cache_dir=tmp_path / "cache")
    paths = traj.save(tmp_path / "out")
    header = paths["csv"].read_text().splitlines()[0].split(",")
    required = ["t", "q1", "q2", "qf21", "tip_x", "tip_y", "E_kin", "E_el", "E_grav", "E_total"]
    assert header[: len(required)] == required
    assert header[len(required) :] == ["dq1", "dq2", "dqf21", "w1", "w2", "u1", "u2"]
    data = np.loadtxt(paths["csv"], delimiter=",", skiprows=1)
    assert data.shape == (51, len(header))
    assert np.allclose(
        data[:, header.index("qf21")], traj.coordinate("qf21"), rtol=1e-11, atol=1e-14
    )
    import json

    summary = json.loads(paths["summary"].read_text())
    assert summary["integrator"] == "rk4" and summary["n_steps"] == 50
    assert set(summary["dominant_frequencies_hz"]) == {"w1", "w2"}
    frame = traj.to_pandas()
    assert list(frame.columns) == header
    assert np.allclose(frame["E_total"].to_numpy(), traj.energies["E_total"])
    assert np.allclose(frame["u1"].to_numpy(), 1.0)
    pngs = traj.plot(tmp_path / "plots")
    assert len(pngs) == 4 and all(p.stat().st_size > 1000 for p in pngs)


def test_work_of_held_torques_balances_energy(tmp_path):
    model = spring_pendulum(k=1.0e4, gravity=(0.0, 0.0))
    n = 400
    u = _held_torques(n, 1e-4)
    traj = simulate(model, X0, n * 1e-4, dt=1e-4, u=u, cache_dir=tmp_path)
    figs = traj.energy_figures()
    assert abs(traj.work_in[-1]) > 0.01 * figs["scale_J"]
    assert figs["balance_error_max_rel"] < 1e-8


def test_integrator_lookup_and_validation(smooth):
    assert get_integrator("rk4") is RK4 and get_integrator(IDAS) is IDAS
    assert set(INTEGRATORS) == {"rk4", "cvodes", "idas", "scipy", "euler", "newmark"}
    assert INTEGRATORS["cvodes"] is CVODES and INTEGRATORS["scipy"] is ScipyIntegrator
    with pytest.raises(SpecError, match="did you mean 'rk4'"):
        get_integrator("rk5")
    with pytest.raises(SpecError, match="dt"):
        RK4(smooth, -1e-3)
    with pytest.raises(SpecError, match="method"):
        ScipyIntegrator(smooth, 1e-3, method="Euler")
    with pytest.raises(SpecError, match="expected 6 finite values"):
        RK4(smooth, 1e-3, compile=False).run([0.0, 0.0], 0.1)
    with pytest.raises(SpecError, match=r"expected \(10, 2\)"):
        RK4(smooth, 1e-3, compile=False).run(X0, 0.01, u=np.zeros((9, 2)))


class _SemiImplicitEuler(Integrator):
    """A user-defined one-step method: only ``_step`` is written, the base does the rest."""

    name = "semi_implicit_euler"
    stability_limit = 2.0

    def _setup(self):
        self.f = self.model.functions["f"]

    def _step(self, x, t, u):
        n = self.model.n_q
        qd = x[n:] + self.dt * np.asarray(self.f(x, u), dtype=float).ravel()[n:]
        return np.concatenate([x[:n] + self.dt * qd, qd])


def test_integrator_chosen_by_class_is_first_order(smooth, tmp_path):
    ref = simulate(smooth, X0, 0.2, dt=1e-3, cache_dir=tmp_path)
    errors = []
    for dt in (2e-3, 1e-3):
        traj = simulate(smooth, X0, 0.2, dt=dt, method=_SemiImplicitEuler)
        assert (
            traj.meta["integrator"] == "semi_implicit_euler"
            and traj.time.size == round(0.2 / dt) + 1
        )
        errors.append(np.max(np.abs(traj.states[-1] - ref.states[-1])))
    assert 1.8 < errors[0] / errors[1] < 2.2
