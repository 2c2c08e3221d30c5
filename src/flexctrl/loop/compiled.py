"""The closed loop in one CasADi call: every sample after the first, for controllers whose law is a
CasADi map.

Per sample the Python loop (:mod:`flexctrl.loop.sampled`) measures, calls
``controller.step`` and the plant's compiled step: hundreds of microseconds of Python
and conversions around a plant step of about 50 us.  A controller that is a fixed map
with memory (LQR, LQG, PD, shaped; :meth:`~flexctrl.control.controller.Controller.sampled_law`)
instead gives its law as a CasADi Function, and one sample becomes

    y_k = sensors(x_k, u_{k-1}) + sigma z_k
    (xi_k, v_k) = law(xi_{k-1}, y_k, u_{k-1}, r_k)          u_k = clip(v_k)
    X_k = advance(x_k, u_k, dt)                           (the compiled plant step)

chained over the samples by ``mapaccum`` and evaluated in ONE call; ``r_k`` (the
reference rows, tabulated once) and ``z_k`` (the noise, drawn from the run's generator
in the order the Python loop draws it) are inputs.  The first sample runs in Python
(estimators start from the first measurement, the shaped step from the first joint
angles).  Divergence is judged afterwards on the same states with the same rules:
the first offending sample ends the run as it would have in the Python loop.  The
controller's statistics are filled as its ``step`` would (status, saturation); its
step time is the law's own, from one batched evaluation over the run divided by the
samples (it excludes the plant).
"""

from __future__ import annotations

import time

import casadi as ca
import numpy as np

from flexctrl.loop.monitors import MODAL_BOUND, RATE_BOUND
from flexctrl.sim.bound import evaluate


def sample_function(run, law) -> ca.Function:
    """``(x, xi, u_prev, r, z) -> (x_next, xi_next, u, X, v, y)`` of one sample (module docstring)."""
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


#: Samples per call of the chained loop (:func:`_chained`).
CHUNK = 128


def run_compiled(run, law, chunk: int | None = CHUNK) -> None:
    """Samples ``run.done`` to the end of ``run`` (a :class:`~flexctrl.loop.sampled.LoopRun`),
    chained in CasADi.

    ``chunk``: samples per call (:func:`_chained`); None: the whole run in one call.
    """
    plant, controller = run.plant, run.controller
    k0, count, Ts = run.done, run.n_samples - run.done, controller.sample_time
    times = np.arange(k0, run.n_samples) * Ts
    R = np.asarray(law.references(times), dtype=float)
    Z = (
        run.rng.standard_normal((count, run.sensors.n_y))
        if run.rng is not None
        else np.zeros((count, run.sensors.n_y))
    )
    xi0, u0 = np.array(law.memory, dtype=float), run.u
    xis, us, states, vs, ys = _chained(sample_function(run, law), run.x, xi0, u0, R, Z, chunk)
    blocks = states.reshape(count, run.substeps, plant.n_x)
    done = _first_divergence(run, blocks, k0)
    n = count if done is None else done + 1
    per, stride = run.per, run.stride
    run.X[k0 * per + 1 : (k0 + n) * per + 1] = blocks[:n, stride - 1 :: stride].reshape(
        n * per, plant.n_x
    )
    run.U[k0 * per : (k0 + n) * per] = np.repeat(us[:n], per, axis=0)
    run.x, run.u, run.done = blocks[n - 1, -1], us[n - 1], k0 + n
    if done is not None:
        run.check(k0 + done, blocks[done])
    _record(controller, law, xis, us, vs, ys, R, xi0, u0, n)


def _chained(
    sample: ca.Function, x0, xi0, u0, R: np.ndarray, Z: np.ndarray, chunk: int | None
) -> list[np.ndarray]:
    """``(xi, u, X, v, y)`` rows of ``len(R)`` chained samples: ``mapaccum`` calls of ``chunk``
    samples each.

    Building a ``mapaccum`` costs time in proportion to its length (about 0.2 ms per sample
    with CasADi 3.8, 0.04-0.27 s for the 940-1070 samples of an LQR or LQG run of
    ``move_joint1_30deg``). A loop of ``chunk`` samples, built once and called over the
    run, with the remainder as a second loop, evaluates the same operations on the same
    values in the same order (the chained state goes from one call to the next as a
    double), so it gives the same numbers as one loop over the whole run.
    """
    count = len(R)
    size = count if chunk is None else min(chunk, count)
    loops: dict[int, ca.Function] = {}
    parts: list[list[np.ndarray]] = []
    x, xi, u = x0, xi0, u0
    for start in range(0, count, size):
        n = min(size, count - start)
        if n not in loops:
            loops[n] = sample.mapaccum("closed_loop", n, [0, 1, 2], [0, 1, 2])
        x_end, xis, us, states, vs, ys = evaluate(
            loops[n], x, xi, u, R[start : start + n], Z[start : start + n]
        )
        parts.append([xis, us, states, vs, ys])
        x, xi, u = x_end[-1], (xis[-1] if xis.size else xi0), us[-1]
    return [np.concatenate(column) for column in zip(*parts)]


def _first_divergence(run, blocks: np.ndarray, k0: int) -> int | None:
    """Index (into ``blocks``) of the first sample the Python loop's check would stop at, or None."""
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


def _record(controller, law, xis, us, vs, ys, R, xi0, u0, n: int) -> None:
    """Fill the controller's statistics and state as ``n`` calls of its ``step`` would."""
    stats = controller.stats
    saturated = np.any(us[:n] != vs[:n], axis=1)
    stats.saturated += int(np.sum(saturated))
    if np.any(saturated):
        stats.clipped_max = max(
            stats.clipped_max, float(np.max(np.abs(us[:n] - vs[:n])[saturated]))
        )
    stats.status[law.status] += n
    xi_prev = np.vstack([xi0[None, :], xis[: n - 1]]) if xi0.size else np.zeros((n, 0))
    u_prev = np.vstack([u0[None, :], us[: n - 1]])
    start = time.perf_counter()
    law.function.map(n)(xi_prev.T, ys[:n].T, u_prev.T, R[:n].T)
    stats.step_times.extend([(time.perf_counter() - start) / n] * n)
    law.restore(xis[n - 1] if xis.size else np.zeros(0))
    controller.u_previous = np.array(us[n - 1], dtype=float)
