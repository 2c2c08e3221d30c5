"""The DARE by doubling: scipy's solution where it has one, a refusal where none stabilises."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg


def test_doubling_dare_agrees_with_scipy_and_refuses_an_uncontrollable_unstable_mode():
    from flexctrl.control.riccati import solve_dare
    from flexctrl.errors import SolverError

    rng = np.random.default_rng(3)
    for _ in range(5):
        A = rng.normal(size=(6, 6)) / 2
        B, Q, R = rng.normal(size=(6, 2)), np.eye(6), np.diag([1.0, 3.0])
        np.testing.assert_allclose(
            solve_dare(A, B, Q, R),
            scipy.linalg.solve_discrete_are(A, B, Q, R),
            rtol=1e-8,
            atol=1e-10,
        )
    with pytest.raises(SolverError):
        solve_dare(np.diag([1.5, 0.5]), np.array([[0.0], [1.0]]), np.eye(2), np.eye(1))
