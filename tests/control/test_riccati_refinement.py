"""The LQR's Riccati solution on the shipped arm in physical units: refined to a residual far
below the acceptance bound, so a design is refused for a wrong solution, never for round-off.

The arm's state is in rad, m, rad/s and m/s; its stiff modes make ``||A||`` 1e3-1e5, which
leaves the doubling's solution accurate to about 1e-7 and its residual near 1e-10, within a
factor 100 of the bound (1e-8): a candidate's design failed at 1.45e-8 on another machine's
round-off.  One Newton step takes the residual to ~1e-12.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sl

import flexctrl as fc
import flexctrl.control.riccati as riccati_module
from flexctrl.control.riccati import RESIDUAL_TOL, _residual, solve_dare


@pytest.fixture(scope="module")
def dare():
    """The (A, B, Q, R) the shipped LQR solves on the 3-mode arm at 30 deg, 2 kg."""
    seen = []
    original = riccati_module.solve_dare

    def record(A, B, Q, R, **kwargs):
        seen.append((kwargs.get("what"), *(np.array(M, dtype=float) for M in (A, B, Q, R))))
        return original(A, B, Q, R, **kwargs)

    riccati_module.solve_dare = record
    try:
        model = fc.load_model("subedi3link", payload=2.0, fidelity="amm:3", gravity=[0.0, 0.0])
        fc.design(model, fc.equilibrium(model, np.radians([30, 0, 0])), fc.load_controller("lqr"))
    finally:
        riccati_module.solve_dare = original
    return next(entry[1:] for entry in seen if entry[0] == "LQR")


def test_the_refined_solution_is_far_inside_the_residual_bound(dare):
    A, B, Q, R = dare
    assert np.linalg.norm(A) > 1e4  # the physical units this is about
    X = solve_dare(A, B, Q, R, what="LQR")
    assert _residual(A, B, Q, R, X) < 1e-3 * RESIDUAL_TOL
    # the same stabilising solution as scipy's Schur method, and the same gain
    reference = sl.solve_discrete_are(A, B, Q, R)
    assert np.linalg.norm(X - reference) < 1e-8 * np.linalg.norm(reference)
    gain = np.linalg.solve(R + B.T @ X @ B, B.T @ X @ A)
    expected = np.linalg.solve(R + B.T @ reference @ B, B.T @ reference @ A)
    assert np.linalg.norm(gain - expected) < 1e-8 * np.linalg.norm(expected)
