"""Helpers shared by the model tests: a link alone, the spinning-beam frequency, RK4's energy
drift."""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np

from flexctrl.analysis.simulation_methods import parse_method
from flexctrl.analysis.steppers import make_stepper, run_open_loop


def one_link(arm, payload: float, gravity=(0.0, 0.0), link: int = 2):
    """Link ``link`` of the arm alone, clamped at a massless hub, carrying ``payload`` kg."""
    return dataclasses.replace(
        arm.with_payload(payload),
        links=arm.links[link : link + 1],
        configuration=(0.0,),
        gravity=gravity,
        joints=(dataclasses.replace(arm.joints[link], hub_mass=0.0),),
    )


def rotating_frequency(model, spin):
    """Lowest transverse frequency (rad/s) of a one-link model spun at ``spin`` rad/s about its
    joint."""
    n = model.n_q
    q, qd = ca.SX.sym("q", n), ca.SX.sym("qd", n)
    F = (
        model.functions["c"](q, qd)
        + model.functions["g"](q)
        + ca.mtimes(model.functions["K"]()["K"], q)
    )[1:]
    fun = ca.Function("F", [q, qd], [F, ca.jacobian(F, q)[:, 1:], ca.jacobian(F, qd)[:, 1:]])
    rate = np.r_[spin, np.zeros(n - 1)]
    qf = np.zeros(n - 1)
    for _ in range(20):  # steady stretched state in the rotating frame
        r, J, _ = (np.asarray(v, dtype=float) for v in fun(np.r_[0.0, qf], rate))
        step = np.linalg.solve(J, r.ravel())
        qf -= step
        if np.abs(step).max() < 1e-15:
            break
    _, KT, C = (np.asarray(v, dtype=float) for v in fun(np.r_[0.0, qf], rate))
    M = model.mass_matrix(np.r_[0.0, qf])[1:, 1:]
    A = np.block(
        [[np.zeros_like(M), np.eye(n - 1)], [-np.linalg.solve(M, KT), -np.linalg.solve(M, C)]]
    )
    ev = np.linalg.eigvals(A)
    return np.sort(np.abs(ev.imag[ev.imag > 1e-6]))[0]


def energy_drift(model, x0, h, duration=0.2):
    """Relative energy change of an undamped RK4 run at step ``h`` (s) and the swing of joint 1
    (rad)."""
    stepper = make_stepper(model, parse_method(f"{model.fidelity}/rk4@{h}"), 1e-3, compile=False)
    run = run_open_loop(stepper, x0, np.zeros((int(round(duration / 1e-3)), model.n_u)))
    n = model.n_q
    E = [sum(float(v) for v in model.functions["energies"](x[:n], x[n:])) for x in run.states]
    return abs(E[-1] - E[0]) / max(abs(e) for e in E), np.ptp([x[0] for x in run.states])
