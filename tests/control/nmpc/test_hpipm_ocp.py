"""HPIPM called directly on the input-bounded OCP QP, against a KKT solve and casadi.conic."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from flexctrl.control.nmpc.hpipm_ocp import HpipmOCP

N, NX, NU = 8, 4, 2
TIGHT = {
    "mode": "robust",
    "iter_max": 100,
    "res_g_max": 1e-11,
    "res_b_max": 1e-11,
    "res_d_max": 1e-11,
    "res_m_max": 1e-11,
}


def _problem(seed: int = 3):
    rng = np.random.default_rng(seed)
    A = [np.eye(NX) + 0.1 * rng.standard_normal((NX, NX)) for _ in range(N)]
    B = [0.3 * rng.standard_normal((NX, NU)) for _ in range(N)]
    b = [0.05 * rng.standard_normal(NX) for _ in range(N)]
    Q = np.diag(rng.uniform(0.5, 2.0, NX))
    R = np.diag(rng.uniform(0.5, 2.0, NU))
    S = 0.1 * rng.standard_normal((NU, NX))  # cross terms u' S x, so the eliminated x_0 enters r_0
    q = [0.2 * rng.standard_normal(NX) for _ in range(N + 1)]
    r = [0.2 * rng.standard_normal(NU) for _ in range(N)]
    return A, B, b, Q, R, S, q, r, rng.standard_normal(NX)


def _stacked(A, B, b, Q, R, S, q, r, x0):
    """The same QP over w = [x_0, u_0, x_1, ..., x_N]: H, g, equality rows, their right side."""
    blk = NX + NU
    nw = N * blk + NX
    H, g = np.zeros((nw, nw)), np.zeros(nw)
    E, e = np.zeros((N * NX, nw)), np.zeros(N * NX)
    for k in range(N):
        x, u = slice(k * blk, k * blk + NX), slice(k * blk + NX, (k + 1) * blk)
        H[x, x], H[u, u], H[u, x], H[x, u] = Q, R, S, S.T
        g[x], g[u] = q[k], r[k]
        rows = slice(k * NX, (k + 1) * NX)
        E[rows, x], E[rows, u], E[rows, (k + 1) * blk : (k + 1) * blk + NX] = (
            A[k],
            B[k],
            -np.eye(NX),
        )
        e[rows] = -b[k]
    H[N * blk :, N * blk :], g[N * blk :] = 2 * Q, q[N]
    return H, g, E, e


def _direct(A, B, b, Q, R, S, q, r, x0, bound, options=TIGHT):
    ocp = HpipmOCP(N, NX, NU, options)
    for k in range(N):
        ocp.A[k], ocp.B[k], ocp.b[k] = A[k].T, B[k].T, b[k]
        ocp.R[k], ocp.S[k], ocp.r[k] = R.T, S.T, r[k]
        ocp.lbu[k], ocp.ubu[k] = -bound, bound
    for k in range(1, N + 1):
        ocp.Q[k], ocp.q[k] = (Q if k < N else 2 * Q).T, q[k]
    ocp.b[0] = A[0] @ x0 + b[0]  # x_0 eliminated
    ocp.r[0] = r[0] + S @ x0
    stats = ocp.solve()
    w = [x0]
    for k in range(N):
        w += [ocp.u[k], ocp.x[k + 1]]
    return np.concatenate(w), stats


def test_direct_hpipm_solves_the_unbounded_qp_as_its_kkt_system_does():
    data = _problem()
    H, g, E, e = _stacked(*data)
    x0 = data[-1]
    # fix x_0 by equality rows too and solve the KKT system exactly
    nw = H.shape[0]
    F = np.vstack([E, np.eye(NX, nw)])
    f = np.r_[e, x0]
    K = np.block([[H, F.T], [F, np.zeros((F.shape[0], F.shape[0]))]])
    exact = np.linalg.solve(K, np.r_[-g, f])[:nw]
    # bounds far from the optimum (|u| < 2 here) but not huge: with +-1e6 the complementarity of the
    # inactive bounds stops short of 1e-11 (HPIPM reports MAX_ITER), an interior point's limit, not
    # the data's
    w, stats = _direct(*data, bound=1e3)
    assert np.abs(exact).max() < 1e2
    assert stats["success"] and stats["return_status"] == "SUCCESS"
    np.testing.assert_allclose(w, exact, rtol=0, atol=1e-8 * np.abs(exact).max())


def test_direct_hpipm_finds_casadi_conics_optimum_with_bounds_binding():
    data = _problem(seed=5)
    H, g, E, e = _stacked(*data)
    x0 = data[-1]
    nw = H.shape[0]
    bound = 0.4
    lbx, ubx = np.full(nw, -np.inf), np.full(nw, np.inf)
    lbx[:NX] = ubx[:NX] = x0
    for k in range(N):
        lbx[k * (NX + NU) + NX : (k + 1) * (NX + NU)] = -bound
        ubx[k * (NX + NU) + NX : (k + 1) * (NX + NU)] = bound
    Hs, Es = ca.DM(ca.sparsify(ca.DM(H))), ca.DM(ca.sparsify(ca.DM(E)))
    qp = ca.conic(
        "reference",
        "hpipm",
        {"h": Hs.sparsity(), "a": Es.sparsity()},
        {
            "N": N,
            "nx": [NX] * (N + 1),
            "nu": [NU] * N + [0],
            "ng": [0] * (N + 1),
            "error_on_fail": False,
            "hpipm": TIGHT,
        },
    )
    reference = np.asarray(
        qp(h=Hs, g=g, a=Es, lba=e, uba=e, lbx=lbx, ubx=ubx)["x"], dtype=float
    ).ravel()
    w, stats = _direct(*data, bound=bound)
    assert stats["success"]
    inputs = np.concatenate([w[k * (NX + NU) + NX : (k + 1) * (NX + NU)] for k in range(N)])
    assert (
        np.sum(np.isclose(np.abs(inputs), bound, atol=1e-7)) >= 3
    )  # the bounds bind: not the unbounded optimum
    np.testing.assert_allclose(w, reference, rtol=0, atol=1e-7)


def test_direct_hpipm_names_what_it_does_not_interface():
    with pytest.raises(ValueError, match=r"not interfaced; allowed: \['iter_max'"):
        HpipmOCP(N, NX, NU, {"tol": 1e-6})
    with pytest.raises(ValueError, match="mode 'fast' is not allowed; allowed:"):
        HpipmOCP(N, NX, NU, {"mode": "fast"})
