"""The linear MPC's quadratic programme: the sparse and condensed QPs, move blocking.

See :mod:`flexctrl.control.mpc.controller` for the problem, the formulations and the scaling.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from flexctrl.control.mpc.problem import ScaledProblem


# --------------------------------------------------------------------------------------
# problem data
# --------------------------------------------------------------------------------------
# --------------------------------------------------------------------------------------
# QP formulations
# --------------------------------------------------------------------------------------
@dataclass(eq=False)
class QP:
    """``min 1/2 w'Hw + g'w  s.t.  lba <= A w <= uba,  lbx <= w <= ubx`` with ``z(t)`` entering
    affinely.

    ``g = g0 + Gz @ z``; ``lba/uba = lba0/uba0 + Lz @ z`` (rows ``Lz`` nonzero only for the
    condensed soft rows); ``lbx[ix0] = ubx[ix0] = z`` (sparse: the initial state).
    ``first_move`` indexes ``v_0`` in ``w``; ``shift_w``/``shift_a`` map a solution to its
    shifted warm start (index arrays).  ``slack`` indexes all ``s``.
    """

    H: sp.csc_matrix
    g0: np.ndarray
    A: sp.csc_matrix
    lba0: np.ndarray
    uba0: np.ndarray
    lbx: np.ndarray
    ubx: np.ndarray
    Gz: np.ndarray | None
    Lz: np.ndarray | None
    ix0: np.ndarray
    first_move: np.ndarray
    moves: np.ndarray  # (N, m) indices of every v_k
    slack: np.ndarray
    shift_w: np.ndarray
    shift_a: np.ndarray
    stages: dict  # structure for HPIPM (N, nx, nu, ng) or {}
    n_state: int
    soft_rows: (
        np.ndarray
    )  # (S, 2 ns): the general rows of the soft constraints of each constrained stage
    soft_steps: np.ndarray | None = (
        None  # the stages (0-based, of z_1..z_N) with soft rows; None: all
    )
    block_starts: np.ndarray | None = (
        None  # move blocking: first stage of every block; None: no blocking
    )
    n_arrival: int = 0  # the last n_arrival soft rows of every constrained stage are arrival rows

    @property
    def n_moves(self) -> int:
        """Number of move variables (the first entries of ``w`` in the condensed form)."""
        return int(self.moves.max()) + 1

    def vectors(
        self,
        z: np.ndarray,
        dv: np.ndarray | None = None,
        dc: np.ndarray | None = None,
        release: np.ndarray | None = None,
    ):
        """``(g, lba, uba, lbx, ubx)`` for the current scaled state ``z``.

        ``dv`` (N, m) and ``dc`` (N, ns) shift the input bounds and the soft-row bounds of
        each stage down (the scaled reference input and soft-row value, see the module docstring).
        ``release`` (one bool per constrained stage) lifts the bounds of that stage's arrival rows.
        """
        g = self.g0 if self.Gz is None else self.g0 + self.Gz @ z
        if self.Lz is None:
            lba, uba = self.lba0, self.uba0
        else:
            shift = self.Lz @ z
            lba, uba = self.lba0 + shift, self.uba0 + shift
        lbx, ubx = self.lbx, self.ubx
        if self.ix0.size or dv is not None:
            lbx, ubx = lbx.copy(), ubx.copy()
        if self.ix0.size:
            lbx[self.ix0] = z
            ubx[self.ix0] = z
        if dv is not None and self.block_starts is None:
            lbx[self.moves] -= dv
            ubx[self.moves] -= dv
        elif dv is not None:  # a held block must respect the bound of every stage it covers
            blocks = self.moves[self.block_starts]
            lbx[blocks] -= np.minimum.reduceat(
                dv, self.block_starts, axis=0
            )  # lo - dv_k for every k: lo - min dv
            ubx[blocks] -= np.maximum.reduceat(
                dv, self.block_starts, axis=0
            )  # hi - dv_k for every k: hi - max dv
        if dc is not None and self.soft_rows.size:
            if self.soft_steps is not None:
                dc = dc[self.soft_steps]
            shift = np.hstack([dc, dc])
            lba, uba = lba.copy(), uba.copy()
            lba[self.soft_rows] -= shift
            uba[self.soft_rows] -= shift
        if release is not None and self.n_arrival and np.any(release):
            ns, na = self.soft_rows.shape[1] // 2, self.n_arrival
            lba, uba = lba.copy(), uba.copy()
            free = self.soft_rows[np.asarray(release, bool)]
            uba[free[:, ns - na : ns]] = np.inf  # the upper rows of the arrival constraints
            lba[free[:, 2 * ns - na :]] = -np.inf  # and the lower ones
        return g, lba, uba, lbx, ubx


def _shift_blocks(first: int, block: int, count: int, tail: np.ndarray) -> np.ndarray:
    """Indices of stage blocks shifted one stage earlier, the last stage repeated, then ``tail`` unchanged."""
    idx = [np.arange(first)]
    for k in range(count):
        src = min(k + 1, count - 1)
        idx.append(first + src * block + np.arange(block))
    idx.append(tail)
    return np.concatenate(idx).astype(int)


def sparse_qp(pb: ScaledProblem, soft_on_next: bool = False) -> QP:
    """Stage-wise sparse QP (see the module docstring); ``soft_on_next``: soft rows on ``A z_k + B v_k`` (HPIPM)."""
    n, m, ns, N = pb.n, pb.m, pb.ns, pb.horizon
    blk = n + m + ns
    nw = N * blk + n
    zi = lambda k: k * blk + np.arange(n)  # noqa: E731
    vi = lambda k: k * blk + n + np.arange(m)  # noqa: E731
    si = lambda k: k * blk + n + m + np.arange(ns)  # noqa: E731
    zN = N * blk + np.arange(n)
    # Hessian (upper triangle is enough for OSQP; give full symmetric for casadi)
    H = sp.lil_matrix((nw, nw))
    g0 = np.zeros(nw)
    for k in range(N):
        H[np.ix_(zi(k), zi(k))] = pb.Q
        H[np.ix_(vi(k), vi(k))] = pb.R
        if ns:
            H[np.ix_(si(k), si(k))] = pb.l2 * np.eye(ns)
            g0[si(k)] = pb.l1
    H[np.ix_(zN, zN)] = pb.P
    # rows per stage: dynamics (n) then 2 ns soft rows
    rblk = n + 2 * ns
    A = sp.lil_matrix((N * rblk, nw))
    lba, uba = np.zeros(N * rblk), np.zeros(N * rblk)
    for k in range(N):
        r = k * rblk
        dyn = r + np.arange(n)
        A[np.ix_(dyn, zi(k))] = pb.A
        A[np.ix_(dyn, vi(k))] = pb.B
        A[np.ix_(dyn, zN if k == N - 1 else zi(k + 1))] = -np.eye(n)
        if ns:
            lo, hi = r + n + np.arange(ns), r + n + ns + np.arange(ns)
            for rows, sign in ((hi, -1.0), (lo, 1.0)):
                if soft_on_next:
                    A[np.ix_(rows, zi(k))] = pb.C @ pb.A
                    A[np.ix_(rows, vi(k))] = pb.C @ pb.B
                else:
                    A[np.ix_(rows, zN if k == N - 1 else zi(k + 1))] = pb.C
                A[np.ix_(rows, si(k))] = sign * np.eye(ns)
            lba[hi], uba[hi] = -np.inf, pb.c_hi
            lba[lo], uba[lo] = pb.c_lo, np.inf
    lbx, ubx = np.full(nw, -np.inf), np.full(nw, np.inf)
    for k in range(N):
        lbx[vi(k)], ubx[vi(k)] = pb.v_lo, pb.v_hi
        if ns:
            lbx[si(k)] = 0.0
    shift_w = _shift_blocks(0, blk, N, zN)
    shift_a = _shift_blocks(0, rblk, N, np.zeros(0, int))
    stages = {"N": N, "nx": [n] * (N + 1), "nu": [m + ns] * N + [0], "ng": [2 * ns] * N + [0]}
    soft = np.array([k * rblk + n + np.arange(2 * ns) for k in range(N)], dtype=int).reshape(
        N, 2 * ns
    )
    return QP(
        sp.csc_matrix(H),
        g0,
        sp.csc_matrix(A),
        lba,
        uba,
        lbx,
        ubx,
        None,
        None,
        zi(0),
        vi(0),
        np.array([vi(k) for k in range(N)]),
        np.concatenate([si(k) for k in range(N)]) if ns else np.zeros(0, int),
        shift_w,
        shift_a,
        stages,
        n,
        soft,
    )


def prediction_matrices(pb: ScaledProblem) -> tuple[np.ndarray, np.ndarray]:
    """``Phi`` (N n x n) and ``Gamma`` (N n x N m): ``[z_1..z_N] = Phi z_0 + Gamma v``."""
    n, m, N = pb.n, pb.m, pb.horizon
    Phi = np.zeros((N * n, n))
    Gam = np.zeros((N * n, N * m))
    Ak = np.eye(n)
    powers = []
    for k in range(N):
        powers.append(Ak)
        Ak = pb.A @ Ak
        Phi[k * n : (k + 1) * n] = Ak
    for k in range(N):
        for j in range(k + 1):
            Gam[k * n : (k + 1) * n, j * m : (j + 1) * m] = powers[k - j] @ pb.B
    return Phi, Gam


def blocking_matrix(blocks: tuple[int, ...], m: int) -> np.ndarray:
    """``T`` (N m x B m): the stage moves ``v = T b`` of the block moves ``b`` (each held over its block)."""
    N = sum(blocks)
    T = np.zeros((N * m, len(blocks) * m))
    k = 0
    for b, length in enumerate(blocks):
        for _ in range(length):
            T[k * m : (k + 1) * m, b * m : (b + 1) * m] = np.eye(m)
            k += 1
    return T


def condensed_qp(pb: ScaledProblem, blocks: tuple[int, ...] = (), stride: int = 1) -> QP:
    """Dense QP in ``[v, s]`` (see the module docstring), or in ``[b, s]`` with move blocking.

    ``blocks`` hold the move over groups of stages (``v = T b``, :func:`blocking_matrix`), so
    a horizon that covers a whole manoeuvre keeps few variables; ``stride`` keeps the soft
    rows of every ``stride``-th predicted state only (the last one always).
    """
    n, m, ns, N = pb.n, pb.m, pb.ns, pb.horizon
    Phi, Gam = prediction_matrices(pb)
    Qt = np.zeros((N * n, N * n))
    for k in range(N - 1):
        Qt[k * n : (k + 1) * n, k * n : (k + 1) * n] = pb.Q
    Qt[(N - 1) * n :, (N - 1) * n :] = pb.P
    if blocks:
        T = blocking_matrix(blocks, m)
        Gam = Gam @ T
        Hv = Gam.T @ Qt @ Gam + T.T @ np.kron(np.eye(N), pb.R) @ T
        nv = len(blocks) * m
        starts = np.r_[0, np.cumsum(blocks)[:-1]].astype(int)
        block_of = np.repeat(np.arange(len(blocks)), blocks)
    else:
        Hv = Gam.T @ Qt @ Gam + np.kron(np.eye(N), pb.R)
        nv = N * m
        starts, block_of = None, np.arange(N)
    Fv = Gam.T @ Qt @ Phi
    steps = (
        np.arange(N) if stride == 1 else np.unique(np.r_[np.arange(stride - 1, N, stride), N - 1])
    )
    S = steps.size
    nsl = S * ns
    nw = nv + nsl
    H = np.zeros((nw, nw))
    H[:nv, :nv] = 0.5 * (Hv + Hv.T)
    H[nv:, nv:] = pb.l2 * np.eye(nsl)
    g0 = np.r_[np.zeros(nv), np.full(nsl, pb.l1)]
    Gz = np.vstack([Fv, np.zeros((nsl, n))])
    lbx = np.r_[np.tile(pb.v_lo, nv // m), np.zeros(nsl)]
    ubx = np.r_[np.tile(pb.v_hi, nv // m), np.full(nsl, np.inf)]
    if ns:
        rows = (steps[:, None] * n + np.arange(n)[None, :]).ravel()
        Cb = np.kron(np.eye(S), pb.C)
        CG, CP = Cb @ Gam[rows], Cb @ Phi[rows]
        Islack = np.eye(nsl)
        A = np.vstack([np.hstack([CG, -Islack]), np.hstack([CG, Islack])])
        lba0 = np.r_[np.full(nsl, -np.inf), np.tile(pb.c_lo, S)]
        uba0 = np.r_[np.tile(pb.c_hi, S), np.full(nsl, np.inf)]
        Lz = -np.vstack([CP, CP])
    else:
        A, lba0, uba0, Lz = np.zeros((0, nw)), np.zeros(0), np.zeros(0), None
    moves = (block_of[:, None] * m + np.arange(m)[None, :]).astype(int)
    if (
        blocks or stride > 1
    ):  # a blocked or thinned plan does not shift by one stage: warm start from the last
        shift_w, shift_a = np.arange(nw), np.arange(A.shape[0])
    else:
        shift_v = _shift_blocks(0, m, N, np.zeros(0, int))
        shift_s = nv + _shift_blocks(0, ns, N, np.zeros(0, int)) if ns else np.zeros(0, int)
        shift_w = np.r_[shift_v, shift_s].astype(int)
        shift_a = (
            np.r_[
                _shift_blocks(0, ns, N, np.zeros(0, int)),
                nsl + _shift_blocks(0, ns, N, np.zeros(0, int)),
            ].astype(int)
            if ns
            else np.zeros(0, int)
        )
    soft = np.array(
        [np.r_[k * ns + np.arange(ns), nsl + k * ns + np.arange(ns)] for k in range(S)], dtype=int
    ).reshape(S, 2 * ns)
    return QP(
        sp.csc_matrix(H),
        g0,
        sp.csc_matrix(A),
        lba0,
        uba0,
        lbx,
        ubx,
        Gz,
        Lz,
        np.zeros(0, int),
        moves[0],
        moves,
        nv + np.arange(nsl),
        shift_w,
        shift_a,
        {},
        n,
        soft,
        None if stride == 1 else steps,
        starts,
        pb.n_arrival,
    )


# --------------------------------------------------------------------------------------


__all__ = [
    "QP",
    "sparse_qp",
    "prediction_matrices",
    "blocking_matrix",
    "condensed_qp",
]
