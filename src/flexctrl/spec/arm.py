"""Robot-arm descriptions (``models/*.toml``) as frozen, validated dataclasses.

Units are SI everywhere (m, kg, s, N), except angles: files and the command line
take degrees, the Python API radians.  :func:`load_arm` is the one place where a
model file is validated; it returns a complete :class:`ArmSpec` or raises a
:class:`~flexctrl.errors.SpecError` naming the file, the key, the value and what
is allowed.

File layout (see ``models/subedi3link.toml`` for a documented example)::

    name = "..."                     # free text
    gravity = [0.0, -9.81]           # m/s^2, world frame
    configuration = [0, 0, 0]        # default joint angles, degrees
    boundary_inertia = "exact"       # or "paper" (see flexctrl.modal.boundary)
    damping_form = "ratio"           # or "paper": modal damping d = 2 zeta omega m_l, or Subedi
                                     # et al.'s Eq 68 as printed, d = 2 zeta omega, or "stiffness":
                                     # the finite elements' (2 zeta / omega_1) K, or "modal": every
                                     # coupled mode of the arm at its configuration damped to
                                     # damping_zeta (flexctrl.spec.damping)
    damping_zeta = 0.01              # with damping_form = "modal": the damping ratio of every
                                     # coupled elastic mode (the links' damping_ratio unused)
    axial_shortening = true          # a bent link's foreshortening; default: on for finite
                                     # elements, off for assumed modes
                                     # (docs/explanation/assumed-modes.md)
    axial_stretch = true             # axially compliant assumed-modes links (EA; default
                                     # off; finite elements always are;
                                     # docs/explanation/assumed-modes.md)
    [payload]  mass (kg), inertia (kg m^2 about its centre of mass)
    [[links]]  length (m), mass_per_length (kg/m), EI (N m^2), inertia
               (kg m^2 about the link's centre of mass), n_modes (0..6),
               damping_ratio (scalar or list per mode), optional EA (N),
               optional [links.section] {width, height, thickness} (m)
    [[joints]] type ("revolute"), hub_mass (kg), hub_inertia (kg m^2),
               friction (N m s/rad), torque_limit (N m; required: ``inf`` written out
               for an actuator without a limit)

A link without ``inertia`` gets the uniform link's ``mass_per_length * length**3 / 12``;
a given value further than :data:`INERTIA_FACTOR` from it warns.

Every table may carry a free-text ``source`` naming where its numbers come from.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from flexctrl.errors import SpecError, keyword_checked, keywords_checked, warn_spec
from flexctrl.spec import shipped
from flexctrl.spec.damping import DampingForm, damping_summary, read_damping
from flexctrl.spec.overrides import apply_overrides
from flexctrl.spec.reader import TableReader, read_toml

MAX_MODES = 6
#: A link's ``inertia`` further than this factor from the uniform link's
#: ``mass_per_length * length**3 / 12`` warns (a slip of a unit or of the axis: about the link's
#: end it would be 4x).
INERTIA_FACTOR = 2.0
JointType = Literal["revolute", "prismatic"]
BoundaryInertia = Literal["exact", "paper"]
JOINT_TYPES: tuple[JointType, ...] = ("revolute", "prismatic")
BOUNDARY_INERTIA: tuple[BoundaryInertia, ...] = ("exact", "paper")


@keywords_checked
@dataclass(frozen=True)
class SectionSpec:
    """Hollow rectangular cross-section; used to derive the axial stiffness EA.

    Attributes
    ----------
    width : float
        Outer width (m).
    height : float
        Outer height (m), in the bending direction.
    thickness : float
        Wall thickness (m), less than half the width and the height.
    """

    width: float
    height: float
    thickness: float

    @property
    def area(self) -> float:
        """Cross-sectional area (m^2)."""
        inner_w, inner_h = self.width - 2 * self.thickness, self.height - 2 * self.thickness
        return self.width * self.height - inner_w * inner_h

    @property
    def second_moment(self) -> float:
        """Second moment of area about the bending axis (m^4), bending in the height direction."""
        inner_w, inner_h = self.width - 2 * self.thickness, self.height - 2 * self.thickness
        return (self.width * self.height**3 - inner_w * inner_h**3) / 12.0


@keywords_checked
@dataclass(frozen=True)
class LinkSpec:
    """One flexible link (Euler-Bernoulli beam).

    Attributes
    ----------
    length : float
        Length (m).
    mass_per_length : float
        Mass per unit length rho (kg/m).
    EI : float
        Flexural rigidity (N m^2).
    inertia : float
        Moment of inertia about the link's centre of mass, rigid (kg m^2); in a file,
        ``mass_per_length * length**3 / 12`` (the uniform link) when absent.
    n_modes : int
        Assumed modes used by default (0..6).
    damping_ratios : tuple of float
        Modal damping ratio per mode (dimensionless); one value is used for all modes.
    EA : float or None
        Axial stiffness (N); derived from ``section`` when absent.
    section : SectionSpec or None
        Cross-section, for the axial stiffness.
    source : str
        Provenance note.
    """

    length: float
    mass_per_length: float
    EI: float
    inertia: float
    n_modes: int
    damping_ratios: tuple[float, ...]
    EA: float | None = None
    section: SectionSpec | None = None
    source: str = ""

    @property
    def mass(self) -> float:
        """Link mass rho L (kg)."""
        return self.mass_per_length * self.length

    def damping_ratio(self, mode: int) -> float:
        """Damping ratio of mode ``mode`` (0-based); a single value applies to all modes."""
        if len(self.damping_ratios) == 1:
            return self.damping_ratios[0]
        if mode >= len(self.damping_ratios):
            raise SpecError(
                f"damping_ratio lists {len(self.damping_ratios)} values but mode {mode + 1} was "
                "asked for; "
                "give one value per mode or a single value for all"
            )
        return self.damping_ratios[mode]

    def axial_stiffness(self) -> float:
        """EA (N): the file's value, or E A with E = EI / I of the section.

        Raises
        ------
        SpecError
            If neither ``EA`` nor ``section`` is given.
        """
        if self.EA is not None:
            return self.EA
        if self.section is None:
            raise SpecError("link has neither 'EA' nor a 'section' to derive it from")
        youngs = self.EI / self.section.second_moment
        return youngs * self.section.area


@keywords_checked
@dataclass(frozen=True)
class JointSpec:
    """A joint at the base of a link, with its hub (motor housing) as a rigid body.

    Attributes
    ----------
    type : {"revolute", "prismatic"}
        The joint's motion.
    hub_mass : float
        Hub mass (kg), located on the joint axis.
    hub_inertia : float
        Hub moment of inertia about the joint axis (kg m^2).
    friction : float
        Viscous joint friction b (N m s/rad).
    torque_limit : float
        Actuator limit (N m), +inf when unlimited.
    source : str
        Provenance note.
    """

    type: JointType
    hub_mass: float
    hub_inertia: float
    friction: float
    torque_limit: float
    source: str = ""


@keywords_checked
@dataclass(frozen=True)
class PayloadSpec:
    """Payload at the tip of the last link.

    ``inertia`` belongs to the payload: it is carried only when ``mass > 0`` (Table 3 of
    Subedi et al. treats the no-payload link 3 as a plain clamped-free beam).

    Attributes
    ----------
    mass : float
        Payload mass (kg), >= 0.
    inertia : float
        Moment of inertia about its centre of mass (kg m^2).
    source : str
        Provenance note.
    """

    mass: float
    inertia: float
    source: str = ""

    @property
    def effective_inertia(self) -> float:
        """Inertia actually carried (kg m^2): zero without a payload mass."""
        return self.inertia if self.mass > 0.0 else 0.0


@keywords_checked
@dataclass(frozen=True)
class ArmSpec:
    """A planar serial arm with flexible links.

    Attributes
    ----------
    name : str
        Model name (default: the file's stem).
    links : tuple of LinkSpec
        The links, base to tip.
    joints : tuple of JointSpec
        ``joints[i]`` sits at the base of ``links[i]``.
    payload : PayloadSpec
        At the tip of the last link.
    gravity : tuple of float
        Gravity vector in the world frame, ``(gx, gy)`` (m/s^2).
    configuration : tuple of float
        Default joint angles (rad).
    boundary_inertia : {"exact", "paper"}
        How the tip inertia J_D of the clamped-mass boundary is formed.
    damping_form : {"ratio", "paper", "stiffness", "modal"}
        How the modal damping coefficient is formed: per clamped-mass mode from the links'
        ``damping_ratio`` (the first three), or on the coupled modes from ``damping_zeta``
        (see :data:`flexctrl.spec.damping.DAMPING_FORMS`).
    damping_zeta : float or None
        With ``damping_form = "modal"``: the damping ratio of every coupled elastic mode at
        the arm's configuration (required then, refused otherwise).
    axial_shortening : bool or None
        Whether the models carry a bent link's axial shortening (assumed modes: second-order
        kinematics, ``docs/explanation/assumed-modes.md`` section 10; finite elements: membrane
        strain).  None (not in the file): each family's default, on for finite elements, off for
        assumed modes (:data:`flexctrl.dynamics.amm.AMM_AXIAL_SHORTENING`).
    axial_stretch : bool or None
        Whether assumed-modes links are axially compliant (one elongation coordinate per link,
        strain energy from ``EA``; ``docs/explanation/assumed-modes.md`` section 14).  None: off
        (:data:`flexctrl.dynamics.amm.AMM_AXIAL_STRETCH`).  Finite-element links always are;
        ``False`` with a finite-element fidelity is refused when the model is built.
    source : str
        The file it was loaded from.
    notes : str
        Free text from the file.
    """

    name: str
    links: tuple[LinkSpec, ...]
    joints: tuple[JointSpec, ...]
    payload: PayloadSpec
    gravity: tuple[float, float]
    configuration: tuple[float, ...]
    boundary_inertia: BoundaryInertia = "exact"
    damping_form: DampingForm = "ratio"
    damping_zeta: float | None = None
    source: str = ""
    notes: str = ""
    axial_shortening: bool | None = None
    axial_stretch: bool | None = None

    @property
    def n_links(self) -> int:
        """Number of links."""
        return len(self.links)

    def damping_summary(self, form: str | None = None) -> dict[str, Any]:
        """The damping as a run's summary records it: the form (``form`` if the model was built
        with another than the file's) and its numbers, ``damping_zeta`` on the coupled modes or
        each link's ``damping_ratio`` per clamped-mass mode."""
        return damping_summary(self, form)

    def with_payload(self, mass: float) -> ArmSpec:
        """A copy carrying a payload of ``mass`` kg (the inertia is kept)."""
        if not (math.isfinite(mass) and mass >= 0.0):
            raise SpecError(
                f"payload mass {mass!r} is not allowed; allowed: a finite number >= 0 (kg)",
                key="payload.mass",
            )
        return dataclasses.replace(
            self, payload=dataclasses.replace(self.payload, mass=float(mass))
        )

    def with_modes(self, n_modes: int) -> ArmSpec:
        """A copy with ``n_modes`` assumed modes on every link."""
        if not 0 <= n_modes <= MAX_MODES:
            raise SpecError(
                f"mode count {n_modes!r} is not allowed; allowed: 0 to {MAX_MODES}", key="n_modes"
            )
        return dataclasses.replace(
            self, links=tuple(dataclasses.replace(l, n_modes=n_modes) for l in self.links)
        )

    def configuration_or_default(self, q: Iterable[float] | None) -> np.ndarray:
        """Joint angles (rad) as an array: ``q`` if given (checked), else the file's default."""
        if q is None:
            return np.array(self.configuration, dtype=float)
        arr = np.asarray(list(q), dtype=float)
        if arr.shape != (self.n_links,):
            raise SpecError(
                f"configuration has {arr.size} angles; expected {self.n_links} (one per joint)",
                key="q",
            )
        if not np.all(np.isfinite(arr)):
            raise SpecError(f"configuration {arr.tolist()} is not finite", key="q")
        return arr


def _read_link(r: TableReader) -> LinkSpec:
    section = None
    if r.has("section"):
        s = r.table_of("section")
        section = SectionSpec(
            s.positive("width", unit="m"),
            s.positive("height", unit="m"),
            s.positive("thickness", unit="m"),
        )
        s.finish()
        if 2 * section.thickness >= min(section.width, section.height):
            raise r.error(
                "section.thickness",
                f"value {section.thickness!r} leaves no hollow; allowed: < half the width and "
                "height",
            )
    damping = r.raw("damping_ratio", 0.0)
    if isinstance(damping, list):
        ratios = r.numbers("damping_ratio", low=0.0, high=10.0)
        if not ratios:
            raise r.error("damping_ratio", "empty list; allowed: one value, or one per mode")
    else:
        ratios = (r.number("damping_ratio", 0.0, low=0.0, high=10.0),)
    link = LinkSpec(
        length=r.positive("length", unit="m"),
        mass_per_length=r.positive("mass_per_length", unit="kg/m"),
        EI=r.positive("EI", unit="N m^2"),
        inertia=_link_inertia(r),
        n_modes=r.integer("n_modes", 2, low=0, high=MAX_MODES),
        damping_ratios=ratios,
        EA=r.positive("EA", unit="N") if r.has("EA") else None,
        section=section,
        source=r.string("source", ""),
    )
    if len(ratios) > 1 and len(ratios) < link.n_modes:
        raise r.error(
            "damping_ratio",
            f"lists {len(ratios)} values for {link.n_modes} modes; allowed: one value, or one per "
            "mode",
        )
    r.finish()
    return link


def _link_inertia(r: TableReader) -> float:
    """The file's ``inertia``, else the uniform link's; a value far from the uniform one warns."""
    length, rho = r.positive("length", unit="m"), r.positive("mass_per_length", unit="kg/m")
    uniform = rho * length**3 / 12.0
    if not r.has("inertia"):
        return uniform
    value = r.nonnegative("inertia", unit="kg m^2")
    if not uniform / INERTIA_FACTOR <= value <= uniform * INERTIA_FACTOR:
        warn_spec(
            f"value {value!r} kg m^2 is {value / uniform:.3g} times mass_per_length * length^3 "
            f"/ 12 = {uniform:.4g} kg m^2 (the uniform link about its centre of mass); expected "
            f"within a factor {INERTIA_FACTOR:g} of it (leave the key out to use the uniform "
            "value)",
            source=r.source,
            key=r.key("inertia"),
            stacklevel=4,
        )
    return value


def _torque_limit(r: TableReader) -> float:
    """``torque_limit``: required, > 0 (N m), or ``inf`` written out for an unlimited actuator."""
    allowed = (
        "a finite number > 0 (N m), or inf for an actuator without a limit (written out: no "
        "default)"
    )
    value = r.raw("torque_limit", allowed=allowed)
    if isinstance(value, float) and value == math.inf:
        return math.inf
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise r.error("torque_limit", f"value {value!r} is not a number; allowed: {allowed}")
    if not (math.isfinite(value) and value > 0):
        raise r.error("torque_limit", f"value {value!r} is out of range; allowed: {allowed}")
    return float(value)


def _read_joint(r: TableReader) -> JointSpec:
    joint = JointSpec(
        type=r.choice("type", JOINT_TYPES, "revolute"),
        hub_mass=r.nonnegative("hub_mass", unit="kg"),
        hub_inertia=r.nonnegative("hub_inertia", unit="kg m^2"),
        friction=r.nonnegative("friction", 0.0, unit="N m s/rad"),
        torque_limit=_torque_limit(r),
        source=r.string("source", ""),
    )
    r.finish()
    return joint


def arm_from_document(document: dict, source: str) -> ArmSpec:
    """Validate a parsed model document into an :class:`ArmSpec` (see module docstring)."""
    r = TableReader(document, source)
    links = tuple(_read_link(t) for t in r.tables("links", min_count=1))
    joints = tuple(_read_joint(t) for t in r.tables("joints", min_count=1))
    if len(joints) != len(links):
        raise r.error(
            "joints",
            f"has {len(joints)} entries for {len(links)} links; allowed: one joint per link",
        )
    p = r.table_of("payload", {})
    payload = PayloadSpec(
        p.nonnegative("mass", 0.0, unit="kg"),
        p.nonnegative("inertia", 0.0, unit="kg m^2"),
        p.string("source", ""),
    )
    p.finish()
    gravity = r.numbers("gravity", [0.0, -9.81], length=2, unit="m/s^2")
    config_deg = r.degrees("configuration", [0.0] * len(links), length=len(links))
    form, zeta = read_damping(r)
    arm = ArmSpec(
        name=r.string("name", Path(source).stem),
        links=links,
        joints=joints,
        payload=payload,
        gravity=(gravity[0], gravity[1]),
        configuration=tuple(math.radians(a) for a in config_deg),
        boundary_inertia=r.choice("boundary_inertia", BOUNDARY_INERTIA, "exact"),
        damping_form=form,
        damping_zeta=zeta,
        axial_shortening=r.boolean("axial_shortening", True) if r.has("axial_shortening") else None,
        axial_stretch=r.boolean("axial_stretch", True) if r.has("axial_stretch") else None,
        source=source,
        notes=r.string("notes", ""),
    )
    r.finish()
    return arm


@keyword_checked
def load_arm(path: str | Path, overrides: Iterable[str] = ()) -> ArmSpec:
    """Load and validate a model file.

    Parameters
    ----------
    path
        A ``models/*.toml`` file.
    overrides
        ``KEY=VALUE`` strings applied before validation (``--set`` on the CLI).

    Returns
    -------
    ArmSpec
        The complete, validated description.

    Raises
    ------
    SpecError
        Naming the file, key, value and what is allowed.
    """
    path = shipped.find(path, "model")
    document = read_toml(path)
    document = apply_overrides(document, overrides, source=f"{path} (--set)")
    return arm_from_document(document, str(path))
