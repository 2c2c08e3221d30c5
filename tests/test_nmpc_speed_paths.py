"""The NMPC's sample: midpoint sensitivities against exact ones, the screened QP against the
whole QP, HPIPM called directly against casadi.conic's, the bound buffers."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from flexctrl.control.nmpc.calls import BoundRTICalls
from flexctrl.control.nmpc.controller import design_nmpc, interval_functions
from flexctrl.control.nmpc.screened_qp import ScreenedQP
from flexctrl.sim.bound import BoundFunction
from flexctrl.spec.controller_settings import NMPCSettings

LIMIT = (
    0.01  # m: passed in the transient (the first 21 of 40 samples solve the whole QP), held after
)
SMALL = dict(compile=False, horizon=15, sample_time=0.02, deflection_limit=0.02, qp_warm_start=True)


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


def _closed_loop(model, op, samples=40, limit=0.02, screen=True, direct=True):
    """The NMPC's torques over ``samples`` of a closed loop; ``screen=False`` always solves the
    whole QP, ``direct=False`` solves the screened QP through ``casadi.conic``."""
    settings = NMPCSettings(sensitivities="midpoint", **{**SMALL, "deflection_limit": limit})
    ctrl = design_nmpc(model, op, settings)
    ctrl.screen = ctrl.screen and screen
    if ctrl.screen and not direct:
        fn, pb = ctrl.functions, ctrl.problem
        qp = ScreenedQP(
            ctrl.layout,
            fn["Hnp"].toarray(),
            fn["prepare"].sparsity_out(0),
            pb.C,
            pb.c_lo,
            pb.c_hi,
            ctrl.settings.qp_warm_start,
            direct=False,
        )
        ctrl._rti_calls = BoundRTICalls(fn["prepare"], fn["qp"], fn["H"], qp)
    F, _ = interval_functions(model, ctrl.sample_time, 4, None)
    x = op.x.copy()
    x[0] -= 0.3  # saturates the torque and bends the link past the deflection limit
    ctrl.reset()
    U = []
    for k in range(samples):
        u = ctrl.step(k * ctrl.sample_time, x)
        U.append(u)
        x = np.asarray(F(x, u), dtype=float).ravel()
    return np.array(U), ctrl


def test_the_screened_qp_gives_the_whole_qps_optimum_and_declines_when_a_limit_binds(onelink):
    screened, ctrl = _closed_loop(*onelink, limit=LIMIT, screen=True)
    whole, plain = _closed_loop(*onelink, limit=LIMIT, screen=False)
    assert plain.stats.slack_max > 0 and plain.stats.summary()["fallbacks"] == 0
    calls = ctrl._calls()
    # the deflection limit binds in the transient (whole QP) and not once the link settles
    assert 0 < calls.screened < calls.solves, (calls.screened, calls.solves)
    np.testing.assert_allclose(
        screened, whole, rtol=0, atol=1e-5 * 15.0
    )  # measured 7e-7 N m (solver tolerance)


def test_a_bound_function_shares_arrays_and_renews_its_memory_on_request():
    x = ca.MX.sym("x", 3)
    first = ca.Function("first", [x], [2 * x], ["x"], ["y"])
    second = ca.Function("second", [x], [ca.sumsqr(x)], ["x"], ["s"])
    link = np.zeros(3)
    a, b = BoundFunction(first, {"y": link}), BoundFunction(second, {"x": link}, renew=True)
    a.arrays["x"][:] = [1.0, 2.0, 3.0]
    a.evaluate()
    b.evaluate()
    assert b.arrays["s"].item() == 56.0  # (2 + 4 + 6)-squared sum through the shared array, no copy
    b.evaluate()
    assert b.arrays["s"].item() == 56.0
    with pytest.raises(ValueError, match="has no input or output"):
        BoundFunction(first, {"z": link})
    with pytest.raises(ValueError, match="C-ordered float64 with 3 entries"):
        BoundFunction(first, {"x": np.zeros(4)})


def test_the_screened_qp_through_hpipm_directly_gives_casadi_conics_optimum(onelink):
    direct, ctrl = _closed_loop(*onelink, limit=LIMIT)
    conic, other = _closed_loop(*onelink, limit=LIMIT, direct=False)
    calls, slow = ctrl._calls(), other._calls()
    assert calls.screen.backend == "hpipm (direct)" and slow.screen.backend == "casadi.conic hpipm"
    # the same samples are screened (the soft rows bind in the transient, then hold) and none fails
    assert 0 < calls.screened == slow.screened < calls.solves
    assert ctrl.stats.summary()["fallbacks"] == other.stats.summary()["fallbacks"] == 0
    # one optimum to the interior point's tolerance: HPIPM sees no +-1e8 state boxes here, so other
    # iterates
    np.testing.assert_allclose(direct, conic, rtol=0, atol=1e-5 * 15.0)
    assert not np.array_equal(direct, conic)  # really the other path


def test_the_direct_path_refuses_bounds_it_does_not_carry(onelink):
    _, ctrl = _closed_loop(*onelink, samples=2, limit=LIMIT)
    calls = ctrl._calls()
    lay = ctrl.layout
    lbx, ubx = ctrl._bounds(np.zeros(lay.n))
    lbx[lay.z[3][0]] = -1.0  # a state bound the direct path would silently drop
    a, lba, uba = calls.linearize(np.zeros(lay.n), ctrl._w)
    with pytest.raises(ValueError, match="z_0 fixed and only the inputs bounded"):
        calls.screen.direct.solve(a, lba, ctrl.functions["g0"], lbx, ubx, ctrl._w)
