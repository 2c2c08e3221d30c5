"""One interval Jacobian per group of shooting intervals (``stages_per_jacobian``), against one per
interval.

The grouped linearisation must give every interval its own nonlinear shooting end and, for
its sensitivities, exactly those of the group's middle interval; the RTI built on it keeps
the fixed points of the nonlinear shooting equations, so a closed loop that settles with one
Jacobian per interval settles at the same place with one per group.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from flexctrl.control.nmpc.controller import design_nmpc
from flexctrl.control.nmpc.interval import group_centres
from flexctrl.errors import SpecError
from flexctrl.spec.controller_reader import controller_from_document
from flexctrl.spec.controller_settings import NMPCSettings

SMALL = dict(compile=False, horizon=10, sample_time=0.02, deflection_limit=0.02, qp_warm_start=True)


def test_each_group_is_served_by_its_middle_interval():
    assert group_centres(20, 4) == [1, 5, 9, 13, 17]
    assert group_centres(20, 20) == [9]
    assert group_centres(20, 3) == [1, 4, 7, 10, 13, 16, 18]  # the last group has two intervals
    assert group_centres(5, 1) == [0, 1, 2, 3, 4]
    assert group_centres(5, 9) == [2]


@pytest.mark.parametrize("stages", [3, 10])
def test_grouped_linearization_has_every_shooting_end_and_the_centres_sensitivities(
    onelink, stages
):
    model, op = onelink
    settings = NMPCSettings(**SMALL)
    per_interval = design_nmpc(model, op, settings)
    grouped = design_nmpc(model, op, dataclasses.replace(settings, stages_per_jacobian=stages))
    lay, params = per_interval.layout, per_interval.functions["params"]
    rng = np.random.default_rng(2)
    Z, V = rng.normal(0, 0.2, (lay.n, lay.N)), rng.normal(0, 0.2, (lay.m, lay.N))
    F1, A1, B1 = (np.array(a, dtype=float) for a in per_interval.functions["linmap"](Z, V, params))
    F2, A2, B2 = (np.array(a, dtype=float) for a in grouped.functions["linmap"](Z, V, params))
    np.testing.assert_allclose(F2, F1, rtol=1e-12, atol=1e-12)  # nonlinear ends on every interval
    n, m = lay.n, lay.m
    centres = group_centres(lay.N, stages)
    for k in range(lay.N):
        c = centres[k // stages]
        np.testing.assert_array_equal(A2[:, k * n : (k + 1) * n], A1[:, c * n : (c + 1) * n])
        np.testing.assert_array_equal(B2[:, k * m : (k + 1) * m], B1[:, c * m : (c + 1) * m])
    assert not np.allclose(
        A1[:, :n], A1[:, (lay.N - 1) * n :]
    )  # the intervals' own Jacobians differ


def test_a_loop_on_grouped_sensitivities_settles_where_the_per_interval_one_does(onelink):
    model, op = onelink
    settings = NMPCSettings(**SMALL)
    finals = []
    for stages in (1, 10):
        ctrl = design_nmpc(model, op, dataclasses.replace(settings, stages_per_jacobian=stages))
        from flexctrl.control.nmpc.controller import interval_functions

        F, _ = interval_functions(model, settings.sample_time, 4, None)
        x = op.x.copy()
        x[0] -= 0.3
        for k in range(60):
            x = np.array(F(x, ctrl.step(k * settings.sample_time, x)), dtype=float).ravel()
        finals.append(x)
        assert ctrl.stats.summary()["fallbacks"] == 0
    for x in finals:
        assert abs(x[0] - op.x[0]) < 1e-3  # rad: both reached the target
    np.testing.assert_allclose(finals[1], finals[0], atol=1e-4)


def test_stages_per_jacobian_is_read_and_checked():
    assert (
        controller_from_document(
            {"kind": "nmpc", "stages_per_jacobian": 4}, "nmpc.toml"
        ).stages_per_jacobian
        == 4
    )
    with pytest.raises(SpecError, match="nmpc_bad.toml.*stages_per_jacobian"):
        controller_from_document({"kind": "nmpc", "stages_per_jacobian": 0}, "nmpc_bad.toml")
