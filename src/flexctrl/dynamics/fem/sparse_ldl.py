"""Symbolic sparse ``LDL^T`` solve for CasADi SX matrices with a chosen elimination order.

Used for the forward dynamics of the finite-element arm, whose mass matrix has
an arrowhead structure: the interior nodes of each link couple to their
neighbours (band) and to a small border (joint coordinates and link-tip dofs)
only.  Eliminating interior dofs first and the border last keeps the fill-in in
the band and the border, so the generated expression grows linearly with the
number of elements instead of cubically.

The factorisation is up-looking: row ``j`` of ``L`` is formed from the nonzeros of
``A[j, :j]`` plus the fill reached through earlier rows (a heap keeps the columns in
order).  No pivoting and no square roots -- only for matrices known to be
symmetric positive definite (mass matrices).
"""

from __future__ import annotations

import heapq
from collections.abc import Sequence

import casadi as ca


def _entries(A: ca.SX, order: Sequence[int]) -> list[dict[int, ca.SX]]:
    """Lower-triangle nonzeros of ``A[order, order]``, row by row, skipping exact zeros."""
    pos = {old: new for new, old in enumerate(order)}
    rows: list[dict[int, ca.SX]] = [dict() for _ in order]
    sp = A.sparsity()
    colind, row = sp.colind(), sp.row()
    for c in range(A.shape[1]):
        for k in range(colind[c], colind[c + 1]):
            r = row[k]
            i, j = pos[r], pos[c]
            if j > i:
                continue
            value = A.nz[k]
            if value.is_zero():
                continue
            rows[i][j] = value
    return rows


def ldl_solve_sparse(A: ca.SX, b: ca.SX, order: Sequence[int] | None = None) -> ca.SX:
    """Solve ``A x = b`` symbolically for symmetric positive definite ``A`` (SX).

    Parameters
    ----------
    A
        Symmetric ``(n, n)`` SX matrix; only its lower triangle (in the permuted
        order) is read.
    b
        ``(n, 1)`` right-hand side.
    order
        Elimination order (a permutation of ``range(n)``); default the natural order.

    Returns
    -------
    casadi.SX
        ``(n, 1)`` solution in the original ordering.
    """
    n = A.shape[0]
    order = list(range(n)) if order is None else [int(k) for k in order]
    if sorted(order) != list(range(n)):
        raise ValueError("order must be a permutation of range(n)")
    rows = _entries(A, order)
    L: list[dict[int, ca.SX]] = [dict() for _ in range(n)]
    below: list[list[int]] = [[] for _ in range(n)]  # below[k]: rows j > k with L[j][k] != 0
    inv_d: list[ca.SX] = [None] * n  # type: ignore[list-item]
    for j in range(n):
        a: dict[int, ca.SX] = {}  # a[k] = L[j][k] d[k]
        heap = [k for k in rows[j] if k < j]
        heapq.heapify(heap)
        done: set[int] = set()
        while heap:
            k = heapq.heappop(heap)
            if k in done:
                continue
            done.add(k)
            Lk = L[k]
            terms = [a[m] * Lk[m] for m in (a if len(a) < len(Lk) else Lk) if m in a and m in Lk]
            s = rows[j].get(k)
            for t in terms:
                s = -t if s is None else s - t
            if s is None:
                continue
            a[k] = s
            L[j][k] = s * inv_d[k]
            for m in below[k]:
                if m < j and m not in done:
                    heapq.heappush(heap, m)
        d = rows[j].get(j)
        if d is None:
            raise ValueError(f"structurally zero pivot at position {j} (order index {order[j]})")
        for k, ak in a.items():
            d = d - ak * L[j][k]
        inv_d[j] = 1 / d
        for k in L[j]:
            below[k].append(j)
    bp = [b[i] for i in order]
    y: list[ca.SX] = []
    for i in range(n):  # L y = b
        s = bp[i]
        for k, lik in L[i].items():
            s = s - lik * y[k]
        y.append(s)
    x: list[ca.SX] = [None] * n  # type: ignore[list-item]
    for i in reversed(range(n)):  # L^T x = D^-1 y
        s = y[i] * inv_d[i]
        for j in below[i]:
            s = s - L[j][i] * x[j]
        x[i] = s
    out: list[ca.SX] = [None] * n  # type: ignore[list-item]
    for new, old in enumerate(order):
        out[old] = x[new]
    return ca.vertcat(*out)
