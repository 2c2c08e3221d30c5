"""The RTI's QP tried without its soft rows: the whole QP's optimum, by HPIPM or its fall-back."""

from __future__ import annotations

import numpy as np
import pytest

from flexctrl.control.nmpc import hpipm_ocp
from flexctrl.control.nmpc.controller import design_nmpc, interval_functions
from flexctrl.spec.controller_settings import NMPCSettings

#: m: passed in the transient (the first 21 of 40 samples solve the whole QP), held after
LIMIT = 0.01
SMALL = dict(compile=False, horizon=15, sample_time=0.02, deflection_limit=0.02, qp_warm_start=True)


def _closed_loop(model, op, samples=40, limit=0.02, screen=True):
    """The NMPC's torques over ``samples`` of a closed loop; ``screen=False`` always solves the
    whole QP."""
    settings = NMPCSettings(sensitivities="midpoint", **{**SMALL, "deflection_limit": limit})
    ctrl = design_nmpc(model, op, settings)
    ctrl.screen = ctrl.screen and screen
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
    # the same optimum to the solver's tolerance (7e-7 N m apart on this run)
    np.testing.assert_allclose(screened, whole, rtol=0, atol=1e-5 * 15.0)


def test_without_hpipms_library_the_screened_qp_falls_back_to_casadi_conic(onelink, monkeypatch):
    direct, ctrl = _closed_loop(*onelink, limit=LIMIT)

    def unavailable():
        raise hpipm_ocp.HpipmUnavailable("no loadable libhpipm (for the test)")

    monkeypatch.setattr(hpipm_ocp, "library", unavailable)
    conic, other = _closed_loop(*onelink, limit=LIMIT)
    calls, fallback = ctrl._calls(), other._calls()
    assert calls.screen.backend == "hpipm (direct)"
    assert fallback.screen.backend == "casadi.conic hpipm (no loadable libhpipm (for the test))"
    assert fallback.screen.direct is None
    # the same samples are screened (the soft rows bind in the transient, then hold) and none fails
    assert 0 < calls.screened == fallback.screened < calls.solves
    assert ctrl.stats.summary()["fallbacks"] == other.stats.summary()["fallbacks"] == 0
    # one optimum to the interior point's tolerance: HPIPM sees no +-1e8 state boxes when called
    # directly, so it takes other iterates
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
