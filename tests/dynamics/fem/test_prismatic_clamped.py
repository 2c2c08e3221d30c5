"""Pan et al. (1990) Fig 4 prismatic joint: the link clamped at E in the carriage (Eqs 22-23) and
held at the housing mouth D' (Eq 24); prescribed motion (Eq 42) and prescribed torque/force (Eq
43)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from full_coupling_checks import check_rigid_limit
from support import DATA

from flexctrl.dynamics.fem.rp_arm import RPArmModel, RPMotion, simulate_rp_arm
from flexctrl.dynamics.fem.rp_arm_full import simulate_rp_arm_full
from flexctrl.errors import SpecError
from flexctrl.spec.fem_models import load_rp_arm

SPEC = load_rp_arm(DATA / "models" / "rp_arm_clamped.toml")
MOTION = RPMotion(C1=0.2, C2=-0.4, T=0.6, theta0=0.0, dtheta=math.radians(60.0))


def _closed_form(W: float, P: float, EI: float, L: float) -> tuple[float, float]:
    """Beam clamped at E, propped at D' (span a = L - W), overhang c = W, tip force P: the tip
    deflection and the part of it that is a cantilever of the free length c on the tangent at D'."""
    a, c = L - W, W
    return P * c**2 * a / (4 * EI) + P * c**3 / (3 * EI), P * c**3 / (3 * EI)


@pytest.mark.parametrize("W", [0.25, 0.5, 0.75])
def test_static_deflection_is_a_cantilever_of_the_current_free_length(W):
    """Mouth on a node: exact (cubic Hermite elements hold a beam under point loads at nodes).
    The overhang beyond D' is a cantilever of the current free length W on the tangent at D'."""
    model = RPArmModel(SPEC, RPMotion(C1=W, C2=0.0, T=1.0), 8)
    P = 2.0
    q, lam = model.static(P)
    tip, free = _closed_form(W, P, SPEC.EI, SPEC.length)
    assert model.support_positions(0.0)[0][2] == pytest.approx(SPEC.length - W)  # the mouth row
    slope_D = model._rows(0.0)[1][2] @ q  # w'(D')
    assert q[model.tip] == pytest.approx(tip, rel=1e-10)
    assert q[model.tip] - slope_D * W == pytest.approx(free, rel=1e-10)
    assert abs(q[0]) < 1e-14 and abs(q[1]) < 1e-14  # clamped at E (Eqs 22-23)
    # the two-support arm holding the same link is a different structure (the check can fail); the
    # two agree as the supports near E (W -> L - D: 1.3 % apart at W = 0.75 m)
    two = RPArmModel(dataclasses.replace(SPEC, joint="supports"), RPMotion(C1=W, C2=0.0, T=1.0), 8)
    assert abs(two.static(P)[0][two.tip] - tip) > (0.05 if W < 0.6 else 0.005) * tip


def test_static_deflection_off_nodes_converges():
    """Mouth inside an element: its reaction is a point force there, a shear jump no cubic holds;
    the error falls with refinement (8 -> 64 elements)."""
    W, P = 0.3, 2.0
    tip, _ = _closed_form(W, P, SPEC.EI, SPEC.length)
    errors = [
        abs(RPArmModel(SPEC, RPMotion(C1=W, C2=0.0, T=1.0), n).static(P)[0][-2] - tip) / tip
        for n in (8, 64)
    ]
    assert errors[0] < 2e-2 and errors[1] < errors[0] / 10, errors


@pytest.fixture(scope="module")
def motion_run():
    return simulate_rp_arm_full(SPEC, MOTION, 4, dt=1e-3, duration=0.8)


def test_prescribed_motion_holds_the_clamp_and_matches_full_coupling(motion_run):
    """Partial coupling (Eq 42, Pan's K_g) and the full model driven by the same motion agree to the
    O(dt^2) tracking of the imposed joint motion; the constraints hold."""
    part = simulate_rp_arm(SPEC, MOTION, 4, dt=1e-3, duration=0.8)
    peak = np.abs(part.tip_y).max()
    assert peak > 5e-4
    # the mouth row slides (its Newmark defect drifts it, 1.3e-8 m); the clamp rows are fixed on the
    # link
    assert part.phi_violation.max() < 1e-7 and np.abs(part.q[:, :2]).max() < 1e-12
    full = motion_run
    assert np.abs(full.tip_y - part.tip_y).max() < 1e-4 * peak
    np.testing.assert_allclose(full.lam, part.lam, rtol=0, atol=1e-4 * np.abs(part.lam).max())
    # the clamped link bends differently from the two-support link under the same motion
    other = simulate_rp_arm(
        dataclasses.replace(SPEC, joint="supports"), MOTION, 4, dt=1e-3, duration=0.8
    )
    assert np.abs(other.tip_y - part.tip_y).max() > 0.1 * peak


def test_rigid_limit_follows_the_rigid_rp_equations():
    """Prescribed torque and force, EI x 1e4: theta and W follow the hand-written rigid R-P arm
    (solve_ivp DOP853, rtol 1e-11) to the Newmark error, which halving dt cuts by ~4; with the
    file's EI the flexibility shows."""
    check_rigid_limit(SPEC, W0=0.3)


def test_clamped_joint_is_driven_at_E_and_read_from_the_file(tmp_path):
    with pytest.raises(SpecError, match="driven_end"):
        RPArmModel(SPEC, MOTION, 4, driven_end="H")
    bad = tmp_path / "bad.toml"
    bad.write_text(
        (DATA / "models" / "rp_arm_clamped.toml").read_text().replace('"clamped"', '"clampd"')
    )
    with pytest.raises(SpecError, match="joint.*did you mean 'clamped'"):
        load_rp_arm(bad)
    assert (
        SPEC.joint == "clamped" and load_rp_arm(DATA / "models" / "rp_arm.toml").joint == "supports"
    )


def test_scene_with_the_clamped_joint(tmp_path):
    """``studies/scenes/rp_clamped_extend.toml`` runs through the scene runner (partial and full
    coupling); ``driven_end = "H"`` with the clamped model is a load-time error naming the key."""
    from flexctrl.scenes.run_fem_scene import run_fem_scene
    from flexctrl.spec.overrides import apply_overrides
    from flexctrl.spec.reader import read_toml

    path = DATA / "studies" / "scenes" / "rp_clamped_extend.toml"
    for extra in ([], ["drive.coupling='full'"]):
        doc = apply_overrides(read_toml(path), ["duration=0.2", "n_elements=4", *extra])
        summary = run_fem_scene(doc, str(path), tmp_path / str(len(extra)), None)
        assert summary["model"]["ndof"] >= 10 and summary["max_phi_violation_m"] < 1e-6
    with pytest.raises(SpecError, match="driven_end.*clamped"):
        run_fem_scene(apply_overrides(read_toml(path), ["driven_end='H'"]), str(path), None, None)
