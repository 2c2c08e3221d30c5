"""A designed controller as a self-contained C library for a real-time target.

:func:`export_c` (``ctrl.export_c(DIR)``) writes a folder that builds with the system C
compiler and nothing else: the controller's law in C, a header with the measurement and
torque order and units, the reference table, a ``Makefile`` and a harness that replays a
closed loop recorded in Python (:class:`StepRecorder`) and compares the torques
(``make -C DIR check``).  By kind:

- LQR, LQG (:mod:`~flexctrl.control.cexport.law`): CasADi's code generation of the
  controller's own law and estimator; agrees with Python to round-off.
- linear MPC (:mod:`~flexctrl.control.cexport.mpc_dense`): the condensed QP solved by a
  small dense ADMM written for its structure, at a tolerance of its own; agrees with
  Python's OSQP to the QP's tolerance.

Everything here works on the designed controller alone (its law, estimator, QP and
reference), which is why it lives in the control layer beside the controllers: recording a
closed loop is the caller's (``flexctrl export`` runs the scene's).
"""

from __future__ import annotations

from pathlib import Path

from flexctrl.control.cexport.library import Export, write_library
from flexctrl.control.cexport.replay import Replay, StepRecorder, write_replay
from flexctrl.errors import SpecError

#: What :func:`export_c` exports, by controller kind.
KINDS = ("lqr", "mpc")


def export_c(
    ctrl,
    out,
    *,
    replay: Replay | None = None,
    qp_eps: float | None = None,
    info: dict | None = None,
) -> Export:
    """Write ``ctrl`` as a C library into the folder ``out`` (see the module docstring).

    Parameters
    ----------
    ctrl : flexctrl.control.controller.Controller
        An LQR/LQG without a gain schedule, or a linear MPC.
    out : str or path-like
        The folder (created; the files of an earlier export are overwritten).
    replay : Replay, optional
        Steps of ``ctrl`` recorded in a closed loop (:meth:`StepRecorder.replay`), written
        as ``replay.csv`` for ``make check``.  Without it there is nothing to check.
    qp_eps : float, optional
        The linear MPC's absolute and relative QP tolerance in C; default 1/100 of the
        controller's OSQP ``eps_abs``.  Other kinds take none.
    info : dict, optional
        ``controller`` and ``design`` strings for the header (default from ``ctrl``).

    Returns
    -------
    Export

    Raises
    ------
    SpecError
        For a kind or an option that has no C export.
    """
    kind = getattr(ctrl, "kind", "")
    if kind not in KINDS:
        raise SpecError(
            f"value {kind or type(ctrl).__name__!r} has no C export; allowed: "
            "an LQR/LQG without a gain schedule, or a linear MPC ('lqr', 'mpc')",
            key="kind",
        )
    if qp_eps is not None and kind != "mpc":
        raise SpecError(
            f"value {qp_eps!r} is not allowed for a '{kind}' controller; allowed: only for "
            "the linear MPC",
            key="qp_eps",
        )
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    if kind == "lqr":
        from flexctrl.control.cexport.law import plan_law

        plan = plan_law(ctrl, folder)
    else:
        from flexctrl.control.cexport.mpc_dense import plan_mpc

        plan = plan_mpc(ctrl, folder, qp_eps, replay)
    if replay is not None:
        write_replay(replay, folder / "replay.csv", ctrl.sensors.names)
    return write_library(
        folder, ctrl, plan, _info(ctrl, info), 0 if replay is None else replay.samples
    )


def _info(ctrl, info: dict | None) -> dict:
    import numpy as np

    model = ctrl.design_model
    design = (
        "a model"
        if model is None
        else f"{model.name} ({model.fidelity}), payload {model.spec.payload.mass:g} kg"
    )
    states = " ".join(getattr(model, "coordinate_names", ()))
    base = {
        "controller": ctrl.kind,
        "design": f"{design}, at {np.degrees(ctrl.op.joints).round(4).tolist()} deg",
        "states": f"{states} and their rates" if states else "(see the design model)",
    }
    return {**base, **(info or {})}


__all__ = ["KINDS", "Export", "Replay", "StepRecorder", "export_c"]
