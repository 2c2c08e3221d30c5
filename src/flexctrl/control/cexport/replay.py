"""A controller's steps recorded in a closed loop, for the C library's harness to replay.

:class:`StepRecorder` stands in for a designed controller in any loop (``fc.closed_loop``,
one's own): it passes every call to the controller, runs every sample through
:meth:`~flexctrl.control.controller.Controller.step` (never the compiled law, so the
torques are those of the method the C code replaces) and keeps, per sample ``k``: the
time, the measurement ``y_k``, the torque held during the sample that just ended
``u_{k-1}`` (clipped), the reference row ``(x_ref, u_ref)`` the controller read and the
torque ``u_k`` it returned.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flexctrl.errors import SpecError


@dataclass(frozen=True)
class Replay:
    """Recorded steps of one controller, one row per sample.

    Attributes
    ----------
    t : ndarray
        (K,) sample times, s.
    y : ndarray
        (K, n_y) measurements in the controller's order and units.
    u_prev : ndarray
        (K, n_u) torque held during the sample before ``k``, N m.
    x_ref, u_ref : ndarray
        (K, n_x) and (K, n_u): the reference row the controller read.
    u : ndarray
        (K, n_u) the torque the controller returned, N m.
    step_times : ndarray
        (K,) wall time of each ``step``, s.
    source : str
        Where the loop was recorded (a scene, a plant), for the exported header.
    """

    t: np.ndarray
    y: np.ndarray
    u_prev: np.ndarray
    x_ref: np.ndarray
    u_ref: np.ndarray
    u: np.ndarray
    step_times: np.ndarray
    source: str = ""

    @property
    def samples(self) -> int:
        """Number of recorded samples."""
        return int(self.t.size)


class StepRecorder:
    """A designed controller with its steps recorded (see the module docstring).

    Parameters
    ----------
    controller : flexctrl.control.controller.Controller
        The controller; every attribute but :meth:`step` and :meth:`sampled_law` is its own.
    source : str
        Where the loop runs (a scene, a plant), said in the exported header.

    Examples
    --------
    >>> rec = StepRecorder(ctrl)                                  # doctest: +SKIP
    >>> fc.closed_loop(model, rec, move, 4.0)                     # doctest: +SKIP
    >>> ctrl.export_c("out/lqr", replay=rec.replay())             # doctest: +SKIP
    """

    def __init__(self, controller, source: str = ""):
        self.controller = controller
        self.source = source
        self._rows: list[tuple] = []

    def __getattr__(self, name: str):
        return getattr(self.controller, name)

    def reset(self) -> None:
        """Reset the controller and forget the recorded steps."""
        self.controller.reset()
        self._rows = []

    def sampled_law(self) -> None:
        """None: every sample runs through :meth:`step`, the method the C code replaces."""
        return None

    def has_sampled_law(self) -> bool:
        """False (see :meth:`sampled_law`)."""
        return False

    def step(self, t: float, measurement) -> np.ndarray:
        """The controller's :meth:`~flexctrl.control.controller.Controller.step`, recorded.

        Parameters
        ----------
        t : float
            The time of the measurement, s.
        measurement : array_like
            In the controller's order and units.

        Returns
        -------
        ndarray
            Its torques, N m.
        """
        ctrl = self.controller
        u_prev = np.array(ctrl.u_previous, dtype=float)
        u = ctrl.step(t, measurement)
        X, U, _ = ctrl.reference.window(float(t), ctrl.sample_time, 1)
        y = np.array(measurement, dtype=float).ravel()
        self._rows.append((float(t), y, u_prev, X[0].copy(), U[0].copy(), np.array(u)))
        return u

    def replay(self) -> Replay:
        """The steps since the last :meth:`reset`.

        Raises
        ------
        SpecError
            When nothing was recorded or the samples are not ``k Ts`` from the first
            (the C library counts samples from its reference table's start).
        """
        if not self._rows:
            raise SpecError("no steps were recorded; run a closed loop first", key="replay")
        t, y, u_prev, X, U, u = (np.array(c) for c in zip(*self._rows))
        Ts = self.controller.sample_time
        if np.max(np.abs(t - Ts * np.arange(t.size))) > 1e-9 * max(1.0, float(t[-1])):
            raise SpecError(
                f"the recorded samples are not k x {Ts:g} s from t = 0; allowed: one run "
                "from the start of the move",
                key="replay",
            )
        times = np.asarray(self.controller.stats.step_times[-t.size :], dtype=float)
        return Replay(t, y, u_prev, X, U, u, times, self.source)


def write_replay(replay: Replay, path, names: tuple[str, ...]) -> None:
    """``replay.csv``: ``k, t, y..., u_prev..., x_ref..., u_ref..., u...`` (exact round trip)."""
    n_u, n_x = replay.u.shape[1], replay.x_ref.shape[1]
    header = (
        ["k", "t", *names]
        + [f"u_prev{i + 1}" for i in range(n_u)]
        + [f"x_ref{i + 1}" for i in range(n_x)]
        + [f"u_ref{i + 1}" for i in range(n_u)]
        + [f"u{i + 1}" for i in range(n_u)]
    )
    table = np.hstack(
        [replay.t[:, None], replay.y, replay.u_prev, replay.x_ref, replay.u_ref, replay.u]
    )
    with open(path, "w") as f:
        f.write(",".join(header) + "\n")
        for k, row in enumerate(table):
            f.write(",".join([str(k)] + [repr(float(v)) for v in row]) + "\n")


__all__ = ["Replay", "StepRecorder", "write_replay"]
