"""Identification of the hub masses that Table 2 of Subedi et al. (2021) omits.

The masses m_h2 and m_h3 (hubs on joints 2 and 3) enter the tip mass of links 1
and 2 (Eqs 69, 71) and so their frequencies in Table 3.  They are found by
least squares on the eight link-1 and link-2 frequencies of Table 3 (payload 0
and 2 kg, two modes each) at q2 = q3 = 0.  The link-3 rows need no hub mass and
stay an independent check of the method.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from flexctrl.errors import SolverError
from flexctrl.modal.arm_modes import link_modes
from flexctrl.modal.paper_data import SUBEDI_TABLE3_HZ
from flexctrl.spec.arm import ArmSpec


@dataclass(frozen=True)
class HubFit:
    """Result of :func:`identify_hub_masses`.

    Attributes
    ----------
    hub_masses : dict of int to float
        Identified masses (kg) by joint number (1-based).
    residuals_hz : list of tuple
        ``(payload_kg, link, mode, table_hz, model_hz, residual_hz)`` for every
        frequency of Table 3 (links 1-3), residual = model - table.
    rms_hz, max_abs_hz : float
        Over the rows used in the fit.
    """

    hub_masses: dict[int, float]
    residuals_hz: list[tuple[float, int, int, float, float, float]]
    rms_hz: float
    max_abs_hz: float


def _with_hub_masses(arm: ArmSpec, masses: dict[int, float]) -> ArmSpec:
    joints = list(arm.joints)
    for joint, mass in masses.items():
        joints[joint - 1] = dataclasses.replace(joints[joint - 1], hub_mass=float(mass))
    return dataclasses.replace(arm, joints=tuple(joints))


def table3_residuals(
    arm: ArmSpec, links: tuple[int, ...] = (1, 2, 3)
) -> list[tuple[float, int, int, float, float, float]]:
    """Model-minus-table residuals of Table 3 for ``links`` (1-based) at q = 0.

    Parameters
    ----------
    arm : ArmSpec
        The arm described (its payload is replaced by each of the table's).
    links : tuple of int
        The links compared, 1-based.

    Returns
    -------
    list of tuple
        ``(payload kg, link, mode, table Hz, model Hz, model - table Hz)`` per entry.
    """
    rows = []
    q = np.zeros(arm.n_links)
    for payload, table in SUBEDI_TABLE3_HZ.items():
        loaded = arm.with_payload(payload)
        for link in links:
            freqs = link_modes(loaded, q, link - 1, n_modes=2).frequency_hz
            for mode in range(2):
                ref = table[link - 1][mode]
                rows.append(
                    (payload, link, mode + 1, ref, float(freqs[mode]), float(freqs[mode] - ref))
                )
    return rows


def identify_hub_masses(
    arm: ArmSpec, joints: tuple[int, ...] = (2, 3), start: float = 5.0
) -> HubFit:
    """Least-squares fit of the hub masses of ``joints`` (1-based) to Table 3.

    Parameters
    ----------
    arm
        The Subedi three-link arm (its hub masses for ``joints`` are ignored).
    joints
        Joints whose hub masses are unknown.
    start
        Initial guess (kg) for every unknown.

    Raises
    ------
    SolverError
        If the least-squares solver does not converge.
    """

    def residuals(x: np.ndarray) -> np.ndarray:
        trial = _with_hub_masses(arm, dict(zip(joints, x)))
        return np.array([r[-1] for r in table3_residuals(trial, links=(1, 2))])

    result = least_squares(
        residuals,
        x0=np.full(len(joints), start),
        bounds=(0.0, np.inf),
        x_scale=10.0,
        xtol=1e-12,
        ftol=1e-12,
    )
    if not result.success:
        raise SolverError(f"hub-mass identification did not converge: {result.message}")
    masses = dict(zip(joints, (float(v) for v in result.x)))
    fitted = _with_hub_masses(arm, masses)
    used = residuals(result.x)
    return HubFit(
        hub_masses=masses,
        residuals_hz=table3_residuals(fitted),
        rms_hz=float(np.sqrt(np.mean(used**2))),
        max_abs_hz=float(np.max(np.abs(used))),
    )
