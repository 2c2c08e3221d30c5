"""The finite-element scenes as frozen descriptions: ``sliding_beam``, ``rp_arm``, ``telescoping``.

Read and validated by :func:`flexctrl.spec.fem_scene.read_fem_scene`, whose module
describes the keys; run by :mod:`flexctrl.scenes.run_fem_scene`.
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar, Literal

from flexctrl.errors import SpecError
from flexctrl.spec.fem_models import RPArmSpec, TelescopingSpec
from flexctrl.spec.fidelity import Fidelity, parse_fidelity

FEM_SCENE_KINDS = ("sliding_beam", "rp_arm", "telescoping")
DRIVE_KINDS: tuple[Literal["motion", "force"], ...] = ("motion", "force")
COUPLINGS: tuple[Literal["partial", "full"], ...] = ("partial", "full")
ENDS = ("H", "E")
MAX_STEPS = 5_000_000
#: Field metadata marking what :meth:`FemScene.settings` leaves out (the origin, the loaded model).
_NOT_A_SETTING = {"setting": False}


@dataclasses.dataclass(frozen=True, kw_only=True)
class FemScene:
    """What every finite-element scene holds, validated (SI units).

    The keys are described in :mod:`flexctrl.spec.fem_scene`.  Use the kind's class:
    :class:`SlidingBeamScene`, :class:`RPArmScene`, :class:`TelescopingScene`.

    Attributes
    ----------
    name, description : str
        Scene name (default: the file's stem) and free text.
    C1 : float
        Initial overhang ``W(0)`` beyond the outer support, m (Eq 57).
    C2 : float
        Travel, m: ``W(T) = C1 - C2`` (negative: the link extends).
    T : float
        Duration of the prescribed motion (or of the force pulses), s.
    tracked_end : {"H", "E"}
        End whose transverse displacement is reported as ``tip_y``.
    driven_end : {"H", "E"}
        Where the axial drive acts.
    n_elements : int
        Equal Hermite elements (per link for ``telescoping``), 1 to 256.
    dt, duration : float
        Newmark step and simulated time, s (``dt <= duration``, at most :data:`MAX_STEPS` steps).
    gamma, beta : float
        Baumgarte parameters, 1/s (Eq 49).
    alpha, delta : float
        Newmark parameters (Eqs 50-51).
    axial_shortening : bool
        Geometric stiffness of the rigid-body axial force (Eqs 16-18).
    max_violation : float
        Bound on the constraint violation ``|Phi|``, m (exceeding it stops the run).
    plots : bool
        Write ``tip.png``.
    source : str
        The file (or other origin) the scene was read from.
    """

    KIND: ClassVar[str] = ""

    name: str
    description: str = ""
    C1: float
    C2: float
    T: float
    tracked_end: Literal["H", "E"] = "H"
    driven_end: Literal["H", "E"]
    n_elements: int = 4
    dt: float = 1e-3
    duration: float
    gamma: float = 5.0
    beta: float = 5.0
    alpha: float = 0.25
    delta: float = 0.5
    axial_shortening: bool = True
    max_violation: float = 1e-3
    plots: bool = True
    source: str = dataclasses.field(default="", metadata=_NOT_A_SETTING)

    @property
    def kind(self) -> str:
        """The scene's ``kind`` (``"sliding_beam"``, ``"rp_arm"`` or ``"telescoping"``)."""
        return self.KIND

    def settings(self) -> dict[str, Any]:
        """The scene as plain, JSON-ready data: ``summary.json``'s ``"scene"``.

        ``kind`` first, then the keys in the order of :mod:`flexctrl.spec.fem_scene`'s
        docstring; angles in degrees, as in the file.
        """
        out: dict[str, Any] = {"kind": self.kind}
        for f in dataclasses.fields(self):
            if f.metadata.get("setting", True):
                out[f.name] = _plain(getattr(self, f.name))
        return out

    def with_fidelity(
        self, fidelity: Fidelity | str | None, *, source: str = "--fidelity"
    ) -> FemScene:
        """This scene with ``fidelity = "fem:N"`` applied (``n_elements = N``); None: unchanged.

        Raises
        ------
        SpecError
            For any other fidelity, naming ``source`` and the key ``fidelity``.
        """
        if fidelity is None:
            return self
        return dataclasses.replace(self, n_elements=fem_elements(fidelity, self.kind, source))


@dataclasses.dataclass(frozen=True, kw_only=True)
class SlidingBeamScene(FemScene):
    """A beam sliding over two bilateral supports (``kind = "sliding_beam"``; Buffinton & Kane).

    Attributes
    ----------
    L : float
        Beam length, m.
    rho : float
        Mass per unit length, kg/m.
    EI : float
        Bending stiffness, N m^2.
    D : float
        Support spacing, m.
    tip_deflection : float
        Initial static deflection of the tracked end, m.
    """

    KIND: ClassVar[str] = "sliding_beam"

    driven_end: Literal["H", "E"] = "H"
    L: float = 1.0
    rho: float = 1.0
    EI: float = 1.0
    D: float = 0.25
    tip_deflection: float = 0.01


@dataclasses.dataclass(frozen=True, kw_only=True)
class _ModelFileScene(FemScene):
    """The keys of the scenes that name a model file (``rp_arm``, ``telescoping``).

    Attributes
    ----------
    model : str
        The model file, resolved to an absolute path.
    theta0_deg, rotation_deg : float
        Housing angle at ``t = 0`` and its change over ``T``, degrees.
    payload : float or None
        Tip mass replacing the model file's, kg (None: the file's).
    gravity : tuple of float or None
        ``(gx, gy)`` replacing the model file's, m/s^2 (None: the file's).
    """

    driven_end: Literal["H", "E"] = "E"
    model: str
    theta0_deg: float = 0.0
    rotation_deg: float = 0.0
    payload: float | None = None
    gravity: tuple[float, float] | None = None


@dataclasses.dataclass(frozen=True)
class RPDrive:
    """The ``[drive]`` table of an ``rp_arm`` scene.

    Attributes
    ----------
    kind : {"motion", "force"}
        ``"motion"``: ``theta(t)``, ``W(t)`` prescribed by Eq 57; ``"force"``: joint torque and
        axial force prescribed (full coupling).
    coupling : {"partial", "full"}
        Eq 42 or Eq 43; a force drive is always ``"full"``.
    torque_amplitude : float
        Force drive only: amplitude of ``tau = A sin(2 pi t / T)`` on ``[0, T]``, N m.
    force_amplitude : float
        Force drive only: amplitude of the axial force at E, same shape, N.
    """

    kind: Literal["motion", "force"] = "motion"
    coupling: Literal["partial", "full"] = "partial"
    torque_amplitude: float = 0.0
    force_amplitude: float = 0.0

    def settings(self) -> dict[str, Any]:
        """Plain data as in ``summary.json`` (the amplitudes only for a force drive)."""
        out: dict[str, Any] = {"kind": self.kind, "coupling": self.coupling}
        if self.kind == "force":
            out.update(torque_amplitude=self.torque_amplitude, force_amplitude=self.force_amplitude)
        return out


@dataclasses.dataclass(frozen=True, kw_only=True)
class RPArmScene(_ModelFileScene):
    """The revolute-prismatic arm (``kind = "rp_arm"``; Pan et al. Figs 1, 4).

    Attributes
    ----------
    initial : {"rest", "static_load"}
        Start undeformed, or from the static deflection under a uniform load scaled to
        ``tip_deflection``.
    tip_deflection : float
        Initial deflection of the tracked end with ``initial = "static_load"``, m.
    drive : RPDrive
        Prescribed motion (partial or full coupling) or prescribed torque and force.
    model_spec : RPArmSpec
        The model file, read at load time, with ``payload`` and ``gravity`` applied.
    """

    KIND: ClassVar[str] = "rp_arm"

    initial: Literal["rest", "static_load"] = "rest"
    tip_deflection: float = 0.01
    drive: RPDrive = RPDrive()
    model_spec: RPArmSpec = dataclasses.field(metadata=_NOT_A_SETTING)


@dataclasses.dataclass(frozen=True, kw_only=True)
class TelescopingScene(_ModelFileScene):
    """Two flexible links sliding on each other (``kind = "telescoping"``; Pan et al. Fig 5).

    ``W`` is the overhang of the inner tip beyond the outer link's mouth, ``n_elements`` applies to
    each link and ``driven_end`` is ``"E"``.

    Attributes
    ----------
    model_spec : TelescopingSpec
        The model file, read at load time (the contacts checked over the stroke), with
        ``payload`` and ``gravity`` applied.
    """

    KIND: ClassVar[str] = "telescoping"

    model_spec: TelescopingSpec = dataclasses.field(metadata=_NOT_A_SETTING)


#: Any finite-element scene.
AnyFemScene = SlidingBeamScene | RPArmScene | TelescopingScene
SCENE_CLASSES: dict[str, type[FemScene]] = {
    c.KIND: c for c in (SlidingBeamScene, RPArmScene, TelescopingScene)
}


def _plain(value: Any) -> Any:
    if isinstance(value, RPDrive):
        return value.settings()
    if isinstance(value, tuple):
        return list(value)
    return value


def fem_elements(value: Any, kind: str, origin: str) -> int:
    """The element count of a ``fem:N`` fidelity; :class:`SpecError` for any other."""
    fid = parse_fidelity(value, source=origin, key="fidelity")
    if fid.kind != "fem":
        raise SpecError(
            f"value '{fid}' does not apply to '{kind}' scenes; allowed: 'fem:N' (N elements)",
            source=origin,
            key="fidelity",
        )
    return int(fid.count or 0)
