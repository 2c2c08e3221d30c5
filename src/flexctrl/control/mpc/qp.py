"""The linear MPC's quadratic programme: the sparse and condensed QPs, move blocking.

See :mod:`flexctrl.control.mpc.controller` for the problem, the formulations and the scaling.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from flexctrl.control.mpc.problem import ScaledProblem


@dataclass(eq=False)
class QP:
    """``min 1/2 w'Hw + g'w  s.t.  lba <= A w <= uba,  lbx <= w <= ubx``, ``z(t)`` affine in it.

    ``g = g0 + Gz @ z``; ``lba/uba = lba0/uba0 + Lz @ z`` (rows of ``Lz`` nonzero only for the
    condensed soft rows); ``lbx[ix0] = ubx[ix0] = z`` (sparse: the initial state).

    Attributes
    ----------
    H, A : scipy.sparse.csc_matrix
        The Hessian and the constraint rows.
    g0, lba0, uba0, lbx, ubx : ndarray
        The linear cost and the bounds at ``z = 0`` (no reference shift).
    Gz, Lz : ndarray or None
        How ``z`` enters the cost and the row bounds (None: it does not).
    ix0 : ndarray of int
        The variables fixed to ``z`` (sparse form; empty when condensed).
    first_move : ndarray of int
        ``v_0`` in ``w``.
    moves : ndarray of int
        (N, m): every ``v_k`` in ``w``.
    slack : ndarray of int
        Every slack ``s`` in ``w``.
    shift_w, shift_a : ndarray of int
        A solution's (primal, dual) shifted by one stage, the warm start of the next sample.
    stages : dict
        The stage structure for HPIPM (``N``, ``nx``, ``nu``, ``ng``) or ``{}``.
    n_state : int
        The size of ``z``.
    soft_rows : ndarray of int
        (S, 2 ns): the rows of the soft constraints of each constrained stage.
    soft_steps : ndarray of int or None
        The stages (0-based, of ``z_1 .. z_N``) with soft rows; None: all.
    block_starts : ndarray of int or None
        Move blocking: the first stage of every block; None: no blocking.
    n_arrival : int
        The last ``n_arrival`` soft rows of every constrained stage are arrival rows.
    rate_rows : ndarray of int
        (N, r): the rows ``v_k - v_(k-1)`` (``v_0`` for ``k = 0``) of the joints with
        torque-rate bounds, after every other row; their bounds move with the reference and
        the last torque (``du`` of :meth:`vectors`).
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
    moves: np.ndarray
    slack: np.ndarray
    shift_w: np.ndarray
    shift_a: np.ndarray
    stages: dict
    n_state: int
    soft_rows: np.ndarray
    soft_steps: np.ndarray | None = None
    block_starts: np.ndarray | None = None
    n_arrival: int = 0
    rate_rows: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), int))

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
        du: np.ndarray | None = None,
    ):
        """``(g, lba, uba, lbx, ubx)`` for the current scaled state ``z``.

        Parameters
        ----------
        z : ndarray
            The scaled initial state deviation.
        dv, dc : ndarray, optional
            (N, m) and (N, ns): shift the input bounds and the soft-row bounds of each stage
            down (the scaled reference input and soft-row value, see the module docstring).
        release : ndarray of bool, optional
            One per constrained stage: lift the bounds of that stage's arrival rows.
        du : ndarray, optional
            (N, r): shift the torque-rate rows' bounds down (the scaled change of the
            reference torque, from the last torque applied for the first stage).

        Returns
        -------
        tuple of ndarray
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
        starts = self.block_starts
        if dv is not None and starts is None:
            lbx[self.moves] -= dv
            ubx[self.moves] -= dv
        elif dv is not None and starts is not None:
            # a held block must respect the bound of every stage it covers:
            # lo - dv_k for every k of the block is lo - min dv; hi - dv_k is hi - max dv
            blocks = self.moves[starts]
            lbx[blocks] -= np.minimum.reduceat(dv, starts, axis=0)
            ubx[blocks] -= np.maximum.reduceat(dv, starts, axis=0)
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
        if du is not None and self.rate_rows.size:
            lba, uba = lba.copy(), uba.copy()
            lba[self.rate_rows] -= du
            uba[self.rate_rows] -= du
        return g, lba, uba, lbx, ubx


def _shift_blocks(first: int, block: int, count: int, tail: np.ndarray) -> np.ndarray:
    """Indices of stage blocks shifted one stage earlier, the last one repeated, then ``tail``."""
    idx = [np.arange(first)]
    for k in range(count):
        src = min(k + 1, count - 1)
        idx.append(first + src * block + np.arange(block))
    idx.append(tail)
    return np.concatenate(idx).astype(int)


def rate_rows(pb: ScaledProblem, moves: np.ndarray, nw: int, first_row: int, shifted: bool):
    """The torque-rate rows (after ``first_row`` others) on the moves ``moves`` (N, m) of ``w``.

    Returns ``(A, lba, uba, rows, shift_a)``: row ``(k, j)`` is ``v_k - v_(k-1)`` of the
    ``j``-th rate-bounded joint (``v_0`` for ``k = 0``; zero when both are one held block),
    its bounds, the row indices (N, r) and their warm-start dual shift.
    """
    joints, N = pb.rate_joints, moves.shape[0]
    r = joints.size
    A = sp.lil_matrix((N * r, nw))
    for k in range(N):
        for i, j in enumerate(joints):
            A[k * r + i, moves[k, j]] += 1.0
            if k:
                A[k * r + i, moves[k - 1, j]] -= 1.0
    rows = first_row + np.arange(N * r).reshape(N, r)
    shift = _shift_blocks(0, r, N, np.zeros(0, int)) if shifted else np.arange(N * r)
    return A.tocsc(), np.tile(pb.rate_lo, N), np.tile(pb.rate_hi, N), rows, first_row + shift


class _StageIndex:
    """Where ``z_k``, ``v_k`` and ``s_k`` sit in the sparse QP's ``w = [z_0, v_0, ..., z_N]``."""

    def __init__(self, n: int, m: int, ns: int, N: int):
        self.n, self.m, self.ns, self.N = n, m, ns, N
        self.blk = n + m + ns
        self.nw = N * self.blk + n
        self.zN = N * self.blk + np.arange(n)

    def z(self, k: int) -> np.ndarray:
        """``z_k`` (``z_N`` for ``k = N``)."""
        return self.zN if k == self.N else k * self.blk + np.arange(self.n)

    def v(self, k: int) -> np.ndarray:
        """``v_k``."""
        return k * self.blk + self.n + np.arange(self.m)

    def s(self, k: int) -> np.ndarray:
        """``s_k``."""
        return k * self.blk + self.n + self.m + np.arange(self.ns)


def _sparse_cost(pb: ScaledProblem, ix: _StageIndex) -> tuple[sp.lil_matrix, np.ndarray]:
    """The sparse QP's Hessian (full and symmetric, as casadi wants it) and linear cost."""
    H = sp.lil_matrix((ix.nw, ix.nw))
    g0 = np.zeros(ix.nw)
    for k in range(ix.N):
        H[np.ix_(ix.z(k), ix.z(k))] = pb.Q
        H[np.ix_(ix.v(k), ix.v(k))] = pb.R
        if ix.ns:
            H[np.ix_(ix.s(k), ix.s(k))] = pb.l2 * np.eye(ix.ns)
            g0[ix.s(k)] = pb.l1
    H[np.ix_(ix.zN, ix.zN)] = pb.P
    return H, g0


def _sparse_rows(pb: ScaledProblem, ix: _StageIndex, soft_on_next: bool):
    """``(A, lba, uba)``: per stage the dynamics (n rows), then the 2 ns soft rows."""
    n, ns, N = ix.n, ix.ns, ix.N
    rblk = n + 2 * ns
    A = sp.lil_matrix((N * rblk, ix.nw))
    lba, uba = np.zeros(N * rblk), np.zeros(N * rblk)
    for k in range(N):
        r = k * rblk
        dyn = r + np.arange(n)
        A[np.ix_(dyn, ix.z(k))] = pb.A
        A[np.ix_(dyn, ix.v(k))] = pb.B
        A[np.ix_(dyn, ix.z(k + 1))] = -np.eye(n)
        if not ns:
            continue
        lo, hi = r + n + np.arange(ns), r + n + ns + np.arange(ns)
        for rows, sign in ((hi, -1.0), (lo, 1.0)):
            if soft_on_next:
                A[np.ix_(rows, ix.z(k))] = pb.C @ pb.A
                A[np.ix_(rows, ix.v(k))] = pb.C @ pb.B
            else:
                A[np.ix_(rows, ix.z(k + 1))] = pb.C
            A[np.ix_(rows, ix.s(k))] = sign * np.eye(ns)
        lba[hi], uba[hi] = -np.inf, pb.c_hi
        lba[lo], uba[lo] = pb.c_lo, np.inf
    return A, lba, uba


def sparse_qp(pb: ScaledProblem, soft_on_next: bool = False) -> QP:
    """Stage-wise sparse QP in ``[z_0, v_0, s_0, ..., z_N]`` (see the module docstring).

    Parameters
    ----------
    pb : ScaledProblem
        The scaled problem data.
    soft_on_next : bool
        Write the soft rows on ``A z_k + B v_k`` (the same constraint on ``z_{k+1}``, in the
        stage HPIPM wants) rather than on ``z_{k+1}``.

    Returns
    -------
    QP
    """
    n, m, ns, N = pb.n, pb.m, pb.ns, pb.horizon
    ix = _StageIndex(n, m, ns, N)
    H, g0 = _sparse_cost(pb, ix)
    A, lba, uba = _sparse_rows(pb, ix, soft_on_next)
    lbx, ubx = np.full(ix.nw, -np.inf), np.full(ix.nw, np.inf)
    for k in range(N):
        lbx[ix.v(k)], ubx[ix.v(k)] = pb.v_lo, pb.v_hi
        if ns:
            lbx[ix.s(k)] = 0.0
            if pb.hard is not None:
                ubx[ix.s(k)] = np.where(pb.hard, 0.0, np.inf)
    moves = np.array([ix.v(k) for k in range(N)])
    Ar, lr, ur, rows, shift_r = rate_rows(pb, moves, ix.nw, A.shape[0], True)
    rblk = n + 2 * ns
    stages = {"N": N, "nx": [n] * (N + 1), "nu": [m + ns] * N + [0], "ng": [2 * ns] * N + [0]}
    soft = np.array([k * rblk + n + np.arange(2 * ns) for k in range(N)], dtype=int)
    return QP(
        H=sp.csc_matrix(H),
        g0=g0,
        A=sp.vstack([sp.csc_matrix(A), Ar], format="csc"),
        lba0=np.r_[lba, lr],
        uba0=np.r_[uba, ur],
        lbx=lbx,
        ubx=ubx,
        Gz=None,
        Lz=None,
        ix0=ix.z(0),
        first_move=ix.v(0),
        moves=moves,
        slack=np.concatenate([ix.s(k) for k in range(N)]) if ns else np.zeros(0, int),
        shift_w=_shift_blocks(0, ix.blk, N, ix.zN),
        shift_a=np.r_[_shift_blocks(0, rblk, N, np.zeros(0, int)), shift_r].astype(int),
        stages=stages,
        n_state=n,
        soft_rows=soft.reshape(N, 2 * ns),
        rate_rows=rows,
    )


def prediction_matrices(pb: ScaledProblem) -> tuple[np.ndarray, np.ndarray]:
    """``Phi`` (N n x n) and ``Gamma`` (N n x N m): ``[z_1..z_N] = Phi z_0 + Gamma v``.

    Parameters
    ----------
    pb : ScaledProblem
        Its ``A``, ``B`` and horizon.

    Returns
    -------
    tuple of ndarray
    """
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
    """``T`` (N m x B m): the stage moves ``v = T b`` of the block moves ``b``, each held.

    Parameters
    ----------
    blocks : tuple of int
        Stages per block (they add up to the horizon ``N``).
    m : int
        Inputs per stage.

    Returns
    -------
    ndarray
    """
    N = sum(blocks)
    T = np.zeros((N * m, len(blocks) * m))
    k = 0
    for b, length in enumerate(blocks):
        for _ in range(length):
            T[k * m : (k + 1) * m, b * m : (b + 1) * m] = np.eye(m)
            k += 1
    return T


def _stage_cost(pb: ScaledProblem) -> np.ndarray:
    """``blockdiag(Q, ..., Q, P)`` over the predicted states ``z_1 .. z_N``."""
    n, N = pb.n, pb.horizon
    Qt = np.zeros((N * n, N * n))
    for k in range(N - 1):
        Qt[k * n : (k + 1) * n, k * n : (k + 1) * n] = pb.Q
    Qt[(N - 1) * n :, (N - 1) * n :] = pb.P
    return Qt


def _condensed_moves(pb: ScaledProblem, Gam: np.ndarray, blocks: tuple[int, ...]):
    """The moves' Hessian and prediction matrix, with or without move blocking.

    Returns ``(Hv, Gam_v, starts, block_of)``: ``Gam_v`` maps the move variables to the
    predicted states, ``starts`` the first stage of every block (None: no blocking) and
    ``block_of`` the move variable of every stage.
    """
    N, m, Qt = pb.horizon, pb.m, _stage_cost(pb)
    if not blocks:
        return Gam.T @ Qt @ Gam + np.kron(np.eye(N), pb.R), Gam, None, np.arange(N)
    T = blocking_matrix(blocks, m)
    Gam = Gam @ T
    Hv = Gam.T @ Qt @ Gam + T.T @ np.kron(np.eye(N), pb.R) @ T
    starts = np.r_[0, np.cumsum(blocks)[:-1]].astype(int)
    return Hv, Gam, starts, np.repeat(np.arange(len(blocks)), blocks)


def _condensed_soft_rows(pb: ScaledProblem, Gam: np.ndarray, Phi: np.ndarray, steps, nw: int):
    """``(A, lba0, uba0, Lz)`` of the soft rows of the predicted states ``steps`` (0-based).

    Upper rows ``C z - s <= c_hi``, then lower rows ``C z + s >= c_lo``; ``Lz`` moves their
    bounds with the initial state.
    """
    n, ns, S = pb.n, pb.ns, steps.size
    if not ns:
        return np.zeros((0, nw)), np.zeros(0), np.zeros(0), None
    nsl = S * ns
    rows = (steps[:, None] * n + np.arange(n)[None, :]).ravel()
    Cb = np.kron(np.eye(S), pb.C)
    CG, CP = Cb @ Gam[rows], Cb @ Phi[rows]
    Islack = np.eye(nsl)
    A = np.vstack([np.hstack([CG, -Islack]), np.hstack([CG, Islack])])
    lba0 = np.r_[np.full(nsl, -np.inf), np.tile(pb.c_lo, S)]
    uba0 = np.r_[np.tile(pb.c_hi, S), np.full(nsl, np.inf)]
    return A, lba0, uba0, -np.vstack([CP, CP])


def _condensed_shifts(pb: ScaledProblem, nv: int, nsl: int, rows: int, shifted: bool):
    """``(shift_w, shift_a)`` of the condensed QP's warm start.

    A blocked or thinned plan does not shift by one stage (``shifted`` False): it warm-starts
    from the last solution as it is.
    """
    m, ns, N = pb.m, pb.ns, pb.horizon
    if not shifted:
        return np.arange(nv + nsl), np.arange(rows)
    none = np.zeros(0, int)
    shift_v = _shift_blocks(0, m, N, none)
    shift_s = nv + _shift_blocks(0, ns, N, none) if ns else none
    if not ns:
        return np.r_[shift_v, shift_s].astype(int), none
    shift_a = np.r_[_shift_blocks(0, ns, N, none), nsl + _shift_blocks(0, ns, N, none)]
    return np.r_[shift_v, shift_s].astype(int), shift_a.astype(int)


def condensed_qp(pb: ScaledProblem, blocks: tuple[int, ...] = (), stride: int = 1) -> QP:
    """Dense QP in ``[v, s]`` (see the module docstring), or in ``[b, s]`` with move blocking.

    Parameters
    ----------
    pb : ScaledProblem
        The scaled problem data.
    blocks : tuple of int
        Hold the move over groups of stages (``v = T b``, :func:`blocking_matrix`), so a
        horizon that covers a whole manoeuvre keeps few variables; empty: every move free.
    stride : int
        Keep the soft rows of every ``stride``-th predicted state only (the last one always).

    Returns
    -------
    QP
    """
    n, m, ns, N = pb.n, pb.m, pb.ns, pb.horizon
    Phi, Gam = prediction_matrices(pb)
    Hv, Gam, starts, block_of = _condensed_moves(pb, Gam, blocks)
    nv = Hv.shape[0]
    Fv = Gam.T @ _stage_cost(pb) @ Phi
    steps = (
        np.arange(N) if stride == 1 else np.unique(np.r_[np.arange(stride - 1, N, stride), N - 1])
    )
    S = steps.size
    nsl = S * ns
    nw = nv + nsl
    H = np.zeros((nw, nw))
    H[:nv, :nv] = 0.5 * (Hv + Hv.T)
    H[nv:, nv:] = pb.l2 * np.eye(nsl)
    A, lba0, uba0, Lz = _condensed_soft_rows(pb, Gam, Phi, steps, nw)
    moves = (block_of[:, None] * m + np.arange(m)[None, :]).astype(int)
    shifted = not blocks and stride == 1
    shift_w, shift_a = _condensed_shifts(pb, nv, nsl, A.shape[0], shifted)
    Ar, lr, ur, rows, shift_r = rate_rows(pb, moves, nw, A.shape[0], shifted)
    if Lz is not None:
        Lz = np.vstack([Lz, np.zeros((Ar.shape[0], n))])
    soft = np.array(
        [np.r_[k * ns + np.arange(ns), nsl + k * ns + np.arange(ns)] for k in range(S)], dtype=int
    ).reshape(S, 2 * ns)
    return QP(
        H=sp.csc_matrix(H),
        g0=np.r_[np.zeros(nv), np.full(nsl, pb.l1)],
        A=sp.vstack([sp.csc_matrix(A), Ar], format="csc"),
        lba0=np.r_[lba0, lr],
        uba0=np.r_[uba0, ur],
        lbx=np.r_[np.tile(pb.v_lo, nv // m), np.zeros(nsl)],
        ubx=np.r_[
            np.tile(pb.v_hi, nv // m),
            np.tile(np.where(pb.hard, 0.0, np.inf), S)
            if pb.hard is not None
            else np.full(nsl, np.inf),
        ],
        Gz=np.vstack([Fv, np.zeros((nsl, n))]),
        Lz=Lz,
        ix0=np.zeros(0, int),
        first_move=moves[0],
        moves=moves,
        slack=nv + np.arange(nsl),
        shift_w=shift_w,
        shift_a=np.r_[shift_a, shift_r].astype(int),
        stages={},
        n_state=n,
        soft_rows=soft,
        soft_steps=None if stride == 1 else steps,
        block_starts=starts,
        n_arrival=pb.n_arrival,
        rate_rows=rows,
    )


__all__ = [
    "QP",
    "sparse_qp",
    "prediction_matrices",
    "blocking_matrix",
    "condensed_qp",
]
