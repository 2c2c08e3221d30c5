"""The interface every model family presents to simulation, linearisation and control.

A :class:`Model` is a bundle of named CasADi Functions built once from an
:class:`~flexctrl.spec.arm.ArmSpec` and a fidelity, plus thin numpy-level
wrappers.  Coordinates follow Subedi et al. (2021): joint coordinates first,
then elastic coordinates link by link; the state is ``x = (q, qd)``.

Required functions (``functions[name]``), with their input and output names:

``M``         (q) -> (M)                mass matrix, (N, N)
``c``         (q, qd) -> (c)            Coriolis and centrifugal vector, (N,)
``g``         (q) -> (g)                gravity vector, (N,)
``K``         () -> (K)                 stiffness, (N, N) (scheduled modes: (q) -> (K))
``D``         () -> (D)                 damping, (N, N) (scheduled modes: (q) -> (D))
``f``         (x, u) -> (xdot)          forward dynamics, x = (q, qd), u = joint torques (n,)
``energies``  (q, qd) -> (E_kin, E_el, E_grav)   J
``tip``       (q, qd) -> (p, v)         last link's tip position and velocity, world frame (2,)
``hubs``      (q) -> (p)                joint positions in the world frame, (2, n+1) incl. the tip
``deflection``(q) -> (w, dw)            tip deflection (m) and slope (rad) of every link, (n,)
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from typing import Any, TypeVar

import casadi as ca
import numpy as np

from flexctrl.spec.fidelity import Fidelity

T = TypeVar("T")

REQUIRED_FUNCTIONS = ("M", "c", "g", "f", "energies", "tip", "hubs", "deflection")


@dataclass(frozen=True)
class Model:
    """A built model: named CasADi Functions and the facts a simulator needs.

    Attributes
    ----------
    name : str
    fidelity : Fidelity
    n_joints : int
        Number of actuated joints (inputs).
    coordinate_names : tuple of str
        ``q1..qn`` then ``qf11, qf12, ...`` (link, mode) or nodal names.
    functions : dict of str to casadi.Function
    omega_max : float
        Highest undamped natural frequency of the linearisation at the build
        configuration (rad/s), free joints or locked, whichever is higher (the free
        one for arms); it bounds explicit integration steps and is used in
        stability advice.
    spec : Any
        The description it was built from (plain data).
    info : dict
        Build facts (mode frequencies, options, derivation choices).
    derived : dict
        Functions derived from this model by the layers above (the closed loop's compiled
        plant step and output map), kept with it: built once per model, gone with it.
    """

    name: str
    fidelity: Fidelity
    n_joints: int
    coordinate_names: tuple[str, ...]
    functions: dict[str, ca.Function]
    omega_max: float
    spec: Any = None
    info: dict = field(default_factory=dict)
    derived: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        missing = [n for n in REQUIRED_FUNCTIONS if n not in self.functions]
        if missing:
            raise TypeError(f"model '{self.name}' lacks the functions {missing}")

    # -- sizes -----------------------------------------------------------------------
    @property
    def n_q(self) -> int:
        """Number of generalised coordinates N."""
        return len(self.coordinate_names)

    @property
    def n_x(self) -> int:
        """State dimension 2N."""
        return 2 * self.n_q

    @property
    def n_u(self) -> int:
        """Number of inputs (joint torques)."""
        return self.n_joints

    # -- numpy-level wrappers --------------------------------------------------------
    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """M(q), (N, N), kg and kg m^2."""
        return np.array(self.functions["M"](q), dtype=float)

    def coriolis(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """c(q, qd), (N,)."""
        return np.array(self.functions["c"](q, qd), dtype=float).ravel()

    def gravity(self, q: np.ndarray) -> np.ndarray:
        """g(q), (N,)."""
        return np.array(self.functions["g"](q), dtype=float).ravel()

    def forward_dynamics(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Accelerations qdd (N,) for joint torques ``tau`` (N m)."""
        x = np.concatenate([np.ravel(q), np.ravel(qd)])
        xdot = np.array(self.functions["f"](x, tau), dtype=float).ravel()
        return xdot[self.n_q :]

    def energies(self, q: np.ndarray, qd: np.ndarray) -> dict[str, float]:
        """Kinetic, elastic and gravitational energy (J) and their total."""
        kin, el, grav = (float(v) for v in self.functions["energies"](q, qd))
        return {"E_kin": kin, "E_el": el, "E_grav": grav, "E_total": kin + el + grav}


def derived(model: Any, key: Hashable, build: Callable[[], T]) -> T:
    """``build()`` once per model, kept in ``model.derived`` under ``key``.

    A model without that store (a stand-in with the same functions) gets it built anew.

    Parameters
    ----------
    model : Model
        The model the value is kept with.
    key : hashable
        What the value is kept under.
    build : callable
        ``build()`` makes the value, called once per model and key.

    Returns
    -------
    object
        The kept value.
    """
    store = getattr(model, "derived", None)
    if store is None:
        return build()
    if key not in store:
        store[key] = build()
    return store[key]
