"""Model files of the finite-element arms with moving supports: ``rp_arm``, ``telescoping``.

The files are ``models/rp_arm.toml`` and ``models/telescoping.toml``.

Plain descriptions, read and validated here and simulated by
:mod:`flexctrl.dynamics.fem.rp_arm`, :mod:`flexctrl.dynamics.fem.rp_arm_full` and
:mod:`flexctrl.dynamics.fem.telescoping` (Pan, Scott & Ulsoy 1990, Figs 1, 4 and 5).
Neither is an :class:`~flexctrl.spec.arm.ArmSpec`.  SI units throughout.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from flexctrl.errors import SpecError
from flexctrl.spec import shipped
from flexctrl.spec.overrides import apply_overrides
from flexctrl.spec.reader import TableReader, read_toml

Array = NDArray[np.float64]
#: The two links of a telescoping pair, in the order of the model file.
SIDES: tuple[Literal["outer", "inner"], ...] = ("outer", "inner")
#: The prismatic joints of an R-P arm (Pan et al. 1990): two bilateral supports in the housing, or
#: the link clamped at its inner end E in the carriage and held by one bearing at the housing mouth
#: (Fig 4).
JOINTS: tuple[Literal["supports", "clamped"], ...] = ("supports", "clamped")


# -- the revolute-prismatic arm
# ---------------------------------------------------------------------
@dataclass(frozen=True)
class RPArmSpec:
    """An R-P arm (``models/rp_arm.toml``): a flexible link sliding through a rotating housing.

    Attributes
    ----------
    name : str
        Model name (default: the file's stem).
    length : float
        Length of the sliding link, m.
    mass_per_length : float
        Mass per unit length of the link, kg/m.
    EI : float
        Bending stiffness of the link, N m^2.
    support_inner, support_outer : float
        Radii of the two bilateral supports from the base axis, m
        (``support_inner < support_outer``).
        With ``joint = "clamped"`` ``support_outer`` is the mouth bearing D' and ``support_inner``
        the outboard end of the carriage's travel (E stays inboard of it).
    joint : {"supports", "clamped"}
        ``"supports"``: the link slides through two bilateral supports (Eqs 24-25 twice), driven at
        an end.  ``"clamped"``: Pan's Fig 4, the link clamped at its inner end E in the carriage
        (Eqs 22-23: ``w(0) = w'(0) = 0``) and held transversely at the mouth D' (Eq 24).
    payload_mass : float
        Point mass at the tip H, kg.
    gravity : tuple of float
        Gravity ``(gx, gy)`` in the plane of motion, world frame, m/s^2.
    hub_inertia : float
        Housing and rotor inertia about joint 1, kg m^2: not used by the prescribed-motion
        model, recorded for torque estimates and used by full coupling.
    carriage_mass : float
        Mass of the axial drive at E, kg (full coupling).
    source : str
        The file the description was read from.
    notes : str
        Free text of the file.
    """

    name: str
    length: float
    mass_per_length: float
    EI: float
    support_inner: float
    support_outer: float
    payload_mass: float = 0.0
    gravity: tuple[float, float] = (0.0, 0.0)
    hub_inertia: float = 0.0
    carriage_mass: float = 0.0
    joint: Literal["supports", "clamped"] = "supports"
    source: str = ""
    notes: str = ""

    @property
    def D(self) -> float:
        """Support spacing, m."""
        return self.support_outer - self.support_inner


def rp_arm_from_document(document: dict, source: str) -> RPArmSpec:
    """Validate a parsed ``rp_arm`` model document (layout: ``models/rp_arm.toml``).

    Raises
    ------
    SpecError
        Naming the file, the key, the value and what is allowed.
    """
    r = TableReader(document, source)
    r.string("kind", "rp_arm", choices=("rp_arm",))
    link = r.table_of("link")
    length = link.positive("length", unit="m")
    rho = link.positive("mass_per_length", unit="kg/m")
    EI = link.positive("EI", unit="N m^2")
    link.string("source", "")
    link.finish()
    housing = r.table_of("housing")
    r1 = housing.nonnegative("support_inner", unit="m")
    r2 = housing.positive("support_outer", unit="m")
    housing.string("source", "")
    joint = housing.choice("joint", JOINTS, "supports")
    if not r2 > r1:
        raise housing.error(
            "support_outer", f"value {r2!r} is not beyond support_inner = {r1!r}; allowed: > {r1} m"
        )
    if r2 - r1 >= length:
        raise housing.error(
            "support_outer",
            f"support spacing {r2 - r1:g} m leaves no stroke on a {length:g} m link; "
            f"allowed: spacing < {length} m",
        )
    housing.finish()
    hub_inertia, carriage_mass, m_t = _drive_masses(r)
    gravity = r.numbers("gravity", [0.0, 0.0], length=2, unit="m/s^2")
    spec = RPArmSpec(
        name=r.string("name", Path(source).stem),
        length=length,
        mass_per_length=rho,
        EI=EI,
        support_inner=r1,
        support_outer=r2,
        payload_mass=m_t,
        gravity=(gravity[0], gravity[1]),
        hub_inertia=hub_inertia,
        carriage_mass=carriage_mass,
        joint=joint,
        source=source,
        notes=r.string("notes", ""),
    )
    r.finish()
    return spec


def _drive_masses(r: TableReader) -> tuple[float, float, float]:
    """The optional ``[base] hub_inertia`` (kg m^2), ``[carriage] mass``, ``[payload] mass``."""
    values = []
    for table, key, unit in (
        ("base", "hub_inertia", "kg m^2"),
        ("carriage", "mass", "kg"),
        ("payload", "mass", "kg"),
    ):
        t = r.table_of(table, {})
        values.append(t.nonnegative(key, 0.0, unit=unit))
        t.string("source", "")
        t.finish()
    return values[0], values[1], values[2]


def load_rp_arm(path: str | Path, overrides: Iterable[str] = ()) -> RPArmSpec:
    """Load and validate ``models/rp_arm.toml`` (``overrides``: ``KEY=VALUE`` strings)."""
    path = shipped.find(path, "model")
    document = apply_overrides(read_toml(path), overrides, source=f"{path} (--set)")
    return rp_arm_from_document(document, str(path))


# -- the telescoping pair
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Contact:
    """A bearing between the two links of a telescoping pair (Eqs 26-28).

    Attributes
    ----------
    on : {"outer", "inner"}
        The link the bearing is fixed on; the other link slides through it.
    at : float
        Material coordinate of the bearing along that link, m.
    slope : bool
        Also equate the slopes of the two links there (Eq 28).
    """

    on: Literal["outer", "inner"]
    at: float
    slope: bool = False


@dataclass(frozen=True)
class LinkProps:
    """A uniform link: ``length`` (m), ``mass_per_length`` (kg/m), ``EI`` (N m^2)."""

    length: float
    mass_per_length: float
    EI: float


@dataclass(frozen=True)
class TelescopingSpec:
    """A telescoping pair (``models/telescoping.toml``): an inner flexible link in an outer one.

    Attributes
    ----------
    name : str
        Model name (default: the file's stem).
    outer, inner : LinkProps
        The tube clamped to the hub (link i-1) and the link sliding inside it (link i).
    contacts : tuple of Contact
        The bearings coupling them (at least two constraint rows).
    hub_radius : float
        Radius of the outer link's clamped root from joint 1, m.
    payload_mass : float
        Point mass at the inner tip H, kg.
    gravity : tuple of float
        Gravity ``(gx, gy)`` in the plane of motion, world frame, m/s^2.
    hub_inertia : float
        Hub and rotor inertia about joint 1, kg m^2 (full coupling; ``[base]``).
    carriage_mass : float
        Mass of the axial drive at the inner root E, kg (full coupling; ``[carriage]``).
    source, notes : str
        The file read and its free text.
    """

    name: str
    outer: LinkProps
    inner: LinkProps
    contacts: tuple[Contact, ...]
    hub_radius: float = 0.0
    payload_mass: float = 0.0
    gravity: tuple[float, float] = (0.0, 0.0)
    hub_inertia: float = 0.0
    carriage_mass: float = 0.0
    source: str = ""
    notes: str = ""

    def contact_points(self, s: float) -> tuple[Array, Array]:
        """Material coordinates ``(x1_k, x2_k)`` (m) of the contacts, E at tube coordinate ``s``.

        ``s`` in m.
        """
        x1 = np.array([c.at if c.on == "outer" else c.at + s for c in self.contacts])
        x2 = np.array([c.at - s if c.on == "outer" else c.at for c in self.contacts])
        return x1, x2

    def check_stroke(self, s_values: Iterable[float], key: str = "C1") -> None:
        """Raise :class:`SpecError` unless every contact stays on both links for these ``s`` (m)."""
        L1, L2 = self.outer.length, self.inner.length
        for s in s_values:
            x1, x2 = self.contact_points(s)
            for k, c in enumerate(self.contacts):
                if not (0.0 < x1[k] <= L1 + 1e-12 and -1e-12 <= x2[k] <= L2 + 1e-12):
                    raise SpecError(
                        f"with E at s = {s:g} m in the outer link (W = {s - L1 + L2:g} m) contact "
                        f"{k + 1} (on {c.on} at {c.at:g} m) sits at x1 = {x1[k]:g} m, "
                        f"x2 = {x2[k]:g} m; allowed: 0 < x1 <= L1 = {L1:g} m and "
                        f"0 <= x2 <= L2 = {L2:g} m (the contact on both links, off the clamped "
                        "root)",
                        source=self.source or None,
                        key=key,
                    )


def telescoping_from_document(document: dict, source: str) -> TelescopingSpec:
    """Validate a parsed ``telescoping`` model document (layout: ``models/telescoping.toml``).

    Raises
    ------
    SpecError
        Naming the file, the key, the value and what is allowed.
    """
    r = TableReader(document, source)
    r.string("kind", "telescoping", choices=("telescoping",))
    links = {}
    for side in SIDES:
        t = r.table_of(side)
        links[side] = LinkProps(
            t.positive("length", unit="m"),
            t.positive("mass_per_length", unit="kg/m"),
            t.positive("EI", unit="N m^2"),
        )
        t.string("source", "")
        t.finish()
    contacts = []
    for t in r.tables("contacts", min_count=1):
        on = t.choice("on", SIDES)
        limit = links[on].length
        contacts.append(
            Contact(
                on,
                t.number("at", low=0.0, high=limit, unit=f"m along the {on} link"),
                t.boolean("slope", False),
            )
        )
        t.finish()
    rows = sum(1 + c.slope for c in contacts)
    if rows < 2:
        raise r.error(
            "contacts",
            f"{len(contacts)} contact(s) give {rows} constraint(s); allowed: at least two "
            "contacts, or one with slope = true (Eqs 26-28), to hold the inner link",
        )
    if len(set(contacts)) != len(contacts):
        raise r.error("contacts", "two contacts are identical; allowed: distinct contacts")
    hub_inertia, carriage_mass, m_t = _drive_masses(r)
    gravity = r.numbers("gravity", [0.0, 0.0], length=2, unit="m/s^2")
    spec = TelescopingSpec(
        name=r.string("name", Path(source).stem),
        outer=links["outer"],
        inner=links["inner"],
        contacts=tuple(contacts),
        hub_radius=r.nonnegative("hub_radius", 0.0, unit="m"),
        payload_mass=m_t,
        gravity=(gravity[0], gravity[1]),
        hub_inertia=hub_inertia,
        carriage_mass=carriage_mass,
        source=source,
        notes=r.string("notes", ""),
    )
    r.finish()
    return spec


def load_telescoping(path: str | Path, overrides: Iterable[str] = ()) -> TelescopingSpec:
    """Load and validate ``models/telescoping.toml`` (``overrides``: ``KEY=VALUE`` strings)."""
    path = shipped.find(path, "model")
    document = apply_overrides(read_toml(path), overrides, source=f"{path} (--set)")
    return telescoping_from_document(document, str(path))
