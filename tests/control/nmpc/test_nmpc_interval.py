"""The NMPC's shooting interval: its sensitivities against exact and finite-difference ones."""

from __future__ import annotations

import numpy as np

from flexctrl import linear as L
from flexctrl.control.nmpc.interval import interval_functions
from flexctrl.scenes.model_files import load_model


def _transition_error(model, x, u, dt, recipe, every=1):
    _, exact = interval_functions(model, dt, 2, "exact")
    _, FJ = interval_functions(model, dt, 2, recipe, jacobian_every=every)
    return np.linalg.norm(
        np.asarray(FJ(x, u)[1], dtype=float) - np.asarray(exact(x, u)[1], dtype=float), 2
    )


def test_midpoint_sensitivities_are_third_order_in_the_sample_time_the_start_point_second(onelink):
    # one Jacobian per interval (2 RK4 steps): at its start the transition A = dx_next/dx is wrong
    # by
    # O(h^2) (J' h^2 / 2), at its middle node by O(h^3) (the midpoint rule); halving the sample
    # divides
    # the errors by ~4 and ~8 (measured 3.8 and 9.7 at 1 -> 0.5 ms)
    model, op = onelink
    x = op.x + np.array([-0.4, 0.01, 3.0, -2.0])
    u = op.u + 10.0
    ratios = {}
    for recipe, every in (("midpoint", 1), ("frozen", 2)):
        errors = [_transition_error(model, x, u, dt, recipe, every) for dt in (0.001, 0.0005)]
        ratios[recipe] = errors[0] / errors[1]
    assert ratios["midpoint"] > 7.0 and 3.0 < ratios["frozen"] < 5.0, ratios
    # and at one sample the midpoint is closer than one Jacobian per RK4 step at its start
    mid, per_step = (_transition_error(model, x, u, 0.004, r) for r in ("midpoint", "frozen"))
    assert mid < per_step


def test_frozen_sensitivities_over_k_steps_are_exact_at_rest_and_coarser_in_motion():
    model = load_model("models/subedi3link.toml", fidelity="amm:2")
    op = L.equilibrium(model, np.radians([80.0, -10.0, -10.0]))
    F, exact = interval_functions(model, 0.01, 9, "exact")
    x = op.x.copy()
    rng = np.random.default_rng(1)
    x[9:12] = [0.5, -0.5, 0.5]
    x[3:9] += 1e-3 * rng.standard_normal(6)
    u = op.u + 0.5 * L.torque_limits(model) * np.array([1.0, -1.0, 1.0])
    eps = 1e-6
    A_fd = np.column_stack(
        [
            (np.asarray(F(x + eps * e, u)) - np.asarray(F(x - eps * e, u))).ravel() / (2 * eps)
            for e in np.eye(18)
        ]
    )
    _, A_ex, _ = (np.asarray(a, dtype=float) for a in exact(x, u))
    assert np.linalg.norm(A_ex - A_fd, 2) < 1e-6 * np.linalg.norm(A_fd, 2)
    errors = {}
    for k in (1, 3):
        _, FJ = interval_functions(model, 0.01, 9, "frozen", jacobian_every=k)
        # at rest the state does not move within the sample: any grouping is the exact derivative
        for a, b in zip(FJ(op.x, op.u)[1:], exact(op.x, op.u)[1:]):
            a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
            assert np.max(np.abs(a - b)) < 1e-12 * np.max(np.abs(b))
        _, A, _ = (np.asarray(a, dtype=float) for a in FJ(x, u))
        errors[k] = np.linalg.norm(A - A_fd, 2) / np.linalg.norm(A_fd, 2)
    # measured 3.1 % (one Jacobian per RK4 step) and 12 % (per three)
    assert errors[1] < 0.06 and errors[3] > 2 * errors[1]
