"""Build a :class:`~flexctrl.dynamics.model.Model` from an arm description and a fidelity.

>>> from flexctrl.dynamics.build import build_model
>>> from flexctrl.spec.arm import load_arm
>>> model = build_model(load_arm("models/subedi3link.toml"), "amm:1")
>>> model.coordinate_names
('q1', 'q2', 'q3', 'qf11', 'qf21', 'qf31')
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np

from flexctrl.dynamics.amm import build_amm
from flexctrl.dynamics.fem.fem_arm import build_fem_model
from flexctrl.dynamics.model import Model
from flexctrl.errors import FlexctrlError, SpecError, keyword_checked
from flexctrl.spec.arm import ArmSpec
from flexctrl.spec.fidelity import Fidelity, parse_fidelity


class ModelFamilyUnavailable(FlexctrlError, NotImplementedError):
    """The requested model family cannot be built here (yet)."""


@keyword_checked
def build_model(
    arm: ArmSpec,
    fidelity: str | Fidelity | None = "amm:2",
    *,
    modes: Literal["frozen", "scheduled"] = "frozen",
    reference_q: Sequence[float] | np.ndarray | None = None,
    damping: Literal["ratio", "paper", "stiffness"] | None = None,
) -> Model:
    """Build the model of ``arm`` at ``fidelity``.

    Parameters
    ----------
    arm
        Validated arm description.
    fidelity
        ``"rigid"`` (same as ``"amm:0"``), ``"amm:N"`` (N assumed modes on every
        link), ``"fem:N"`` (N finite elements per link,
        :func:`flexctrl.dynamics.fem.fem_arm.build_fem_model`), or None for each link's
        ``n_modes`` from the file.  ``"auto"`` is resolved per scene, not here.
    modes
        ``"frozen"`` or ``"scheduled"`` modal parameters
        (see :mod:`flexctrl.dynamics.amm`).
    reference_q
        Joint angles (rad) of the frozen modes and of ``Model.omega_max``;
        default the arm's ``configuration``.
    damping
        ``"ratio"`` (d = 2 zeta omega m_l), ``"paper"`` (Eq 68 as printed) or ``"stiffness"``
        (the finite elements' ``(2 zeta / omega_1) K``, which is all they have); default
        (None): the arm's ``damping_form``.

    Raises
    ------
    SpecError
        For an unknown fidelity or option.
    ModelFamilyUnavailable
        For ``auto``, and for ``modes="scheduled"`` with ``fem:N``.
    """
    if fidelity is None:
        return build_amm(
            arm,
            [link.n_modes for link in arm.links],
            modes=modes,
            reference_q=reference_q,
            damping=damping,
        )
    fid = fidelity if isinstance(fidelity, Fidelity) else parse_fidelity(fidelity)
    if fid.kind == "fem":
        return _build_fem(arm, fid, modes=modes, reference_q=reference_q, damping=damping)
    if fid.kind == "auto":
        raise ModelFamilyUnavailable(
            "fidelity 'auto' is resolved per scene from an accuracy tolerance, not by build_model: "
            "run the scene (fidelity = 'auto' with tolerance = METRES), `flexctrl fidelity SCENE "
            "--tol METRES` or flexctrl.scenes.auto.choose_fidelity; here give 'rigid', "
            "'amm:N' or 'fem:N'"
        )
    modes_per_link = fid.modes_per_link
    if modes_per_link is None:
        raise SpecError(
            f"fidelity {fid} has no mode count; allowed: 'rigid', 'amm:N' or 'fem:N'",
            key="fidelity",
        )
    return build_amm(
        arm, modes_per_link, modes=modes, reference_q=reference_q, damping=damping, fidelity=fid
    )


def _build_fem(
    arm: ArmSpec,
    fid: Fidelity,
    *,
    modes: str,
    reference_q: Sequence[float] | np.ndarray | None,
    damping: str | None,
) -> Model:
    """The finite-element model of ``arm`` at ``fid`` (``fem:N``), its options checked."""
    if modes != "frozen":
        raise ModelFamilyUnavailable(
            f"modes '{modes}' applies to assumed modes only; a finite-element model has no "
            "mode option"
        )
    if (arm.damping_form if damping is None else damping) == "modal":
        raise ModelFamilyUnavailable(
            "damping form 'modal' (damping_zeta on the coupled modes) applies to assumed modes "
            "only; a finite-element model takes its damping from damping_ratio "
            "stiffness-proportionally (use an 'amm:N' fidelity, or damping form 'ratio' or "
            "'stiffness')"
        )
    if (arm.damping_form if damping is None else damping) == "paper":
        raise ModelFamilyUnavailable(
            "damping form 'paper' (Eq 68 of Subedi et al. as printed) applies to assumed "
            "modes only; a finite-element model takes its damping from damping_ratio "
            "stiffness-proportionally, (2 zeta / omega_1) K (use damping form 'ratio' or "
            "'stiffness', or an 'amm:N' fidelity)"
        )
    if arm.axial_stretch is False:
        raise SpecError(
            "axial_stretch = false is not allowed with a finite-element fidelity: its links are "
            "always axially compliant (EA); allowed: true or unset, or an 'amm:N' fidelity",
            key="axial_stretch",
        )
    if fid.count is None:
        raise SpecError(f"fidelity {fid} has no element count; allowed: 'fem:N'", key="fidelity")
    # membrane strain, validated
    shortening = True if arm.axial_shortening is None else arm.axial_shortening
    return build_fem_model(arm, fid.count, reference_q=reference_q, axial_shortening=shortening)
