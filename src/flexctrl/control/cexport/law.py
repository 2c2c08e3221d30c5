"""The LQR and LQG in C: CasADi's code generation of the controller's own law.

The law is :meth:`LQRController.law_function`, the function of the compiled closed loop's
:class:`~flexctrl.control.controller.SampledLaw`, and its first-sample form (the Kalman
filter starts from the least-squares fit ``C^+ (y - y_op - D du)``)::

    u = u_ref - K (x_hat - x_ref)         clipped to the torque limits in C

so C does the floating-point operations of ``ctrl.step`` up to the order of the sums in
the matrix products (numpy's BLAS against CasADi's loops): the torques agree to round-off.
"""

from __future__ import annotations

from pathlib import Path

from flexctrl.control.cexport.c_code import generate, template
from flexctrl.control.cexport.library import Export, Plan, export_folder, no_option, write_library


def export_law(ctrl, out, replay=None, qp_eps=None) -> Export:
    """Write the LQR/LQG ``ctrl`` as a C library into ``out`` (:meth:`Controller.export_c`).

    Parameters
    ----------
    ctrl : LQRController
        Without a gain schedule.
    out : str or path-like
        The folder.
    replay : Replay, optional
        Its recorded steps, for ``make check``.
    qp_eps : None
        Only the linear MPC takes a QP tolerance.

    Returns
    -------
    Export
    """
    no_option(ctrl, qp_eps)
    folder = export_folder(out)
    return write_library(folder, ctrl, plan_law(ctrl, folder), replay)


def plan_law(ctrl, out: Path) -> Plan:
    """Write the law's C sources into ``out``; the plan for :func:`write_library`."""
    functions = [ctrl.law_function(start=True), ctrl.law_function(start=False)]
    renamed = [
        _renamed(f, name) for f, name in zip(functions, ("flexctrl_law_start", "flexctrl_law"))
    ]
    sizes = generate(renamed, out, "flexctrl_law")
    (out / "law.c").write_text(template("law.c"))
    n_xi = int(renamed[1].size1_in(0))
    defines = {"FLEXCTRL_N_XI": str(n_xi)} | {
        f"FLEXCTRL_LAW_SZ_{key.upper()}": str(value) for key, value in sizes.items()
    }
    members = (
        "  double xi[FLEXCTRL_N_XI + 1];          /* the estimator memory (deviation estimate) */\n"
        "  long long iw[FLEXCTRL_LAW_SZ_IW + 1];  /* work arrays of the generated code */\n"
        "  double w[FLEXCTRL_LAW_SZ_W + 1];"
    )
    estimator = "a steady-state Kalman filter" if n_xi else "the measured full state"
    law = (
        f"Law: u = u_ref - K (x_hat - x_ref), x_hat from {estimator} on the design model's\n"
        " * zero-order-hold discretisation; K, the filter gains and the operating point are\n"
        " * constants of flexctrl_law.c (CasADi's code generation of the controller's law)."
    )
    return Plan(
        route="law",
        sources=["flexctrl_law.c", "law.c"],
        members=members,
        defines=defines,
        law=law,
        check_rel=1e-9,
        check_doc="every torque within 1e-9 of the joint's largest |torque| in the run",
        notes={"law_work_sizes": sizes, "estimator_memory": n_xi},
    )


def _renamed(function, name: str):
    """``function`` under the C name ``name`` (same inputs and outputs)."""
    import casadi as ca

    args = function.mx_in()
    return ca.Function(name, args, function(*args), function.name_in(), function.name_out())


__all__ = ["export_law", "plan_law"]
