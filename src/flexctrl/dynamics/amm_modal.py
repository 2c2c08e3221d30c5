"""The modal parameters of an assumed-modes model: frozen constants or scheduled expressions.

Frozen modes are the clamped-mass modes of each link at one configuration, as numeric
constants (:class:`~flexctrl.dynamics.amm_kinematics.LinkModal` of DM).  Scheduled modes follow
the configuration through the differentiable lookup tables
(:func:`flexctrl.modal.lookup.modal_lookup`) and enter the kinematics as expressions in ``q``.
"""

from __future__ import annotations

from collections.abc import Sequence

import casadi as ca
import numpy as np

from flexctrl.beam.clamped_mass import ClampedMassModes
from flexctrl.dynamics.amm_kinematics import LinkModal
from flexctrl.modal.arm_modes import link_modes
from flexctrl.modal.lookup import modal_lookup
from flexctrl.modal.static_correction import CorrectedModes
from flexctrl.spec.arm import ArmSpec

#: The substitution that puts the tables' expansion point at ``q``: ``(symbols, values)``.
Expansion = tuple[list[ca.SX], list[ca.SX]]


def frozen_modal(
    arm: ArmSpec, q_ref: np.ndarray, n_modes: Sequence[int], correct: Sequence[bool] = ()
) -> tuple[list[LinkModal], list[list[float]]]:
    """Frozen modal constants per link, and each link's modal frequencies (rad/s).

    Parameters
    ----------
    arm : ArmSpec
        The arm, payload included.
    q_ref : ndarray
        Joint angles (rad) the clamped-mass modes are computed at.
    n_modes : sequence of int
        Modes per link.
    correct : sequence of bool
        Links that get the tip-moment correction shape after their modes
        (:class:`~flexctrl.modal.static_correction.CorrectedModes`).

    Returns
    -------
    modal : list of LinkModal
        Numeric constants per link.
    frequencies : list of list of float
        Each link's modal frequencies, rad/s.
    """
    modal, freqs = [], []
    for i, nf in enumerate(n_modes):
        modes: ClampedMassModes | CorrectedModes | None = None
        if nf:
            clamped = link_modes(arm, q_ref, i, nf)
            modes = CorrectedModes(clamped) if i < len(correct) and correct[i] else clamped
        modal.append(LinkModal.from_modes(modes, modes.n_modes if modes is not None else 0))
        freqs.append([float(x) for x in np.asarray(modes.omega)] if modes is not None else [])
    return modal, freqs


def scheduled_modal(
    arm: ArmSpec,
    q: ca.SX,
    n_modes: Sequence[int],
    lookups: Sequence[ca.Function | None] | None,
) -> tuple[list[LinkModal], Expansion]:
    """Modal expressions ``p(q_r)`` from the lookup functions (one per link, None for n_f = 0).

    The tables enter as their second-order expansion about a symbolic point ``q0``,
    ``p(q) = a + B (q - q0) + 1/2 (q - q0)^T C (q - q0)``, with ``a, B, C`` symbols.
    The equations of motion need at most second derivatives of ``p``, which this
    expansion gives exactly at ``q = q0``.  Returns the modal parameters and the
    substitution ``(symbols, values)`` that puts ``q0 = q`` and the spline's value,
    Jacobian and Hessian in place: one spline evaluation of each order per link,
    instead of one per place CasADi differentiates a spline call, which makes ``f``
    several times slower.  Derivatives of the substituted expressions (linearisation) go
    through the spline calls and stay exact.

    Parameters
    ----------
    arm : ArmSpec
        The arm, payload included.
    q : casadi.SX
        The generalised coordinates.
    n_modes : sequence of int
        Modes per link.
    lookups : sequence of casadi.Function or None, optional
        One table Function per link (:attr:`flexctrl.modal.lookup.ModalLookup.function`,
        None for a link without modes); default: built by
        :func:`~flexctrl.modal.lookup.modal_lookup`.

    Returns
    -------
    modal : list of LinkModal
        Expressions per link.
    expansion : tuple of (list, list)
        The symbols of the expansion and the values to substitute for them.
    """
    if lookups is None:
        lookups = [
            modal_lookup(arm, i, nf).function if nf else None for i, nf in enumerate(n_modes)
        ]
    n = arm.n_links
    q0 = ca.SX.sym("q_expansion", n)
    step = q[:n] - q0
    symbols, values = [q0], [q[:n]]
    modal = []
    for i, nf in enumerate(n_modes):
        if nf == 0:
            modal.append(LinkModal.from_modes(None, 0))
            continue
        table = lookups[i]
        if table is None:
            raise ValueError(f"link {i + 1} has {nf} modes but no lookup table (lookups[{i}])")
        link_symbols, link_values, pieces = _link_expansion(table, q, step, n, i)
        symbols += link_symbols
        values += link_values
        modal.append(LinkModal(*pieces))
    return modal, (symbols, values)


def _link_expansion(
    table: ca.Function, q: ca.SX, step: ca.SX, n: int, i: int
) -> tuple[list[ca.SX], list[ca.SX], list[ca.SX]]:
    """The symbols ``a, B, C`` of link ``i``'s expansion, their values and the modal pieces."""
    point = ca.SX.sym("q_table", n)
    outputs = table(point)  # in LinkModal's field order: FIELDS, then y, s
    shapes = [out.shape for out in outputs]
    value = ca.vertcat(*(ca.vec(out) for out in outputs))
    m = value.shape[0]
    jac = ca.jacobian(value, point)
    hess = ca.jacobian(ca.vec(jac), point)  # row i + m k: d^2 value_i / dq_k dq
    derivatives = ca.Function(f"modal_expansion_link{i + 1}", [point], [value, jac, hess])
    a, B, C = (
        ca.SX.sym(f"a{i + 1}", m),
        ca.SX.sym(f"B{i + 1}", m, n),
        ca.SX.sym(f"C{i + 1}", m * n, n),
    )
    local = a + ca.mtimes(B, step) + 0.5 * ca.mtimes(ca.reshape(ca.mtimes(C, step), m, n), step)
    values = [ca.densify(v) for v in derivatives(q[:n])]
    pieces, offset = [], 0
    for shape in shapes:
        size = shape[0] * shape[1]
        pieces.append(ca.reshape(local[offset : offset + size], shape[0], shape[1]))
        offset += size
    return [a, B, C], values, pieces
