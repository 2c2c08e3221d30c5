"""Telescoping joint with full coupling (Pan et al. 1990, Fig 5 and Eq 43): theta and W unknown."""

from __future__ import annotations

import math

import numpy as np
import pytest
from full_coupling_checks import check_constraint_derivatives
from support import DATA

from flexctrl.dynamics.fem.full_coupling import RPForces
from flexctrl.dynamics.fem.moving_frame import RPMotion
from flexctrl.dynamics.fem.telescoping import simulate_telescoping
from flexctrl.dynamics.fem.telescoping_full import TelescopingFullModel, simulate_telescoping_full
from flexctrl.errors import SimulationError
from flexctrl.spec.fem_models import load_telescoping

SPEC = load_telescoping(DATA / "models" / "telescoping.toml")
MOTION = RPMotion(C1=0.1, C2=-0.4, T=0.6, theta0=0.0, dtheta=math.radians(60.0))


@pytest.fixture(scope="module")
def runs():
    part = simulate_telescoping(SPEC, MOTION, 4, 4, dt=1e-3, duration=0.8)
    full = {
        dt: simulate_telescoping_full(SPEC, MOTION, 4, 4, dt=dt, duration=0.8)
        for dt in (1e-3, 5e-4)
    }
    return part, full


def test_fed_the_same_motion_it_reproduces_the_motion_driven_model(runs):
    """theta(t), W(t) imposed by constraints: the nodal rows of the Lagrangian (shortening in T) are
    the partial model's (Pan's K_g on both links): the tip, the tube mouth and the contact forces
    agree to the O(dt^2) tracking of the imposed joint motion (halving dt cuts the gap by > 2.5)."""
    part, full = runs
    f = full[1e-3]
    peak = np.abs(part.tip_y).max()
    assert peak > 2e-3
    gap = np.abs(f.tip_y - part.tip_y).max()
    assert gap < 1e-4 * peak
    assert np.abs(f.outer_tip_y - part.outer_tip_y).max() < 1e-4 * np.abs(part.outer_tip_y).max()
    np.testing.assert_allclose(f.lam, part.lam, rtol=0, atol=1e-4 * np.abs(part.lam).max())
    assert max(np.abs(f.theta - MOTION.theta(f.t)).max(), np.abs(f.W - MOTION.W(f.t)).max()) < 1e-5
    part_half = simulate_telescoping(SPEC, MOTION, 4, 4, dt=5e-4, duration=0.8)
    assert gap / np.abs(full[5e-4].tip_y - part_half.tip_y).max() > 2.5
    assert (
        np.abs(f.torque).max() > 1.0 and np.abs(f.force).max() > 1.0
    )  # the motion needs real inputs
    # without the shortening in T the nodal rows lose K_g: the check can fail
    plain = simulate_telescoping_full(
        SPEC, MOTION, 4, 4, dt=1e-3, duration=0.8, axial_shortening=False
    )
    assert np.abs(plain.tip_y - part.tip_y).max() > 100 * gap


def test_recorded_torque_and_force_reproduce_the_motion(runs):
    """The joint multipliers of the motion run fed back as inputs (prescribed force, full coupling):
    on the same grid the same discrete equations, so theta, W and the tip come back to 1e-9."""
    f = runs[1][1e-3]
    forces = RPForces.from_samples(f.t, f.torque, f.force, theta0=MOTION.theta0, W0=MOTION.C1)
    same = simulate_telescoping_full(SPEC, forces, 4, 4, dt=1e-3, duration=0.8)
    assert np.abs(same.theta - f.theta).max() < 1e-9 and np.abs(same.W - f.W).max() < 1e-9
    assert np.abs(same.tip_y - f.tip_y).max() < 1e-9 and same.phi_violation.max() < 1e-6


def test_constraint_derivatives_match_finite_differences():
    """Phi_z, h (Eq 47), h_z, h_zd of the W-dependent contact rows against central differences."""
    model = TelescopingFullModel(SPEC, RPForces.sine(1.0, 1.0, 1.0, W0=0.23), 4, 4)
    check_constraint_derivatives(model, W=0.23, seed=2)


def test_a_contact_leaving_a_link_is_an_error():
    push = RPForces(torque=lambda t: 0.0, force=lambda t: 20.0, W0=0.5)
    with pytest.raises(SimulationError, match="took a contact off a link"):
        simulate_telescoping_full(SPEC, push, 4, 4, dt=1e-3, duration=1.0)
