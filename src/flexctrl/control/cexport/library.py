"""The parts of a C library every exported controller has: header, data, Makefile, harness.

Each kind of controller (:mod:`~flexctrl.control.cexport.law`,
:mod:`~flexctrl.control.cexport.mpc_dense`) writes its sources and returns a :class:`Plan`;
:func:`write_library` writes the rest of the folder around it:

``flexctrl_controller.h``  the API; sizes; measurement order and units; torque order, units, limits
``flexctrl_data.c``        constants: names, units, limits, operating point, reference table
``harness.c``, ``harness_check.h``  the replay of a recorded closed loop and its bound
``Makefile``               ``make`` (library + harness), ``make check``, ``make clean``; ``cc`` only
``export.json``            what was exported
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from flexctrl.control.cexport.c_code import c_array, c_double, template, unit_of
from flexctrl.control.cexport.replay import write_replay
from flexctrl.errors import SpecError


@dataclass
class Plan:
    """What one kind of controller adds to the library.

    Attributes
    ----------
    route : str
        ``"law"`` (generated fixed law) or ``"mpc_dense"`` (own QP solver).
    sources : list of str
        Its C files in the folder.
    members : str
        C members of ``struct flexctrl_controller`` (its mutable state).
    defines : dict
        More ``#define`` lines of the header.
    law : str
        What the law is, for the header's comment.
    ref_window : int
        Reference rows one step reads (the MPC: horizon + 1).
    check_rel : float
        The harness's bound, relative to each joint's largest torque.
    check_abs : ndarray, optional
        And absolute per joint, N m.
    check_doc : str
        The bound in words.
    data : str
        More C definitions for ``flexctrl_data.c``.
    declarations : str
        Their declarations for the header.
    notes : dict
        Figures for ``export.json``.
    """

    route: str
    sources: list[str]
    members: str
    defines: dict[str, str] = field(default_factory=dict)
    law: str = ""
    ref_window: int = 1
    check_rel: float = 1e-9
    check_abs: np.ndarray | None = None
    check_doc: str = ""
    data: str = ""
    declarations: str = ""
    notes: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Export:
    """A written C library (the value of :meth:`Controller.export_c`).

    Attributes
    ----------
    folder : Path
        Where it is: ``make -C folder check`` builds and checks it.
    files : tuple of str
        The files written.
    route : str
        How the law is computed in C (``"law"``, ``"mpc_dense"``).
    samples : int
        Samples in ``replay.csv`` (0: nothing to check against).
    check : str
        The bound ``make check`` holds the C torques to.
    """

    folder: Path
    files: tuple[str, ...]
    route: str
    samples: int
    check: str


def reference_table(ctrl) -> tuple[np.ndarray, np.ndarray]:
    """``(X (T, n_x), U (T, n_u))``: the controller's reference on its sample grid, as it reads it.

    The rows ``0 .. T-1`` up to the end of the move and one past it (later rows repeat the
    last, the target at rest): the values ``reference.window`` gives the controller.
    """
    ref, Ts = ctrl.reference, ctrl.sample_time
    rows = int(math.ceil(ref.t_arrive / Ts - 1e-9)) + 2
    X, U, _ = ref.window(0.0, Ts, rows)
    return np.array(X, dtype=float), np.array(U, dtype=float)


def _comment_lines(ctrl, info: dict) -> tuple[str, str]:
    names = list(ctrl.sensors.names)
    meas = "\n".join(f" *   y[{i}] {n:<10s} {unit_of(n)}" for i, n in enumerate(names))
    limits = ctrl.limits
    torques = "\n".join(
        f" *   u[{i}] tau{i + 1}       N m, limit +-{limits[i]:g}" for i in range(ctrl.n_u)
    )
    return meas, torques


def header_text(ctrl, plan: Plan, info: dict) -> str:
    """The text of ``flexctrl_controller.h``."""
    meas, torques = _comment_lines(ctrl, info)
    defines = {
        "FLEXCTRL_N_Y": str(ctrl.sensors.n_y),
        "FLEXCTRL_N_U": str(ctrl.n_u),
        "FLEXCTRL_N_X": str(ctrl.op.x.size),
        "FLEXCTRL_SAMPLE_TIME": c_double(ctrl.sample_time),
        "FLEXCTRL_REF_ROWS": str(info["ref_rows"]),
        "FLEXCTRL_REF_WINDOW": str(plan.ref_window),
        "FLEXCTRL_SATURATE": "1" if ctrl.saturate else "0",
        **plan.defines,
    }
    define_lines = "\n".join(f"#define {k} {v}" for k, v in defines.items())
    return template("header.h").format(
        controller=info["controller"],
        route=plan.route,
        design=info["design"],
        recorded=info["recorded"],
        measurements=meas,
        torques=torques,
        states=info["states"],
        law=plan.law,
        defines=define_lines,
        declarations=plan.declarations,
        members=plan.members,
    )


def data_text(ctrl, table_x: np.ndarray, table_u: np.ndarray, plan: Plan) -> str:
    """The text of ``flexctrl_data.c``."""
    names = list(ctrl.sensors.names)
    quoted = ", ".join(f'"{n}"' for n in names)
    units = ", ".join(f'"{unit_of(n)}"' for n in names)
    return (
        "/* flexctrl_data.c -- the exported controller's constants (generated). */\n"
        '#include <math.h>\n#include "flexctrl_controller.h"\n\n'
        f"const char *const flexctrl_measurement_names[FLEXCTRL_N_Y] = {{{quoted}}};\n"
        f"const char *const flexctrl_measurement_units[FLEXCTRL_N_Y] = {{{units}}};\n"
        + c_array("flexctrl_torque_limits", ctrl.limits)
        + c_array("flexctrl_op_x", ctrl.op.x)
        + c_array("flexctrl_op_u", ctrl.op.u)
        + c_array("flexctrl_ref_x", table_x)
        + c_array("flexctrl_ref_u", table_u)
        + plan.data
        + template("reference_window.c")
    )


def check_text(plan: Plan, n_u: int) -> str:
    """The text of ``harness_check.h``: the bound the harness holds the torques to."""
    check_abs = np.zeros(n_u) if plan.check_abs is None else np.asarray(plan.check_abs)
    doc = plan.check_doc.replace('"', "'")
    return (
        "/* harness_check.h -- the bound of make check (generated). */\n"
        f"#define CHECK_REL {c_double(plan.check_rel)}\n"
        "#define EXACT_FACTOR 1.1\n"
        f'#define CHECK_DOC "{doc}"\n' + c_array("check_abs", check_abs, static=True)
    )


def export_folder(out) -> Path:
    """The folder ``out``, created."""
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def no_option(ctrl, qp_eps) -> None:
    """:class:`SpecError` for a QP tolerance given to a controller without a QP."""
    if qp_eps is not None:
        raise SpecError(
            f"value {qp_eps!r} is not allowed for a '{ctrl.kind}' controller; allowed: only "
            "for the linear MPC",
            key="qp_eps",
        )


def design_info(ctrl, replay) -> dict:
    """What the header says the controller was designed on and the replay recorded from."""
    model = ctrl.design_model
    where = (
        "a model"
        if model is None
        else (f"{model.name} ({model.fidelity}), payload {model.spec.payload.mass:g} kg")
    )
    names = tuple(getattr(model, "coordinate_names", ()))
    return {
        "controller": ctrl.kind,
        "design": f"{where}, at {np.degrees(ctrl.op.joints).round(4).tolist()} deg",
        "states": " ".join(names) + " and their rates" if names else "(the design model's)",
        "recorded": "nothing (no replay.csv)" if replay is None else replay.source or "Python",
    }


def write_library(out: Path, ctrl, plan: Plan, replay=None) -> Export:
    """Write the generic files around ``plan`` (whose sources are already in ``out``).

    Parameters
    ----------
    out : Path
        The folder.
    ctrl : Controller
        The exported controller.
    plan : Plan
        Its kind's part.
    replay : Replay, optional
        Written as ``replay.csv`` for the harness.

    Returns
    -------
    Export
    """
    if replay is not None:
        write_replay(replay, out / "replay.csv", ctrl.sensors.names)
    samples = 0 if replay is None else replay.samples
    table_x, table_u = reference_table(ctrl)
    info = {**design_info(ctrl, replay), "ref_rows": int(table_x.shape[0])}
    texts = {
        "flexctrl_controller.h": header_text(ctrl, plan, info),
        "flexctrl_data.c": data_text(ctrl, table_x, table_u, plan),
        "harness_check.h": check_text(plan, ctrl.n_u),
        "harness.c": template("harness.c"),
        "Makefile": template("Makefile").replace("@SOURCES@", " ".join(plan.sources)),
    }
    for name, text in texts.items():
        (out / name).write_text(text)
    meta = {
        **info,
        "route": plan.route,
        "sources": ["flexctrl_data.c", *plan.sources],
        "measurement_names": list(ctrl.sensors.names),
        "sample_time_s": ctrl.sample_time,
        "replay_samples": samples,
        "check": plan.check_doc,
        "check_rel": plan.check_rel,
        "check_abs_Nm": None if plan.check_abs is None else np.asarray(plan.check_abs).tolist(),
        **plan.notes,
    }
    (out / "export.json").write_text(json.dumps(meta, indent=2, default=float) + "\n")
    files = sorted(p.name for p in out.iterdir() if p.is_file())
    return Export(out, tuple(files), plan.route, samples, plan.check_doc)


__all__ = [
    "Plan",
    "Export",
    "reference_table",
    "export_folder",
    "no_option",
    "design_info",
    "write_library",
]
