"""One real-time iteration: its calls through bound buffers and its checks of the QP data."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from flexctrl.control.nmpc.rti import qp_data_problem
from flexctrl.sim.bound import BoundFunction


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


def test_qp_data_problem_names_what_would_make_the_qp_solver_abort():
    w, a = np.zeros(3), np.ones(4)
    lo, hi = np.array([-np.inf, 0.0]), np.array([np.inf, 1.0])
    assert qp_data_problem(w, a, lo, hi) == ""  # one-sided rows are legitimate
    assert qp_data_problem(w, ca.DM(a), ca.DM(lo), ca.DM(hi)) == ""
    assert qp_data_problem(np.array([0.0, np.nan, 0.0]), a, lo, hi) == (
        "non-finite linearisation trajectory"
    )
    assert qp_data_problem(w, np.array([1.0, np.inf]), lo, hi) == "non-finite sensitivities"
    assert qp_data_problem(w, ca.DM([1.0, np.nan]), lo, hi) == "non-finite sensitivities"
    assert qp_data_problem(w, a, ca.DM([np.nan, 0.0]), hi) == "NaN in the constraint bounds"
    assert qp_data_problem(w, a, np.array([np.inf, 0.0]), hi) == "infinite shooting gap"
    assert qp_data_problem(w, a, lo, np.array([-np.inf, 1.0])) == "infinite shooting gap"
