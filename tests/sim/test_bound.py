"""Functions called through buffers bound to numpy arrays: the values of an ordinary call."""

from __future__ import annotations

import casadi as ca
import numpy as np

from flexctrl.sim.bound import BoundFunction, evaluate


def test_a_bound_function_gives_the_calls_values_as_rows_and_copies():
    x, u = ca.MX.sym("x", 3), ca.MX.sym("u", 2)
    fun = ca.Function("f", [x, u], [ca.horzcat(x * u[0], ca.sin(x) + u[1]), ca.sumsqr(x)])
    bound = BoundFunction(fun)
    rng = np.random.default_rng(1)
    got, wanted = [], []
    for _ in range(3):
        xv, uv = rng.standard_normal(3), rng.standard_normal(2)
        got.append(bound(xv, uv))
        wanted.append(fun(xv, uv))
    for (block, square), want in zip(
        got, wanted
    ):  # earlier results are the caller's: later calls leave them
        np.testing.assert_array_equal(
            block, np.asarray(want[0]).T
        )  # (3 x 2) comes back as 2 rows of 3
        assert block.shape == (2, 3) and square.item() == float(want[1])


def test_evaluate_gives_a_calls_values_as_rows_for_any_input_shape():
    x, u = ca.MX.sym("x", 3), ca.MX.sym("u", 2)
    fun = ca.Function("f", [x, u], [ca.horzcat(x * u[0], ca.sin(x) + u[1]), ca.sumsqr(x)])
    xv, uv = np.array([0.3, -1.2, 2.0]), np.array([[0.5], [-0.25]])  # u as a column
    block, square = evaluate(fun, xv, uv)
    want = fun(xv, uv)
    np.testing.assert_array_equal(block, np.asarray(want[0]).T)
    assert square.item() == float(want[1]) and block.shape == (2, 3)


def test_a_renewed_buffer_gives_the_same_values_call_after_call():
    x = ca.MX.sym("x", 2)
    fun = ca.Function("g", [x], [ca.vertcat(x[0] * x[1], ca.exp(x[0]))])
    plain, renewed = BoundFunction(fun), BoundFunction(fun, renew=True)
    rng = np.random.default_rng(3)
    for _ in range(3):
        xv = rng.standard_normal(2)
        (a,), (b,) = plain(xv), renewed(xv)
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(a.ravel(), np.asarray(fun(xv)).ravel())
