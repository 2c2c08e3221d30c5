"""A symbolic LDL^T solve of a small symmetric positive definite system (mass matrices).

``M qdd = rhs`` solved by an explicit LDL^T factorisation written out entry by entry:
no square roots, no pivoting, structural zeros skipped.  For the sizes of an assumed-modes
arm it generates smaller and faster code than ``casadi.solve`` (a symbolic QR).
"""

from __future__ import annotations

from typing import Any

import casadi as ca


def _dot(row_a: list[Any], row_l: list[Any], stop: int) -> Any:
    """``sum_m row_a[m] row_l[m]`` over ``m < stop``, skipping structural zeros (None)."""
    terms = [
        row_a[m] * row_l[m] for m in range(stop) if row_a[m] is not None and row_l[m] is not None
    ]
    return sum(terms[1:], terms[0]) if terms else None


def _minus(x: Any, y: Any) -> Any:
    """``x - y`` with None for a structural zero."""
    if y is None:
        return x
    return -y if x is None else x - y


def ldl_solve(A: Any, b: Any) -> Any:
    """Solve ``A x = b`` for symmetric positive definite ``A`` by an explicit LDL^T (symbolic).

    Structural zeros of ``A`` are skipped.  No pivoting: only for matrices known to be
    positive definite (mass matrices).  One division per pivot.

    Parameters
    ----------
    A : casadi.SX or casadi.MX
        Square, symmetric positive definite (only the lower triangle is read).
    b : casadi.SX or casadi.MX
        Right-hand side, a column.

    Returns
    -------
    casadi.SX or casadi.MX
        The column ``x``.
    """
    n = A.shape[0]
    if n == 0:
        return type(A).zeros(0, 1)
    L: list[list[Any]] = [[None] * n for _ in range(n)]  # unit lower factor
    a: list[list[Any]] = [[None] * n for _ in range(n)]  # a[j][k] = L[j][k] d[k]
    inv_d: list[Any] = [None] * n
    for j in range(n):
        for k in range(j):
            s = _minus(None if A[j, k].is_zero() else A[j, k], _dot(a[j], L[k], k))
            if s is not None:
                a[j][k], L[j][k] = s, s * inv_d[k]
        inv_d[j] = 1 / _minus(A[j, j], _dot(a[j], L[j], j))
    y: list[Any] = [None] * n
    for i in range(n):  # L y = b
        s = b[i]
        for k in range(i):
            if L[i][k] is not None:
                s = s - L[i][k] * y[k]
        y[i] = s
    x: list[Any] = [None] * n
    for i in reversed(range(n)):  # L^T x = D^-1 y
        s = y[i] * inv_d[i]
        for k in range(i + 1, n):
            if L[k][i] is not None:
                s = s - L[k][i] * x[k]
        x[i] = s
    return ca.vertcat(*x)
