"""The closed loop chained in CasADi: every sample after the first, for laws that are CasADi maps.

Per sample the Python loop (:meth:`flexctrl.loop.run_state.LoopRun.python_sample`)
measures, calls ``controller.step`` and the plant's compiled step, with Python and
conversions around every plant step.  A controller that is a fixed map with memory (LQR,
LQG, PD, shaped; :meth:`~flexctrl.control.controller.Controller.sampled_law`) instead
gives its law as a CasADi Function, and one sample becomes

    y_k = sensors(x_k, u_{k-1}) + sigma z_k
    (xi_k, v_k) = law(xi_{k-1}, y_k, u_{k-1}, r_k)          u_k = clip(v_k)
    X_k = advance(x_k, u_k, dt)                           (the compiled plant step)

chained over the samples by ``mapaccum``; ``r_k`` (the reference rows, tabulated once)
and ``z_k`` (the noise, drawn from the run's generator in the order the Python loop draws
it) are inputs.  The first sample runs in Python (estimators start from the first
measurement, the shaped step from the first joint angles).

The chain is evaluated in calls of at most :data:`CHUNK` samples: building a ``mapaccum``
costs time in proportion to its length, so one loop of ``CHUNK`` samples is built once and
called over the run (the remainder as a second loop).  A call holds every plant step of
its samples, so fine plant steps (finite elements, thousands of steps per sample) get
fewer samples per call, at most :data:`CHUNK_STEPS` plant steps: building a chain of
nested step loops costs memory and time faster than in proportion to its length, and a
call's states stay bounded whatever the run's length.  The chained state goes from one
call to the next as a double, so any chunking gives the same numbers to the last digit.

Divergence is judged after each call on the same states with the same rules as the
Python loop: the first offending sample ends the run as it would have there, and no
further call is made.  The controller's statistics are filled as its ``step`` would
(status, saturation); its step time is the law's own, from one batched evaluation over
the run divided by the samples (it excludes the plant).
"""

from __future__ import annotations

import time

import casadi as ca
import numpy as np

from flexctrl.loop.monitors import MODAL_BOUND, RATE_BOUND
from flexctrl.sim.bound import evaluate

#: Samples per call of the chained loop, at most.
CHUNK = 128
#: Plant steps per call of the chained loop, at most: fewer samples per call for fine plant
#: steps (one sample per call beyond it).
CHUNK_STEPS = 4096


def sample_function(run, law) -> ca.Function:
    """``(x, xi, u_prev, r, z) -> (x_next, xi_next, u, X, v, y)``: one sample (module docstring)."""
    plant, sensors, controller = run.plant, run.sensors, run.controller
    x, u_prev = ca.MX.sym("x", plant.n_x), ca.MX.sym("u_prev", plant.n_u)
    xi = ca.MX.sym("xi", law.memory.size)
    r = ca.MX.sym("r", law.function.size1_in(3))
    z = ca.MX.sym("z", sensors.n_y)
    y = sensors.function(x, u_prev)
    if run.rng is not None:
        y = y + ca.DM(sensors.noise_std) * z
    xi_next, v = law.function(xi, y, u_prev, r)
    u = v
    if controller.saturate:
        limits = ca.DM(controller.limits)
        u = ca.fmin(ca.fmax(v, -limits), limits)
    X = run.advance(x, u, run.dt)
    return ca.Function(
        "closed_loop_sample",
        [x, xi, u_prev, r, z],
        [X[:, -1], xi_next, u, X, v, y],
        ["x", "xi", "u_prev", "r", "z"],
        ["x_next", "xi_next", "u", "X", "v", "y"],
    )


def chunk_size(run) -> int:
    """Samples per call for ``run``: :data:`CHUNK`, fewer when a sample holds many plant steps."""
    return max(1, min(CHUNK, CHUNK_STEPS // run.substeps))


def run_compiled(run, law) -> None:
    """Samples ``run.done`` to the end of ``run``, chained in CasADi (module docstring).

    Parameters
    ----------
    run : flexctrl.loop.run_state.LoopRun
        After its first sample (run in Python).
    law : SampledLaw
        The controller's :meth:`sampled_law`.
    """
    controller, k0 = run.controller, run.done
    count, Ts = run.n_samples - k0, controller.sample_time
    R = np.asarray(law.references(np.arange(k0, run.n_samples) * Ts), dtype=float)
    Z = (
        run.rng.standard_normal((count, run.sensors.n_y))
        if run.rng is not None
        else np.zeros((count, run.sensors.n_y))
    )
    xi0, u0 = np.array(law.memory, dtype=float), run.u
    sample = sample_function(run, law)
    size = min(chunk_size(run), count)
    loops: dict[int, ca.Function] = {}
    parts: list[list[np.ndarray]] = []
    xi = xi0
    for start in range(0, count, size):
        n = min(size, count - start)
        if n not in loops:
            loops[n] = sample.mapaccum("closed_loop", n, [0, 1, 2], [0, 1, 2])
        _x_end, xis, us, states, vs, ys = evaluate(
            loops[n], run.x, xi, run.u, R[start : start + n], Z[start : start + n]
        )
        blocks = states.reshape(n, run.substeps, run.plant.n_x)
        kept = _keep(run, blocks, us, k0 + start)
        parts.append([xis[:kept], us[:kept], vs[:kept], ys[:kept]])
        xi = xis[kept - 1] if xis.size else xi0
        if run.divergence is not None:
            break
    xis, us, vs, ys = (np.concatenate(column) for column in zip(*parts))
    _record(controller, law, xis, us, vs, ys, R, xi0, u0)


def _keep(run, blocks: np.ndarray, us: np.ndarray, k0: int) -> int:
    """Keep the states ``blocks`` and torques ``us`` of samples ``k0, k0 + 1, ...`` in ``run``.

    Returns how many samples were kept: up to a divergence, whose sample is kept and
    recorded (:meth:`~flexctrl.loop.run_state.LoopRun.check`) and ends the run.
    """
    per, stride, plant = run.per, run.stride, run.plant
    first = _first_divergence(run, blocks, k0)
    n = len(blocks) if first is None else first + 1
    run.X[k0 * per + 1 : (k0 + n) * per + 1] = blocks[:n, stride - 1 :: stride].reshape(
        n * per, plant.n_x
    )
    run.U[k0 * per : (k0 + n) * per] = np.repeat(us[:n], per, axis=0)
    run.x, run.u, run.done = blocks[n - 1, -1], us[n - 1], k0 + n
    if first is not None:
        run.check(k0 + first, blocks[first])
    return n


def _first_divergence(run, blocks: np.ndarray, k0: int) -> int | None:
    """Index into ``blocks`` of the first sample the Python loop's check would stop at, or None."""
    plant = run.plant
    with np.errstate(invalid="ignore", over="ignore"):
        bad = ~np.all(np.isfinite(blocks), axis=(1, 2))
        bad |= (
            np.max(np.abs(blocks[:, :, plant.n_u : plant.n_q]), axis=(1, 2), initial=0.0)
            > MODAL_BOUND
        )
        bad |= np.max(np.abs(blocks[:, :, plant.n_q :]), axis=(1, 2)) > RATE_BOUND
    ends = blocks[:, -1]
    monitor = run.monitor
    if monitor is not None and hasattr(monitor, "flags"):
        finite = ~bad
        flagged = np.zeros(len(blocks), dtype=bool)
        flagged[finite] = monitor.flags(ends[finite])
        bad |= flagged
    elif monitor is not None:
        Ts = run.controller.sample_time
        for j in range(len(blocks)):
            if bad[j] or monitor((k0 + j) * Ts + Ts, ends[j]) is not None:
                bad[j] = True
                break
    hits = np.flatnonzero(bad)
    return int(hits[0]) if hits.size else None


def _record(controller, law, xis, us, vs, ys, R, xi0, u0) -> None:
    """Fill the controller's statistics and state as ``len(us)`` calls of its ``step`` would."""
    n = len(us)
    stats = controller.stats
    saturated = np.any(us != vs, axis=1)
    stats.saturated += int(np.sum(saturated))
    if np.any(saturated):
        stats.clipped_max = max(stats.clipped_max, float(np.max(np.abs(us - vs)[saturated])))
    stats.status[law.status] += n
    xi_prev = np.vstack([xi0[None, :], xis[: n - 1]]) if xi0.size else np.zeros((n, 0))
    u_prev = np.vstack([u0[None, :], us[: n - 1]])
    start = time.perf_counter()
    law.function.map(n)(xi_prev.T, ys.T, u_prev.T, R[:n].T)
    stats.step_times.extend([(time.perf_counter() - start) / n] * n)
    law.restore(xis[n - 1] if xis.size else np.zeros(0))
    controller.u_previous = np.array(us[n - 1], dtype=float)
