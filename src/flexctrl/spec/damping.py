"""How a model's damping is described: the forms, the file keys that choose one, and what a
run's summary records of it."""

from __future__ import annotations

from typing import Any, Literal

DampingForm = Literal["ratio", "paper", "stiffness", "modal"]
#: Modal damping forms (``damping_form`` in model files, ``[damping] form`` in scenes,
#: ``damping=`` in :func:`flexctrl.dynamics.build.build_model`).  ``"ratio"``:
#: ``d = 2 zeta omega m_l`` (kg/s), so ``zeta`` is the damping ratio of the isolated mode
#: (modes normalised to the link mass, Eq 40, have modal mass ``m_l``).  ``"paper"``: Subedi
#: et al. (2021) Eq 68 as printed, ``d = 2 zeta sqrt(k/m_l) = 2 zeta omega`` (unit 1/s where a
#: modal force needs kg/s; it acts as the damping ratio ``zeta / m_l``).  ``"stiffness"``: the
#: finite elements' stiffness-proportional rule ``D_i = (2 zeta_i / omega_1i) K_i`` per link
#: (``zeta_i`` the link's first ratio, ``omega_1i`` its first clamped-mass frequency), i.e. mode j
#: of link i has the ratio ``zeta_i omega_j / omega_1i``: with it both families damp alike
# : (``docs/explanation/assumed-modes.md`` section 14).  The first three form the damping per
# clamped-mass mode of
#: each link (Eq 68's form), which is not the damping of the arm's coupled modes: on the shipped
#: arm ``"ratio"`` with 0.01 gives its linearisation's poles zeta 0.05-0.36.  ``"modal"``: the
#: damping ratio ``damping_zeta`` on every coupled elastic mode of the arm at its
#: configuration (joints free, no gravity), ``D = M Phi diag(2 zeta omega) Phi' M`` with
#: ``Phi`` the mass-normalised modes of ``K phi = omega^2 M phi`` (classical modal damping;
#: assumed modes, frozen, only).
DAMPING_FORMS: tuple[DampingForm, ...] = ("ratio", "paper", "stiffness", "modal")


def read_damping(r) -> tuple[DampingForm, float | None]:
    """A model file's ``damping_form`` and, with ``"modal"``, its required ``damping_zeta``
    (``r``: the file's top-level :class:`~flexctrl.spec.reader.TableReader`)."""
    form = r.choice("damping_form", DAMPING_FORMS, "ratio")
    if form != "modal":
        if r.has("damping_zeta"):
            raise r.error(
                "damping_zeta",
                f"damping_zeta applies to damping_form = 'modal' only (here '{form}'); "
                "allowed: damping_form = 'modal' beside it, or the links' damping_ratio",
            )
        return form, None
    if not r.has("damping_zeta"):
        raise r.error(
            "damping_zeta",
            "damping_form = 'modal' needs damping_zeta, the damping ratio of every coupled "
            "elastic mode; allowed: a number in [0, 1]",
        )
    return form, r.number("damping_zeta", low=0.0, high=1.0)


def damping_summary(arm, form: str | None = None) -> dict[str, Any]:
    """The damping of ``arm`` (an :class:`~flexctrl.spec.arm.ArmSpec`) as a run's summary
    records it: the form (``form`` when the model was built with another than the file's) and
    its numbers, ``damping_zeta`` on the coupled modes or each link's ``damping_ratio`` per
    clamped-mass mode."""
    form = arm.damping_form if form is None else form
    if form == "modal":
        return {"form": form, "zeta_coupled_modes": arm.damping_zeta}
    return {
        "form": form,
        "damping_ratio_per_clamped_mass_mode": [list(k.damping_ratios) for k in arm.links],
    }
