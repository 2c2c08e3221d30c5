"""HPIPM called directly (ctypes) on an input-bounded optimal-control QP, its memory made once.

The problem, ``N`` stages, ``x_0`` given (``k = 0..N``, no ``u_N``)::

    min  sum_k 1/2 u_k' R_k u_k + x_k' S_k' u_k + 1/2 x_k' Q_k x_k + r_k' u_k + q_k' x_k
    s.t. x_{k+1} = A_k x_k + B_k u_k + b_k,   lbu <= u_k <= ubu

Why not ``casadi.conic("hpipm")``: every call of it allocates and creates HPIPM's dimensions,
QP, solution, arguments and workspace anew, projects the sparse constraint matrix and Hessian
into stage blocks, and boxes every state with bounds of +-1e8 (CasADi gives HPIPM all
variables as boxed), so HPIPM's interior point carries ``2 (N + 1) n_x`` inequalities that
never bind.  Here the structures are made once per solver, ``x_0`` is eliminated (stage 0 has
no state: ``b_0 <- A_0 x_0 + b_0``, ``r_0 <- r_0 + S_0 x_0``), only the inputs are bounded,
and one solve is three C calls (set the data, set the primal start, solve) plus two for the
status, on numpy arrays bound once.

The library is the ``libhpipm`` that ships with CasADi (the one ``casadi.conic`` loads), with
the same options (mode, iteration limit, the four residual tolerances, primal warm start).
Like CasADi, the cost is handed to HPIPM halved (``1/2 H``, ``1/2 g``: the same minimizer), so
the residual tolerances mean what they mean through ``casadi.conic``.  The two are the same
optimum to the interior point's tolerance, not to the bit (other inequalities, so other
iterates).
"""

from __future__ import annotations

import ctypes
import functools
import glob
import os

import casadi
import numpy as np

#: HPIPM's ``enum hpipm_mode``
MODES = {"speed_abs": 0, "speed": 1, "balance": 2, "robust": 3}
#: HPIPM's ``enum hpipm_status``
STATUS = {0: "SUCCESS", 1: "MAX_ITER", 2: "MIN_STEP", 3: "NAN_SOL", 4: "INCONS_EQ"}
#: the ``hpipm`` options of :func:`~flexctrl.control.nmpc.screened_qp.hpipm_options` and their
#: HPIPM setters
_TOLERANCES = {
    "res_g_max": "tol_stat",
    "res_b_max": "tol_eq",
    "res_d_max": "tol_ineq",
    "res_m_max": "tol_comp",
}


class HpipmUnavailable(RuntimeError):
    """HPIPM's shared library could not be found or loaded next to CasADi."""


@functools.lru_cache(maxsize=1)
def library() -> ctypes.CDLL:
    """CasADi's ``libhpipm`` (loaded once; its ``libblasfeo`` sits beside it).

    Raises
    ------
    HpipmUnavailable
        No loadable ``libhpipm`` in CasADi's package folder.
    """
    folder = os.path.dirname(casadi.__file__)
    names = sorted(
        glob.glob(os.path.join(folder, "libhpipm.*")) + glob.glob(os.path.join(folder, "hpipm.dll"))
    )
    errors = []
    for name in names:
        try:
            lib = ctypes.CDLL(name)
        except OSError as exc:
            errors.append(f"{name}: {exc}")
            continue
        for fn in (
            "d_ocp_qp_ipm_solve",
            "d_ocp_qp_set_all",
            "d_ocp_qp_sol_get_all",
            "d_ocp_qp_ipm_get_status",
        ):
            getattr(lib, fn).restype = None
        for fn in (
            "d_ocp_qp_dim_strsize",
            "d_ocp_qp_dim_memsize",
            "d_ocp_qp_strsize",
            "d_ocp_qp_memsize",
            "d_ocp_qp_sol_strsize",
            "d_ocp_qp_sol_memsize",
            "d_ocp_qp_ipm_arg_strsize",
            "d_ocp_qp_ipm_arg_memsize",
            "d_ocp_qp_ipm_ws_strsize",
            "d_ocp_qp_ipm_ws_memsize",
        ):
            getattr(lib, fn).restype = ctypes.c_size_t
        return lib
    raise HpipmUnavailable(
        f"no loadable libhpipm in CasADi's folder {folder!r}"
        + (f" ({'; '.join(errors)})" if errors else "")
    )


def _pointers(array: np.ndarray, sizes: list[int]) -> ctypes.Array:
    """A C array of pointers to consecutive blocks of ``sizes`` entries of ``array``.

    ``array`` is contiguous.
    """
    base, step = array.ctypes.data, array.itemsize
    offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(int)
    return (ctypes.c_void_p * len(sizes))(*[base + int(o) * step for o in offsets])


def _checked_mode(options: dict) -> str:
    """HPIPM's mode, after the options are checked against those interfaced."""
    unknown = set(options) - {"mode", "iter_max", "warm_start", *_TOLERANCES}
    if unknown:
        raise ValueError(
            f"HPIPM options {sorted(unknown)} are not interfaced; allowed: "
            f"{sorted({'mode', 'iter_max', 'warm_start', *_TOLERANCES})}"
        )
    mode = options.get("mode", "speed")
    if mode not in MODES:
        raise ValueError(f"HPIPM mode {mode!r} is not allowed; allowed: {sorted(MODES)}")
    return mode


class HpipmOCP:
    """HPIPM on the problem of the module docstring; one per controller.

    Not picklable and not thread-safe: its memory is HPIPM's.

    Parameters
    ----------
    N, nx, nu : int
        Stages, states and inputs per stage.
    options : dict
        ``{"mode", "iter_max", "res_g_max", "res_b_max", "res_d_max", "res_m_max", "warm_start"}``
        as for ``casadi.conic``'s HPIPM (:func:`~flexctrl.control.nmpc.screened_qp.hpipm_options`);
        ``warm_start`` 1 starts from the primal guess given to :meth:`solve`.

    The data are written into :attr:`A`, :attr:`B`, :attr:`b`, :attr:`Q`, :attr:`S`, :attr:`R`,
    :attr:`q`, :attr:`r`, :attr:`lbu`, :attr:`ubu` (numpy arrays bound to HPIPM's pointers; each
    stage's matrix as its transpose in C order, which is HPIPM's column-major block) before
    :meth:`solve`, the cost already halved or not as the caller chooses.
    """

    def __init__(self, N: int, nx: int, nu: int, options: dict):
        lib = library()
        self.lib, self.N, self.nx, self.nu = lib, N, nx, nu
        mode = _checked_mode(options)
        self._mem: list = []  # every buffer HPIPM points into, kept alive with the solver
        self._create_structures(mode, options)
        self._bind_data()

    def _struct(self, name: str) -> ctypes.Array:
        memory = ctypes.create_string_buffer(int(getattr(self.lib, f"{name}_strsize")()))
        self._mem.append(memory)
        return memory

    def _memory(self, size: int) -> ctypes.c_void_p:
        block = ctypes.create_string_buffer(int(size) + 64)
        self._mem.append(block)
        return ctypes.c_void_p((ctypes.addressof(block) + 63) // 64 * 64)  # aligned as HPIPM asks

    def _create_structures(self, mode: str, options: dict) -> None:
        """HPIPM's dimensions, QP, solution, solver arguments and workspace."""
        lib, N, nx, nu = self.lib, self.N, self.nx, self.nu
        # stage sizes: stage 0 has no state (x_0 eliminated), the last no input
        nxs = np.array([0] + [nx] * N, dtype=np.int32)
        nus = np.array([nu] * N + [0], dtype=np.int32)
        zeros = np.zeros(N + 1, dtype=np.int32)
        self._ints = (nxs, nus, zeros)
        self._dim = self._struct("d_ocp_qp_dim")
        lib.d_ocp_qp_dim_create(N, self._dim, self._memory(lib.d_ocp_qp_dim_memsize(N)))

        def ptr(a):
            return a.ctypes.data_as(ctypes.c_void_p)

        # nx, nu, nbx, nbu, ng, ns
        lib.d_ocp_qp_dim_set_all(
            ptr(nxs), ptr(nus), ptr(zeros), ptr(nus), ptr(zeros), ptr(zeros), self._dim
        )
        self._qp = self._struct("d_ocp_qp")
        lib.d_ocp_qp_create(self._dim, self._qp, self._memory(lib.d_ocp_qp_memsize(self._dim)))
        self._sol = self._struct("d_ocp_qp_sol")
        lib.d_ocp_qp_sol_create(
            self._dim, self._sol, self._memory(lib.d_ocp_qp_sol_memsize(self._dim))
        )
        self._arg = self._struct("d_ocp_qp_ipm_arg")
        lib.d_ocp_qp_ipm_arg_create(
            self._dim, self._arg, self._memory(lib.d_ocp_qp_ipm_arg_memsize(self._dim))
        )
        lib.d_ocp_qp_ipm_arg_set_default(MODES[mode], self._arg)
        if "iter_max" in options:
            lib.d_ocp_qp_ipm_arg_set_iter_max(
                ctypes.byref(ctypes.c_int(int(options["iter_max"]))), self._arg
            )
        for key, setter in _TOLERANCES.items():
            if key in options:
                getattr(lib, f"d_ocp_qp_ipm_arg_set_{setter}")(
                    ctypes.byref(ctypes.c_double(float(options[key]))), self._arg
                )
        lib.d_ocp_qp_ipm_arg_set_warm_start(
            ctypes.byref(ctypes.c_int(int(options.get("warm_start", 0)))), self._arg
        )
        self._ws = self._struct("d_ocp_qp_ipm_ws")
        lib.d_ocp_qp_ipm_ws_create(
            self._dim,
            self._arg,
            self._ws,
            self._memory(lib.d_ocp_qp_ipm_ws_memsize(self._dim, self._arg)),
        )

    def _bind_data(self) -> None:
        """The data and solution arrays, and the pointer lists HPIPM reads them through."""
        N, nx, nu = self.N, self.nx, self.nu
        # HPIPM's column-major blocks: a stage's (rows, cols) matrix is a C-ordered (cols, rows)
        # array
        self.A = np.zeros((N, nx, nx))  # stage 0's A has no columns (x_0 eliminated): A[0] unused
        self.B = np.zeros((N, nu, nx))
        self.b = np.zeros((N, nx))
        self.Q = np.zeros((N + 1, nx, nx))  # Q[0] unused
        self.S = np.zeros((N + 1, nx, nu))  # S_k (nu x nx) as (nx, nu); S[0] unused
        self.R = np.zeros((N + 1, nu, nu))  # R[N] unused
        self.q = np.zeros((N + 1, nx))
        self.r = np.zeros((N + 1, nu))
        self.lbu = np.zeros((N + 1, nu))
        self.ubu = np.zeros((N + 1, nu))
        self.u = np.zeros((N + 1, nu))  # primal start, then the solution
        self.x = np.zeros((N + 1, nx))  # x[0] unused
        idxbu = np.tile(np.arange(nu, dtype=np.int32), N + 1)
        spare = np.zeros(1)  # what the fields of size 0 point at (never read or written)
        no_slack = np.full((N + 1) * nu, -1, dtype=np.int32)  # idxs_rev: no constraint has a slack
        multipliers = np.zeros(2 * (N + 1) * (nx + nu) + N * nx)
        self._keep = (idxbu, spare, no_slack, multipliers)
        P = _pointers
        none = P(spare, [0] * (N + 1))  # fields of size 0 (no state bounds, general rows, slacks)
        # stage 0's A, S, Q and x blocks exist but are never read: HPIPM takes nx[0] = 0 columns
        # of them
        self._set_all = (
            P(self.A, [nx * nx] * N),
            P(self.B, [nu * nx] * N),
            P(self.b, [nx] * N),
            P(self.Q, [nx * nx] * (N + 1)),
            P(self.S, [nx * nu] * (N + 1)),
            P(self.R, [nu * nu] * (N + 1)),
            P(self.q, [nx] * (N + 1)),
            P(self.r, [nu] * (N + 1)),
            none,
            none,
            none,
            P(idxbu, [nu] * (N + 1)),
            P(self.lbu, [nu] * (N + 1)),
            P(self.ubu, [nu] * (N + 1)),
            *[none] * 9,
            P(no_slack, [nu] * (N + 1)),
            none,
            none,
            self._qp,
        )
        # u, x, ls, us, pi, lam_lb, lam_ub, lam_lg, lam_ug, lam_ls, lam_us
        self._sol_all = (
            P(self.u, [nu] * (N + 1)),
            P(self.x, [nx] * (N + 1)),
            none,
            none,
            P(multipliers, [nx] * N),
            P(multipliers[N * nx :], [nu] * (N + 1)),
            P(multipliers[N * nx + (N + 1) * nu :], [nu] * (N + 1)),
            *[none] * 4,
        )
        self._status, self._iter = ctypes.c_int(-1), ctypes.c_int(-1)

    def solve(self) -> dict:
        """Solve on the data in the bound arrays from the primal start in :attr:`u`, :attr:`x`; the
        solution replaces them.

        Returns
        -------
        dict
            ``success`` (HPIPM's status is SUCCESS), ``return_status`` (its name) and
            ``iter_count``, the keys of ``casadi.conic``'s statistics that the NMPC reads.
        """
        lib = self.lib
        lib.d_ocp_qp_set_all(*self._set_all)
        lib.d_ocp_qp_sol_set_all(*self._sol_all, self._sol)
        lib.d_ocp_qp_ipm_solve(self._qp, self._sol, self._arg, self._ws)
        lib.d_ocp_qp_sol_get_all(self._sol, *self._sol_all)
        lib.d_ocp_qp_ipm_get_status(self._ws, ctypes.byref(self._status))
        lib.d_ocp_qp_ipm_get_iter(self._ws, ctypes.byref(self._iter))
        status = int(self._status.value)
        return {
            "success": status == 0,
            "return_status": STATUS.get(status, f"status {status}"),
            "iter_count": int(self._iter.value),
        }


__all__ = ["HpipmOCP", "HpipmUnavailable", "library", "MODES", "STATUS"]
