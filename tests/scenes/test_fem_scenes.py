"""Finite-element scenes (flexctrl.scenes.run_fem_scene) and the revolute-prismatic arm.

The arm is :mod:`flexctrl.dynamics.fem.rp_arm`.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid
from support import DATA

from flexctrl.dynamics.fem.rp_arm import RPMotion, simulate_rp_arm
from flexctrl.dynamics.fem.sliding_beam import FAST_PULL, FAST_PUSH, simulate_sliding_beam
from flexctrl.errors import SpecError
from flexctrl.scenes.run_fem_scene import run_fem_scene
from flexctrl.spec.fem_models import RPArmSpec, load_rp_arm, rp_arm_from_document
from flexctrl.spec.fidelity import Fidelity
from flexctrl.spec.overrides import apply_overrides
from flexctrl.spec.reader import read_toml

SCENES = DATA / "studies" / "scenes"
BK = ("bk_slow_push", "bk_fast_push", "bk_fast_pull")
HEADER = "t,W,tip_y,phi_max,phidot_max"


def scene(name: str, *overrides: str) -> tuple[dict, str]:
    path = SCENES / f"{name}.toml"
    return apply_overrides(read_toml(path), overrides), str(path)


# -- the scene runner
# ---------------------------------------------------------------------------------
@pytest.mark.parametrize("name", BK)
def test_bk_scenes_write_trajectory_summary_and_plot(tmp_path, name):
    doc, src = scene(name, "duration=0.2")
    summary = run_fem_scene(doc, src, tmp_path, None)
    lines = (tmp_path / "trajectory.csv").read_text().splitlines()
    assert lines[0] == HEADER
    data = np.loadtxt(tmp_path / "trajectory.csv", delimiter=",", skiprows=1)
    assert data.shape == (summary["n_steps"] + 1, 5) and summary["n_steps"] == 200
    assert data[0, 2] == pytest.approx(0.01)  # tracked end starts 1 cm deflected
    assert data[0, 1] == pytest.approx(doc["C1"])
    assert summary["peak_abs_tip_y_m"] == pytest.approx(np.abs(data[:, 2]).max(), rel=1e-8)
    assert summary["max_phi_violation_m"] == pytest.approx(data[:, 3].max(), rel=1e-8, abs=1e-15)
    assert summary["max_phi_violation_m"] < 1e-5 and summary["max_phidot_violation_m_s"] < 1e-3
    assert summary["wall_time_per_simulated_s"] > 0 and summary["n_elements"] == 4
    assert (tmp_path / "tip.png").stat().st_size > 1000
    on_disk = json.loads((tmp_path / "summary.json").read_text())
    assert on_disk["scene"]["T"] == doc["T"] and on_disk["scene"]["axial_shortening"] is True


def test_bk_scene_reproduces_the_model_function():
    doc, src = scene("bk_fast_push", "duration=0.3")
    summary = run_fem_scene(doc, src, None, None)
    ref = simulate_sliding_beam(FAST_PUSH, 4, dt=1e-3, duration=0.3)
    assert summary["peak_abs_tip_y_m"] == pytest.approx(np.abs(ref.tip_y).max(), rel=1e-12)
    assert summary["final_tip_y_m"] == pytest.approx(ref.tip_y[-1], rel=1e-12)
    assert summary["files"] == []


def test_push_and_pull_coincide_without_axial_shortening(tmp_path):
    tips = {}
    for name in ("bk_fast_push", "bk_fast_pull"):
        for flag in ("true", "false"):
            doc, src = scene(name, f"axial_shortening={flag}", "duration=0.6")
            out = tmp_path / f"{name}_{flag}"
            run_fem_scene(doc, src, out, None)
            tips[name, flag] = np.loadtxt(out / "trajectory.csv", delimiter=",", skiprows=1)[:, 2]
    np.testing.assert_allclose(
        tips["bk_fast_push", "false"], tips["bk_fast_pull", "false"], rtol=0, atol=1e-12
    )
    assert np.abs(tips["bk_fast_push", "true"] - tips["bk_fast_pull", "true"]).max() > 2e-3


def test_fidelity_sets_the_element_count():
    doc, src = scene("bk_fast_pull", "duration=0.05")
    summary = run_fem_scene(doc, src, None, Fidelity("fem", 8))
    assert summary["n_elements"] == 8 and summary["model"]["ndof"] == 18
    with pytest.raises(SpecError, match="fem:N"):
        run_fem_scene(doc, src, None, Fidelity("amm", 2))
    doc, src = scene(
        "bk_fast_pull", "duration=0.05", "fidelity='fem:6'"
    )  # as `simulate --fidelity` writes it
    assert run_fem_scene(doc, src, None, None)["n_elements"] == 6
    assert run_fem_scene(doc, src, None, "fem:2")["n_elements"] == 2  # the argument wins


@pytest.mark.parametrize(
    "override, key, words",
    [
        ("axial_shortenning=false", "axial_shortenning", "did you mean 'axial_shortening'"),
        ("tracked_end='X'", "tracked_end", "allowed: 'H', 'E'"),
        ("axial_shortening=1", "axial_shortening", "allowed: true or false"),
        ("C1=0.9", "C1", "within [0, L - D]"),
        ("dt=5.0", "dt", "allowed: 0 < dt <= duration"),
        ("kind='sliding'", "kind", "allowed: 'sliding_beam', 'rp_arm'"),
        ("n_elements=0", "n_elements", "allowed: an integer from 1"),
    ],
)
def test_scene_errors_name_file_key_value_and_allowed(override, key, words):
    doc, src = scene("bk_slow_push", override)
    with pytest.raises(SpecError) as info:
        run_fem_scene(doc, src, None, None)
    message = str(info.value)
    assert "bk_slow_push.toml" in message and f"key '{key}'" in message and words in message


def test_rp_scene_runs(tmp_path):
    doc, src = scene("rp_extend_rotate", "duration=0.3")
    summary = run_fem_scene(doc, src, tmp_path, None)
    header = (tmp_path / "trajectory.csv").read_text().splitlines()[0]
    assert header == HEADER + ",theta,tip_X,tip_Y"
    data = np.loadtxt(tmp_path / "trajectory.csv", delimiter=",", skiprows=1)
    assert data[0, 5] == 0.0 and data[-1, 5] > 0.0 and data[0, 6] == pytest.approx(0.8 + 0.3)
    assert summary["max_phi_violation_m"] < doc["max_violation"] and summary["n_elements"] == 8
    assert summary["model"]["support_outer_m"] == 0.8


# -- the R-P arm
# -------------------------------------------------------------------------------------------
BK_RP = RPArmSpec(
    "bk", length=1.0, mass_per_length=1.0, EI=1.0, support_inner=0.55, support_outer=0.8
)


@pytest.mark.parametrize("case", [FAST_PUSH, FAST_PULL], ids=lambda c: c.name)
@pytest.mark.parametrize("driven_end", ["E", "H"])
def test_rp_arm_without_rotation_is_the_sliding_beam(case, driven_end):
    """Same supports (D = 0.25 m), same Eq 57 motion, the housing held still: same response."""
    c = dataclasses.replace(case, driven_end=driven_end)
    ref = simulate_sliding_beam(c, 4, dt=1e-3, duration=0.5)
    motion = RPMotion(c.C1, c.C2, c.T, theta0=0.7, dtheta=0.0)
    res = simulate_rp_arm(
        BK_RP,
        motion,
        4,
        dt=1e-3,
        duration=0.5,
        driven_end=driven_end,
        tracked_end=c.tracked_end,
        initial="static_load",
    )
    np.testing.assert_allclose(res.tip_y, ref.tip_y, rtol=0, atol=1e-12)
    np.testing.assert_allclose(res.lam, ref.lam, rtol=1e-9, atol=1e-12)


@pytest.fixture(scope="module")
def rp_run():
    spec = load_rp_arm(DATA / "models" / "rp_arm.toml")
    motion = RPMotion(C1=0.3, C2=-0.4, T=1.0, theta0=0.0, dtheta=math.radians(60.0))
    return spec, motion, simulate_rp_arm(spec, motion, 8, dt=1e-3, duration=1.5)


def test_rp_arm_constraints_and_kinematics(rp_run):
    spec, motion, res = rp_run
    assert res.phi_violation.max() < 1e-6  # m (measured ~2e-9), against ~1.3 mm deflections
    assert res.phidot_violation.max() < 1e-5  # m/s
    assert res.W[-1] == pytest.approx(0.7) and res.theta[-1] == pytest.approx(math.radians(60.0))
    np.testing.assert_allclose(res.tip_world[0], [1.1, 0.0])
    radius = np.hypot(*res.tip_world[-1])
    assert radius == pytest.approx(
        spec.support_outer + 0.7, abs=1e-5
    )  # 1.5 m, up to the deflection


def test_rp_arm_follows_the_quasi_static_deflection(rp_run):
    """Eq 57 is smooth and slow against the link (first frequency > 15 Hz): the dynamic tip stays
    close to the static deflection under the instantaneous rigid-body loads, then rings down."""
    _, _, res = rp_run
    m = res.model
    prob = m.problem()
    static = []
    for t in res.t:
        A, n = prob.phi_q(None, t), m.ndof
        S = np.zeros((n + 2, n + 2))
        S[:n, :n], S[:n, n:], S[n:, :n] = m.stiffness(t), A.T, A
        static.append(np.linalg.solve(S, np.r_[m.load(t), 0.0, 0.0])[m.tip])
    static = np.array(static)
    peak = np.abs(static).max()
    assert peak > 5e-4  # m: rotation loads the link (extension alone would not)
    moving = res.t <= 1.0
    assert np.abs(res.tip_y[moving] - static[moving]).max() < 0.05 * peak
    assert np.abs(res.tip_y[~moving]).max() < 0.2 * peak


def test_rp_arm_energy_balance(rp_run):
    """The energy changes by the work of the frame's inertia and of the moving supports.

    d/dt (1/2 qd M qd + 1/2 q K q) = qd . (rigid-motion loads - (K_g - theta'^2 M) q - A^T lam);
    after T the energy stays constant.
    """
    spec, motion, _ = rp_run
    errors = {}
    for dt in (1e-3, 5e-4):
        res = simulate_rp_arm(spec, motion, 8, dt=dt, duration=1.2)
        m, prob = res.model, res.model.problem()
        E = np.array([m.vibration_energy(q, qd) for q, qd in zip(res.q, res.qd)])
        power = np.array(
            [
                qd @ (prob.force(q, qd, t) + m.K @ q - prob.phi_q(q, t).T @ lam)
                for t, q, qd, lam in zip(res.t, res.q, res.qd, res.lam)
            ]
        )
        work = cumulative_trapezoid(power, res.t, initial=0.0)
        errors[dt] = np.abs(E - E[0] - work).max() / E.max()
        after = res.t > motion.T
        assert np.ptp(E[after]) < 1e-5 * E[after].mean()
    assert errors[1e-3] < 5e-5
    assert errors[1e-3] / errors[5e-4] > 3.0  # second order in dt


def test_rp_model_file_is_validated():
    doc = read_toml(DATA / "models" / "rp_arm.toml")
    spec = rp_arm_from_document(doc, "models/rp_arm.toml")
    assert spec.D == pytest.approx(0.2) and spec.EI == pytest.approx(212.8)
    bad = apply_overrides(doc, ["housing.support_outer=0.5"])
    with pytest.raises(SpecError, match="support_outer"):
        rp_arm_from_document(bad, "rp.toml")
    with pytest.raises(SpecError, match="did you mean 'mass_per_length'"):
        rp_arm_from_document(apply_overrides(doc, ["link.mass_per_lenght=1.0"]), "rp.toml")
    with pytest.raises(SpecError, match="allowed: within"):
        simulate_rp_arm(spec, RPMotion(C1=0.6, C2=-0.4, T=1.0), 4, duration=0.01)


def test_scene_kind_adapters(tmp_path):
    """The reader validates at load, the runner writes files at run."""
    from flexctrl.scenes.run_fem_scene import run_scene
    from flexctrl.spec.fem_scene import read_fem_scene as read_scene

    doc, src = scene("bk_fast_push", "duration=0.05")
    loaded = read_scene(doc, src, SCENES)
    assert loaded.kind == "sliding_beam" and loaded.name == "bk_fast_push"
    result = run_scene(loaded, tmp_path, plots=False, fidelity="fem:5")
    assert result.summary["n_elements"] == 5 and not (tmp_path / "tip.png").exists()
    assert sorted(p.name for p in result.files) == ["summary.json", "trajectory.csv"]
    with pytest.raises(SpecError, match="key 'T'"):
        read_scene({**doc, "T": -1.0}, src, SCENES)
