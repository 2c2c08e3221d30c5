"""Differentiable lookup of modal parameters over the arm configuration.

Subedi et al. (2021, Section 3) tabulate the configuration-dependent modes
offline and interpolate.  Here each link gets a table over the joint angles that
change its boundary values (:func:`flexctrl.modal.boundary.scheduling_joints`),
on a uniform grid over one period, interpolated by cubic B-splines
(``casadi.interpolant(..., "bspline", ...)``) so the result can be differentiated
by CasADi (scheduled-mode dynamics, linearisation).  Angles are wrapped to
(-pi, pi] before the lookup; the grid overlaps the period by two cells on each
side so the spline is smooth across the wrap.

Shape rates: for the scheduled model's kinetic energy
(:mod:`flexctrl.dynamics.amm_kinematics`, "Shapes that move with the
configuration") each grid point also holds ``y[k, j, r] = int rho phi_k psi_jr dx``
and ``s[j, r, k, t] = int rho psi_jr psi_kt dx`` with ``psi_jr = d phi_j / d q_r``
taken by central differences of the normalised shapes (``_SHAPE_STEP`` rad) and the
integrals by Gauss-Legendre quadrature (``_GAUSS_POINTS`` points; the shapes of the
lowest six modes are smooth, and 24 points integrate them to round-off).  The
function outputs them over *all* joints (zero for joints the link does not depend
on), columns ordered ``r * n_modes + j``.

Mode signs are made continuous over the grid (each mode is aligned with its
grid neighbour by the sign of the overlap of their shapes), otherwise the
interpolant would average modes of opposite sign.

Tables are cached on disk (``$FLEXCTRL_CACHE`` or ``.flexctrl-cache/``) as
``.npz`` files keyed by a hash of everything they depend on.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import casadi as ca
import numpy as np

from flexctrl.modal.arm_modes import link_modes
from flexctrl.modal.boundary import scheduling_joints
from flexctrl.modal.shortening import (
    GAUSS_POINTS,
    SHORTENING_FIELDS,
    axial_shapes,
    gauss_nodes,
    shortening_integrals,
)
from flexctrl.spec.arm import ArmSpec
from flexctrl.user_cache import cache_directory

FIELDS = ("omega", "tip_deflection", "tip_slope", "v", "w", "z")
SHAPE_RATE_FIELDS = ("y", "s")
#: Axial shortening (:mod:`flexctrl.modal.shortening`), and its cross integral with the shape rates.
SHORT_FIELDS = SHORTENING_FIELDS + ("sh_psi",)
_FORMAT_VERSION = 3
_SHAPE_STEP = 1e-4  # rad, central differences of the shapes
_GAUSS_POINTS = GAUSS_POINTS
_SAMPLES = np.linspace(0.0, 1.0, 41)  # fractions of the link length for sign alignment


def cache_dir() -> Path:
    """Folder of cached tables (:func:`flexctrl.user_cache.cache_directory`)."""
    return cache_directory()


def _wrap(q):
    return ca.atan2(ca.sin(q), ca.cos(q))


@dataclass
class ModalLookup:
    """Interpolated modal parameters of one link.

    Attributes
    ----------
    link : int
        0-based link index.
    n_modes : int
    n_joints : int
        Joints of the arm (length of the input ``q``).
    joints : tuple of int
        0-based joints the table depends on.
    grid_deg : numpy.ndarray
        Grid of each scheduling angle (degrees), including the overlap.
    values : dict of str to numpy.ndarray
        Tabulated fields, shape ``grid shape + field shape``.
    function : casadi.Function
        Input ``q`` (all n joint angles, rad); outputs ``omega`` (rad/s),
        ``tip_deflection``, ``tip_slope`` (1/m), ``v`` (kg), ``w`` (kg m), each
        (n_modes, 1), ``z`` (kg), (n_modes, n_modes), ``y`` (kg/rad),
        (n_modes, n_modes * n_joints), ``s`` (kg/rad^2), (n_modes * n_joints,) * 2, then the
        axial-shortening integrals ``sh_tip, sh_v, sh_w`` (P, 1), ``sh_y`` (n_modes, P),
        ``sh_z`` (P, P) and ``sh_psi[r n_modes + j, p] = int rho dphi_j/dq_r N_p`` (n_modes
        n_joints, P), ``P = n_modes (n_modes + 1) / 2`` (:mod:`flexctrl.modal.shortening`).
    build_time_s : float
        Wall time to compute the table (0 when read from the cache).
    """

    link: int
    n_modes: int
    n_joints: int
    joints: tuple[int, ...]
    grid_deg: np.ndarray
    values: dict[str, np.ndarray]
    function: ca.Function = field(init=False)
    build_time_s: float = 0.0

    def __post_init__(self) -> None:
        self.function = self._make_function()

    def _make_function(self) -> ca.Function:
        q = ca.SX.sym("q", self.n_joints)
        nf, n = self.n_modes, self.n_joints
        names = FIELDS + SHAPE_RATE_FIELDS + SHORT_FIELDS
        P = nf * (nf + 1) // 2
        outputs = {
            "y": ca.SX.zeros(nf, nf * n),
            "s": ca.SX.zeros(nf * n, nf * n),
            "sh_psi": ca.SX.zeros(nf * n, P),
        }
        if not self.joints:
            for name in FIELDS + SHORTENING_FIELDS:
                outputs[name] = ca.SX(ca.DM(self.values[name]))
            return ca.Function(
                f"modal_link{self.link + 1}", [q], [outputs[k] for k in names], ["q"], list(names)
            )
        grid = [np.radians(self.grid_deg)] * len(self.joints)
        dims = len(self.joints)
        arrays = [
            self.values[name].reshape(self.values[name].shape[:dims] + (-1,)) for name in names
        ]
        stacked = np.concatenate(arrays, axis=-1)  # grid..., m
        m = stacked.shape[-1]
        flat = np.moveaxis(stacked, -1, 0).reshape(m, -1, order="F").ravel(order="F")
        spline = ca.interpolant(f"modal_table_link{self.link + 1}", "bspline", grid, flat)
        out = spline(ca.vertcat(*[_wrap(q[j]) for j in self.joints]))
        offset = 0
        for name in names:
            shape = self.values[name].shape[dims:]
            index = offset + np.arange(int(np.prod(shape))).reshape(
                shape
            )  # C order, as flattened above
            offset += index.size
            if name == "z":
                outputs[name] = ca.reshape(out[index.ravel()], nf, nf)  # symmetric
            elif name == "y":  # y[k, j, r_local]
                for k, j, rl in np.ndindex(*shape):
                    outputs["y"][k, self.joints[rl] * nf + j] = out[int(index[k, j, rl])]
            elif name == "s":  # s[j, r_local, k, t_local]
                for j, rl, k, tl in np.ndindex(*shape):
                    outputs["s"][self.joints[rl] * nf + j, self.joints[tl] * nf + k] = out[
                        int(index[j, rl, k, tl])
                    ]
            elif name == "sh_psi":  # sh_psi[j, r_local, p]
                for j, rl, p in np.ndindex(*shape):
                    outputs["sh_psi"][self.joints[rl] * nf + j, p] = out[int(index[j, rl, p])]
            elif len(shape) == 2:  # C order (rows, cols)
                outputs[name] = ca.reshape(out[index.ravel()], shape[1], shape[0]).T
            else:
                outputs[name] = out[index.ravel()]
        return ca.Function(
            f"modal_link{self.link + 1}", [q], [outputs[k] for k in names], ["q"], list(names)
        )

    def evaluate(self, q: np.ndarray) -> dict[str, np.ndarray]:
        """Interpolated fields at joint angles ``q`` (rad), as numpy arrays."""
        result = self.function(q=np.asarray(q, dtype=float))
        return {
            k: np.array(v, dtype=float)
            if k in ("z", "y", "s", "sh_y", "sh_z", "sh_psi")
            else np.array(v, dtype=float).squeeze(axis=-1)
            for k, v in result.items()
        }


def _key(arm: ArmSpec, link: int, n_modes: int, step_deg: float) -> str:
    outboard = {
        "links": [vars(l) | {"section": None, "source": ""} for l in arm.links[link:]],
        "joints": [vars(j) | {"source": ""} for j in arm.joints[link + 1 :]],
        "payload": [arm.payload.mass, arm.payload.effective_inertia],
        "convention": arm.boundary_inertia,
        "n_modes": n_modes,
        "step": step_deg,
        "version": _FORMAT_VERSION,
    }
    text = json.dumps(outboard, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:20]


def _modal_fields(modes) -> dict[str, np.ndarray]:
    return {
        "omega": modes.omega,
        "tip_deflection": modes.tip_deflection,
        "tip_slope": modes.tip_slope,
        "v": modes.v,
        "w": modes.w,
        "z": modes.z,
    }


def _aligned_shapes(
    arm: ArmSpec, q: np.ndarray, link: int, n_modes: int, x: np.ndarray, like: np.ndarray
) -> np.ndarray:
    """Shapes at ``x`` of the modes at ``q``, each signed to overlap positively with ``like``."""
    shapes = link_modes(arm, q, link, n_modes).shape(x)
    return shapes * np.where(np.sum(shapes * like, axis=1) < 0.0, -1.0, 1.0)[:, None]


def _shape_rate_integrals(
    arm: ArmSpec,
    q: np.ndarray,
    link: int,
    n_modes: int,
    joints: tuple[int, ...],
    shapes: np.ndarray,
    x: np.ndarray,
    weights: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``y[k, j, r]``, ``s[j, r, k, t]`` and the shape rates ``psi[j, r, x]`` at ``q``.

    ``shapes`` are the modes at ``q`` on the nodes ``x``.
    """
    psi = np.zeros((n_modes, len(joints), x.size))
    for rl, joint in enumerate(joints):
        step = np.zeros(arm.n_links)
        step[joint] = _SHAPE_STEP
        plus = _aligned_shapes(arm, q + step, link, n_modes, x, shapes)
        minus = _aligned_shapes(arm, q - step, link, n_modes, x, shapes)
        psi[:, rl, :] = (plus - minus) / (2.0 * _SHAPE_STEP)
    y = np.einsum("kx,jrx,x->kjr", shapes, psi, weights)
    s = np.einsum("jrx,ktx,x->jrkt", psi, psi, weights)
    return y, s, psi


def _shortening_fields(modes, signs: np.ndarray, psi: np.ndarray | None) -> dict[str, np.ndarray]:
    """The axial-shortening integrals of the signed modes.

    ``sh_psi`` comes from the shape rates on the Gauss nodes.
    """
    nf = modes.n_modes
    shape = lambda x, d: modes.shape(x, d) * signs[:, None]  # noqa: E731
    out = shortening_integrals(shape, modes.length, modes.rho, nf)
    if psi is not None:
        x, weights = gauss_nodes(modes.length, modes.rho, _GAUSS_POINTS)
        N = axial_shapes(lambda xs: shape(xs, 1), x, nf)
        out["sh_psi"] = np.einsum("jrx,px,x->jrp", psi, N, weights)
    return out


def _tabulate(
    arm: ArmSpec, link: int, n_modes: int, joints: tuple[int, ...], grid_deg: np.ndarray
) -> dict[str, np.ndarray]:
    shape = (grid_deg.size,) * len(joints)
    table: dict[str, np.ndarray] = {}
    shapes_ref: dict[tuple[int, ...], np.ndarray] = {}
    length = arm.links[link].length
    x = _SAMPLES * length
    x_gauss, weights = gauss_nodes(length, arm.links[link].mass_per_length, _GAUSS_POINTS)
    for index in np.ndindex(*shape):
        q = np.zeros(arm.n_links)
        for j, i in zip(joints, index):
            q[j] = np.radians(grid_deg[i])
        modes = link_modes(arm, q, link, n_modes)
        shapes = modes.shape(x)
        # align signs with the previous grid point (along the last varying axis, else the first)
        neighbour = None
        for axis in reversed(range(len(index))):
            if index[axis] > 0:
                neighbour = index[:axis] + (index[axis] - 1,) + index[axis + 1 :]
                break
        signs = np.ones(n_modes)
        if neighbour is not None:
            signs = np.where(np.sum(shapes * shapes_ref[neighbour], axis=1) < 0.0, -1.0, 1.0)
        else:
            signs = np.where(modes.tip_deflection < 0.0, -1.0, 1.0)
        shapes_ref[index] = shapes * signs[:, None]
        y, s, psi = _shape_rate_integrals(
            arm, q, link, n_modes, joints, modes.shape(x_gauss) * signs[:, None], x_gauss, weights
        )
        fields = _modal_fields(modes)
        fields = {
            "omega": fields["omega"],
            "tip_deflection": fields["tip_deflection"] * signs,
            "tip_slope": fields["tip_slope"] * signs,
            "v": fields["v"] * signs,
            "w": fields["w"] * signs,
            "z": fields["z"] * np.outer(signs, signs),
            "y": y,
            "s": s,
            **_shortening_fields(modes, signs, psi),
        }
        for name, value in fields.items():
            if name not in table:
                table[name] = np.zeros(shape + np.shape(value))
            table[name][index] = value
    return table


def modal_lookup(
    arm: ArmSpec,
    link: int,
    n_modes: int | None = None,
    *,
    step_deg: float = 10.0,
    use_cache: bool = True,
) -> ModalLookup:
    """Build (or read from the cache) the modal table of ``link`` (0-based).

    Parameters
    ----------
    arm
        Arm description (payload and ``boundary_inertia`` included).
    link
        0-based link index.
    n_modes
        Modes (default: the link's ``n_modes``).
    step_deg
        Grid step (degrees); must divide 360.
    use_cache
        Read and write the on-disk cache.
    """
    n_modes = arm.links[link].n_modes if n_modes is None else n_modes
    if not (0 < step_deg <= 90 and abs(360.0 / step_deg - round(360.0 / step_deg)) < 1e-9):
        raise ValueError(
            f"step_deg {step_deg!r} is not allowed; allowed: a divisor of 360 in (0, 90]"
        )
    joints = scheduling_joints(arm, link)
    overlap = 2 * step_deg
    grid_deg = (
        np.arange(-180.0 - overlap, 180.0 + overlap + step_deg / 2, step_deg)
        if joints
        else np.zeros(1)
    )
    path = cache_dir() / "modal" / f"link{link + 1}-{_key(arm, link, n_modes, step_deg)}.npz"
    if use_cache and path.is_file():
        with np.load(path) as data:
            values = {
                name: data[name]
                for name in FIELDS
                + SHORTENING_FIELDS
                + (SHAPE_RATE_FIELDS + ("sh_psi",) if joints else ())
            }
        return ModalLookup(link, n_modes, arm.n_links, joints, grid_deg, values, 0.0)
    start = time.perf_counter()
    if joints:
        values = _tabulate(arm, link, n_modes, joints, grid_deg)
    else:
        modes = link_modes(arm, np.zeros(arm.n_links), link, n_modes)
        values = {k: np.asarray(v) for k, v in _modal_fields(modes).items()}
        values.update(_shortening_fields(modes, np.ones(n_modes), None))
    elapsed = time.perf_counter() - start
    if use_cache:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, **values)
        os.replace(tmp, path)
    return ModalLookup(link, n_modes, arm.n_links, joints, grid_deg, values, elapsed)


def interpolation_error_hz(
    arm: ArmSpec, lookup: ModalLookup, samples: int = 200, seed: int = 0
) -> float:
    """Worst |interpolated - exact| natural frequency (Hz) at random configurations.

    Parameters
    ----------
    arm : ArmSpec
        The arm described.
    lookup : ModalLookup
        The table checked.
    samples : int
        Random configurations drawn.
    seed : int
        Seed of the generator.

    Returns
    -------
    float
        The largest error (Hz); 0 for a table without scheduling joints.
    """
    if not lookup.joints:
        return 0.0
    rng = np.random.default_rng(seed)
    worst = 0.0
    for _ in range(samples):
        q = rng.uniform(-np.pi, np.pi, arm.n_links)
        exact = link_modes(arm, q, lookup.link, lookup.n_modes).frequency_hz
        interp = lookup.evaluate(q)["omega"] / (2 * np.pi)
        worst = max(worst, float(np.max(np.abs(interp - exact))))
    return worst
