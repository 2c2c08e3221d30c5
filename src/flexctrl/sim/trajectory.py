"""The result of a simulation: :class:`Trajectory` (arrays, meta, figures, files, plots).

Shaped like python-control's ``TimeResponseData``: plain arrays with one row per
time sample, names for every column, ``to_pandas()``, ``save()`` and ``plot()``.
Energies, tip positions and link-tip deflections are evaluated by the simulator
with mapped CasADi functions, not Python loops, and stored here.

CSV layout (``trajectory.csv``), one header row then one row per sample::

    t, q1..qn, qf11, qf12, ..., tip_x, tip_y, E_kin, E_el, E_grav, E_total,
    dq1..dqn, dqf11, ..., w1..wn, u1..un

``dq*`` are the coordinate velocities, ``w<i>`` the tip deflection of link i (m),
``u<i>`` the joint torque applied from that sample on (zero-order hold; the last
row repeats the last applied torque).  Units: s, rad, m, J, N m.
"""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.sim.fft_peaks import dominant_frequencies

ENERGY_NAMES = ("E_kin", "E_el", "E_grav", "E_total")


def energy_dict(kin: np.ndarray, el: np.ndarray, grav: np.ndarray) -> dict[str, np.ndarray]:
    """``{E_kin, E_el, E_grav, E_total}`` (J) from the three energies; ``E_total`` is their sum.

    Parameters
    ----------
    kin, el, grav : numpy.ndarray
        Kinetic, elastic and gravitational energy (J), each of shape (T,).

    Returns
    -------
    dict of str to numpy.ndarray
        The three energies and their sum.
    """
    return {"E_kin": kin, "E_el": el, "E_grav": grav, "E_total": kin + el + grav}


class LazyEnergies(Mapping):
    """The energies of a trajectory, evaluated on first access (a read-only mapping like a dict).

    ``compute()`` returns ``(E_kin, E_el, E_grav)`` (J, each shape (T,)); ``E_total`` is
    their sum.  A closed loop's metrics read the tip and deflections only, and the kinetic
    energy (the mass matrix at every plant step) costs most of the outputs, so the
    closed loop leaves it to whoever reads it (the CSV, the plots, the energy figures).
    Copied or pickled, it is evaluated and becomes a plain dict.

    Parameters
    ----------
    compute : callable
        ``compute() -> (E_kin, E_el, E_grav)`` (J, each of shape (T,)), called once.
    """

    def __init__(self, compute: Callable[[], tuple[np.ndarray, np.ndarray, np.ndarray]]):
        self._compute: Callable[[], tuple[np.ndarray, np.ndarray, np.ndarray]] | None = compute
        self._values: dict[str, np.ndarray] | None = None

    @property
    def evaluated(self) -> bool:
        """Whether the energies have been computed."""
        return self._values is not None

    def _get(self) -> dict[str, np.ndarray]:
        if self._values is None:
            if self._compute is None:
                raise RuntimeError("the energies were neither computed nor computable")
            self._values = energy_dict(*self._compute())
            self._compute = None
        return self._values

    def __getitem__(self, key: str) -> np.ndarray:
        if key not in ENERGY_NAMES:
            raise KeyError(key)
        return self._get()[key]

    def __contains__(self, key: object) -> bool:
        return key in ENERGY_NAMES

    def __iter__(self) -> Iterator[str]:
        return iter(ENERGY_NAMES)

    def __len__(self) -> int:
        return len(ENERGY_NAMES)

    def __reduce__(self):
        return dict, (self._get(),)

    def __deepcopy__(self, memo):
        return copy.deepcopy(self._get(), memo)

    def __repr__(self) -> str:
        return f"LazyEnergies({'evaluated' if self.evaluated else 'not evaluated yet'})"


@dataclass
class Trajectory:
    """Time histories of one simulation run.

    Attributes
    ----------
    time : numpy.ndarray
        Sample times (s), shape (T,).
    states : numpy.ndarray
        ``x = (q, qd)`` per sample, shape (T, 2N).
    inputs : numpy.ndarray
        Joint torques (N m) applied from each sample on, shape (T, n).
    coordinate_names : tuple of str
        Names of the N coordinates (``q1..qn, qf11, ...``).
    energies : mapping of str to numpy.ndarray
        ``E_kin``, ``E_el``, ``E_grav`` and ``E_total`` (J), each shape (T,): a dict, or
        :class:`LazyEnergies` (evaluated when first read) from the closed loop.
    tip : numpy.ndarray
        Tip position of the last link in the world frame (m), shape (T, 2).
    deflections : numpy.ndarray
        Tip deflection of every link (m), shape (T, n_links).
    meta : dict
        Integrator, step, wall time, counters, status and settings.
    """

    time: np.ndarray
    states: np.ndarray
    inputs: np.ndarray
    coordinate_names: tuple[str, ...]
    energies: Mapping[str, np.ndarray]
    tip: np.ndarray
    deflections: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)

    # -- views -------------------------------------------------------------------------
    @property
    def n_q(self) -> int:
        """Number of coordinates N."""
        return len(self.coordinate_names)

    @property
    def q(self) -> np.ndarray:
        """Coordinates, shape (T, N)."""
        return self.states[:, : self.n_q]

    @property
    def qd(self) -> np.ndarray:
        """Coordinate velocities, shape (T, N)."""
        return self.states[:, self.n_q :]

    def coordinate(self, name: str) -> np.ndarray:
        """The history of coordinate ``name`` (e.g. ``"qf31"``)."""
        if name not in self.coordinate_names:
            raise KeyError(f"no coordinate '{name}'; known: {', '.join(self.coordinate_names)}")
        return self.q[:, self.coordinate_names.index(name)]

    @property
    def work_in(self) -> np.ndarray:
        """Cumulative work of the joint torques (J).

        The torque is held over each step, so the work of step k is exactly
        ``u_k . (q_joints(t_k+1) - q_joints(t_k))``.
        """
        n_u = self.inputs.shape[1]
        steps = np.einsum("ij,ij->i", self.inputs[:-1], np.diff(self.q[:, :n_u], axis=0))
        return np.concatenate([[0.0], np.cumsum(steps)])

    # -- figures -----------------------------------------------------------------------
    def energy_figures(self) -> dict[str, float]:
        """Energy drift figures, relative to the energy exchanged in the run.

        ``scale`` is ``max(E_kin + E_el) + range(E_grav) + max|work_in|`` (J);
        ``drift_rel`` is ``(E_total(end) - E_total(0)) / scale``; ``max_error_rel``
        is ``max|E_total - E_total(0)| / scale``; ``balance_error_max_rel`` is
        ``max|E_total - E_total(0) - work_in| / scale`` (zero for an exact
        integrator without damping or friction, negative when damping dissipates).
        """
        e = self.energies
        work = self.work_in
        grav = e["E_grav"]
        scale = float(
            np.max(e["E_kin"] + e["E_el"]) + (np.max(grav) - np.min(grav)) + np.max(np.abs(work))
        )
        scale = max(scale, 1e-300)
        change = e["E_total"] - e["E_total"][0]
        balance = change - work
        return {
            "scale_J": scale,
            "drift_rel": float(change[-1] / scale),
            "max_error_rel": float(np.max(np.abs(change)) / scale),
            "balance_error_max_rel": float(np.max(np.abs(balance)) / scale),
            "balance_error_end_rel": float(balance[-1] / scale),
        }

    def dominant_frequencies(self, count: int = 2, span: float = 2.0) -> dict[str, list[float]]:
        """Strongest FFT peaks (Hz) of every link's tip deflection over the first ``span`` s."""
        dt = float(np.median(np.diff(self.time))) if self.time.size > 1 else 0.0
        if dt <= 0.0:
            return {f"w{i + 1}": [] for i in range(self.deflections.shape[1])}
        samples = min(self.time.size, int(round(span / dt)) + 1)
        return {
            f"w{i + 1}": dominant_frequencies(self.deflections[:samples, i], dt, count)
            for i in range(self.deflections.shape[1])
        }

    def summary(self, fft_count: int = 2, fft_span: float = 2.0) -> dict[str, Any]:
        """Meta data plus energy figures and dominant frequencies (JSON-ready)."""
        out = dict(self.meta)
        out["samples"] = int(self.time.size)
        out["t_final"] = float(self.time[-1])
        out["energy"] = self.energy_figures()
        out["dominant_frequencies_hz"] = self.dominant_frequencies(fft_count, fft_span)
        out["fft_span_s"] = float(min(fft_span, self.time[-1] - self.time[0]))
        return jsonable(out)

    # -- tables and files ------------------------------------------------------------
    def columns(self) -> tuple[list[str], np.ndarray]:
        """Column names and the matrix written to ``trajectory.csv`` (see module docstring)."""
        n_links = self.deflections.shape[1]
        names = (
            ["t", *self.coordinate_names, "tip_x", "tip_y", *ENERGY_NAMES]
            + [f"d{name}" for name in self.coordinate_names]
            + [f"w{i + 1}" for i in range(n_links)]
            + [f"u{i + 1}" for i in range(self.inputs.shape[1])]
        )
        energies = np.column_stack([self.energies[k] for k in ENERGY_NAMES])
        matrix = np.column_stack(
            [self.time, self.q, self.tip, energies, self.qd, self.deflections, self.inputs]
        )
        return names, matrix

    def to_pandas(self):
        """A ``pandas.DataFrame`` with the CSV columns, indexed by time (needs pandas)."""
        try:
            import pandas as pd  # optional: only this method needs it
        except ImportError as exc:  # pragma: no cover - pandas is a dev dependency
            raise ImportError("Trajectory.to_pandas needs pandas (pip install pandas)") from exc
        names, matrix = self.columns()
        return pd.DataFrame(matrix, columns=names).set_index("t", drop=False)

    def save(
        self,
        directory: str | Path,
        extra: dict[str, Any] | None = None,
        *,
        fft_count: int = 2,
        fft_span: float = 2.0,
    ) -> dict[str, Path]:
        """Write ``trajectory.csv`` and ``summary.json`` (``extra`` merged into the summary).

        ``fft_count`` and ``fft_span`` (s) set the dominant-frequency figures
        (see :meth:`dominant_frequencies`).

        Returns
        -------
        dict
            ``{"csv": path, "summary": path}``.
        """
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        names, matrix = self.columns()
        csv_path = directory / "trajectory.csv"
        np.savetxt(
            csv_path, matrix, delimiter=",", header=",".join(names), comments="", fmt="%.12g"
        )
        summary = self.summary(fft_count, fft_span)
        if extra:
            summary.update(jsonable(extra))
        summary_path = directory / "summary.json"
        summary_path.write_text(json.dumps(summary, indent=2, allow_nan=False) + "\n")
        return {"csv": csv_path, "summary": summary_path}

    def plot(self, directory: str | Path, prefix: str = "") -> list[Path]:
        """Write PNG plots (joint angles, deflections per link, tip path, energies).

        Uses matplotlib's Agg canvas directly (no pyplot state, no window).
        """
        # lazily: the plots import matplotlib, which a run without figures never needs
        from flexctrl.sim.trajectory_plots import plot_trajectory

        return plot_trajectory(self, Path(directory), prefix)


def jsonable(value: Any) -> Any:
    """Convert numpy scalars/arrays and non-finite floats into JSON-safe values.

    Parameters
    ----------
    value : object
        A scalar, array, list, tuple or dict (nested); non-finite floats become strings.

    Returns
    -------
    object
        The same value made of plain Python types.
    """
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return v if math.isfinite(v) else str(v)
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.bool_,)):
        return bool(value)
    if isinstance(value, Path):
        return str(value)
    return value
