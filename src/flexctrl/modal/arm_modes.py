"""Clamped-mass modes of every link of an arm at one configuration and payload."""

from __future__ import annotations

import numpy as np

from flexctrl.beam.clamped_mass import ClampedMassModes, clamped_mass_modes
from flexctrl.errors import SpecError, keyword_checked
from flexctrl.modal.boundary import boundary_values
from flexctrl.spec.arm import ArmSpec


def _arm_spec(arm) -> ArmSpec:
    """The :class:`ArmSpec` of ``arm``: itself, or a built model's ``spec``."""
    if isinstance(arm, ArmSpec):
        return arm
    spec = getattr(arm, "spec", None)
    if isinstance(spec, ArmSpec):
        return spec
    raise SpecError(
        f"value {type(arm).__name__} is not an arm; allowed: an ArmSpec (flexctrl.load_arm) or a "
        "Model built from one (flexctrl.load_model)",
        key="arm",
    )


def checked_link(arm: ArmSpec, link) -> int:
    """``link`` as a 0-based index of ``arm.links``, or a :class:`SpecError` naming the value,
    the allowed indices and the files' count from 1."""
    n = arm.n_links
    if isinstance(link, (bool, np.bool_)) or not isinstance(link, (int, np.integer)):
        raise SpecError(
            f"value {link!r} is not a link index; allowed: an integer 0..{n - 1}", key="link"
        )
    if not 0 <= int(link) < n:
        raise SpecError(
            f"value {link} is not a link of this {n}-link arm; allowed: 0..{n - 1} (Python "
            "counts links from 0; file keys and the command line count them from 1, "
            f"links[1]..links[{n}])",
            key="link",
        )
    return int(link)


@keyword_checked
def link_modes(
    arm, q: np.ndarray | None, link: int, n_modes: int | None = None, convention: str | None = None
) -> ClampedMassModes:
    """Clamped-mass modes of ``link`` (0-based) at joint angles ``q`` (rad).

    Each link is a clamped beam carrying the rest of the arm as a rigid tip body
    (Subedi et al. 2021, Eqs 28-40 and 69-73): these are the shapes the assumed-modes model
    is built on and the frequencies ``flexctrl modes`` prints, not the arm's vibration
    frequencies (:func:`flexctrl.locked_frequencies`, :func:`flexctrl.modal_summary`).

    Parameters
    ----------
    arm : ArmSpec or Model
        Arm description, or a model built from one (its ``spec``: payload and
        ``boundary_inertia``).
    q : array of float or None
        Joint angles (rad), shape (n,); None: the description's ``configuration``.
    link
        Link index, 0-based as Python indexes ``arm.links`` (file keys and the command line
        count links from 1: ``links[1]`` is ``link=0``); one outside ``0..n-1`` is a
        :class:`SpecError` naming both counts.
    n_modes
        Modes to compute (default: the link's ``n_modes``).
    convention
        ``"exact"`` or ``"paper"`` boundary inertia (default: the arm's).

    Examples
    --------
    >>> import flexctrl as fc
    >>> from flexctrl.modal.arm_modes import link_modes
    >>> model = fc.load_model("models/subedi3link.toml", payload=2.0, fidelity="amm:1")
    >>> spec = fc.load_arm("models/subedi3link.toml").with_payload(2.0)
    >>> from_model = link_modes(model, None, 2, 2).frequency_hz
    >>> bool((from_model.round(3) == link_modes(spec, None, 2, 2).frequency_hz.round(3)).all())
    True
    """
    arm = _arm_spec(arm)
    link = checked_link(arm, link)
    q = arm.configuration_or_default(q)
    spec = arm.links[link]
    bv = boundary_values(arm, np.asarray(q, dtype=float), link, convention)
    return clamped_mass_modes(
        spec.length,
        spec.mass_per_length,
        spec.EI,
        spec.n_modes if n_modes is None else n_modes,
        m_tip=float(bv.m),
        J_tip=float(bv.J),
        M_tip=float(bv.M),
    )


@keyword_checked
def arm_modes(
    arm, q: np.ndarray | None = None, n_modes: int | None = None, convention: str | None = None
) -> list[ClampedMassModes]:
    """Clamped-mass modes of every link, ordered from link 1 outward (see :func:`link_modes`).

    Parameters
    ----------
    arm : ArmSpec or Model
        Arm description, or a model built from one.
    q : array of float, optional
        Joint angles (rad); default the description's ``configuration``.
    n_modes : int, optional
        Modes per link (default: each link's ``n_modes``).
    convention : {"exact", "paper"}, optional
        Boundary inertia (default: the arm's).

    Returns
    -------
    list of ClampedMassModes
        ``frequency_hz`` (Hz) and the shapes of each link.
    """
    arm = _arm_spec(arm)
    return [link_modes(arm, q, i, n_modes, convention) for i in range(arm.n_links)]
