"""Axial shortening in the assumed-modes model (``axial_shortening``;
``docs/explanation/assumed-modes.md`` section 10).

References independent of the model code: the closed-form slope of a cantilever under a tip and a
uniform load (foreshortening by numerical quadrature of it), Southwell's relation for a spinning
cantilever, the energy balance along RK4 at two steps, and the model without the effect (rigid
limit, frequencies at rest).
"""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest
from model_checks import energy_drift, one_link, rotating_frequency

from flexctrl.dynamics.amm import build_amm
from flexctrl.dynamics.build import build_model
from flexctrl.errors import SpecError
from flexctrl.spec.arm import load_arm


@pytest.fixture
def arm(model_path):
    return load_arm(model_path)


def static_elastic(model, q_joints):
    """Elastic coordinates of the static equilibrium with the joints clamped at ``q_joints``
    (Newton)."""
    n, N = model.n_joints, model.n_q
    q = ca.SX.sym("q", N)
    F = (model.functions["g"](q) + ca.mtimes(model.functions["K"]()["K"], q))[n:]
    fun = ca.Function("F", [q], [F, ca.jacobian(F, q)[:, n:]])
    qf = np.zeros(N - n)
    for _ in range(30):
        r, J = (np.asarray(v, dtype=float) for v in fun(np.r_[q_joints, qf]))
        step = np.linalg.solve(J, r.ravel())
        qf -= step
        if np.abs(step).max() < 1e-15:
            break
    return np.r_[q_joints, qf]


@pytest.mark.parametrize("n_modes, rel", [(2, 2e-2), (4, 2e-3)])
def test_static_foreshortening_under_tip_load_matches_closed_form(arm, n_modes, rel):
    """Horizontal cantilever under its weight and a 10 kg tip weight: the tip draws in by
    s(L) = 1/2 int w'^2 of the Euler-Bernoulli slope w' = (P x (2L - x) / 2 + q x (3L^2 - 3Lx +
    x^2) / 6) / EI."""
    one = one_link(arm, 10.0, gravity=(0.0, -9.81))
    link = one.links[0]
    L, EI = link.length, link.EI
    P, w = 10.0 * 9.81, link.mass_per_length * 9.81
    x = np.linspace(0.0, L, 200001)
    slope = (P * x * (2 * L - x) / 2 + w * x * (3 * L**2 - 3 * L * x + x**2) / 6) / EI
    closed = 0.5 * np.trapezoid(slope**2, x)
    on = build_amm(one, n_modes, axial_shortening=True)
    q = static_elastic(on, [0.0])
    tip = np.asarray(on.functions["tip"](q, np.zeros(on.n_q))[0], dtype=float).ravel()
    assert L - tip[0] == pytest.approx(closed, rel=rel)
    assert closed > 5e-4  # a measurable shortening (m)
    off = build_amm(one, n_modes, axial_shortening=False)
    q_off = static_elastic(off, [0.0])
    assert float(off.functions["tip"](q_off, np.zeros(off.n_q))[0][0]) == pytest.approx(
        L, abs=1e-12
    )


@pytest.mark.parametrize("shortening, coefficient", [(True, 0.1933), (False, -1.0)])
def test_spinning_link_follows_southwell(arm, shortening, coefficient):
    """In-plane bending of a spinning cantilever: omega^2 = omega_0^2 + (1.1933 - 1) Omega^2
    (Southwell; -1 is the frame's softening alone, which is all the model has without the
    effect)."""
    m = build_amm(one_link(arm, 0.0), 4, axial_shortening=shortening)
    w0 = rotating_frequency(m, 0.0)
    spin = 0.1 * w0
    w = rotating_frequency(m, spin)
    assert (w**2 - w0**2) / spin**2 == pytest.approx(coefficient, abs=0.006)


@pytest.mark.parametrize("modes", ["frozen", "scheduled"])
def test_energy_conserved_at_rk4_order(arm, modes):
    """Undamped free swing under gravity with link 3 bent and the joints moving: the energy error of
    RK4 falls by at least 2^3.5 when the step halves, and is small at the fine step."""
    arm = dataclasses.replace(
        arm.with_payload(2.0),
        links=tuple(dataclasses.replace(l, damping_ratios=(0.0,)) for l in arm.links),
        joints=tuple(dataclasses.replace(j, friction=0.0) for j in arm.joints),
        axial_shortening=True,
    )
    model = build_model(arm, "amm:2", modes=modes)
    assert model.info["axial_shortening"] is True
    x0 = np.zeros(model.n_x)
    x0[[0, 1, 2]] = [0.2, -0.3, 0.4]
    x0[model.coordinate_names.index("qf31")] = 0.05
    x0[model.n_q : model.n_q + 3] = [1.0, -2.0, 3.0]
    coarse, swing = energy_drift(model, x0, 2.5e-4)
    fine, _ = energy_drift(model, x0, 1.25e-4)
    assert swing > 0.05  # the joints really move (rad)
    assert fine < 1e-5
    assert coarse / fine > 2**3.5


def test_rigid_limit_and_rest_frequencies_unchanged(arm):
    """amm:0 does not see the switch; at rest (straight links) M and K, hence the locked frequencies
    and Table 3, are those of the model without the effect (it is second order in the
    deflection)."""
    loaded = arm.with_payload(2.0)
    rng = np.random.default_rng(3)
    rigid = [build_amm(loaded, 0, axial_shortening=flag) for flag in (True, False)]
    for _ in range(3):
        q, qd = rng.uniform(-1, 1, 3), rng.uniform(-2, 2, 3)
        for name in ("M", "g"):
            a, b = (np.asarray(m.functions[name](q), dtype=float) for m in rigid)
            assert np.array_equal(a, b)
        a, b = (np.asarray(m.functions["c"](q, qd), dtype=float) for m in rigid)
        assert np.array_equal(a, b)
    for qr in ([0.0, 0.0, 0.0], [0.0, np.pi / 2, 0.0], [0.0, np.pi / 4, -np.pi / 2]):
        on, off = (
            build_amm(loaded, 2, reference_q=qr, axial_shortening=flag) for flag in (True, False)
        )
        assert on.info["locked_frequencies_rad_s"] == pytest.approx(
            off.info["locked_frequencies_rad_s"], rel=1e-12
        )
        q0 = np.r_[qr, np.zeros(on.n_q - 3)]
        assert np.allclose(on.mass_matrix(q0), off.mass_matrix(q0), rtol=0, atol=1e-13)


def test_shortening_changes_only_second_order_terms(arm):
    """The difference between the two models is quadratic in the deflection: tip position at
    q_f and 2 q_f differ from the linear model's by a factor 4."""
    loaded = arm.with_payload(2.0)
    on, off = (build_amm(loaded, 2, axial_shortening=flag) for flag in (True, False))
    q = np.r_[0.3, -0.2, 0.5, 0.003, 0.001, -0.002, 0.0005, 0.004, -0.001]
    scale = np.r_[1, 1, 1, 2, 2, 2, 2, 2, 2]
    d1, d2 = (
        np.asarray(
            on.functions["tip"](v, 0 * v)[0] - off.functions["tip"](v, 0 * v)[0], dtype=float
        ).ravel()
        for v in (q, q * scale)
    )
    assert np.linalg.norm(d2) / np.linalg.norm(d1) == pytest.approx(4.0, rel=2e-2)


def test_switch_reaches_the_model_from_files_and_scenes(model_path, tmp_path):
    from flexctrl.scenes.arm_setup import scene_arm
    from flexctrl.spec.scene import load_scene

    assert load_arm(model_path).axial_shortening is None  # each family's default
    assert build_model(load_arm(model_path), "amm:1").info["axial_shortening"] is False
    assert build_model(load_arm(model_path), "fem:1").info["axial_shortening"] is True
    assert (
        build_model(load_arm(model_path, ["axial_shortening=true"]), "amm:1").info[
            "axial_shortening"
        ]
        is True
    )
    assert load_arm(model_path, ["axial_shortening=false"]).axial_shortening is False
    with pytest.raises(SpecError, match="axial_shortening"):
        load_arm(model_path, ["axial_shortening=1"])
    scene_file = tmp_path / "s.toml"
    scene_file.write_text(
        f'kind = "arm"\nmodel = "{model_path}"\ndt = 1e-3\nduration = 0.01\n'
        "axial_shortening = false\n"
    )
    scene = load_scene(scene_file)
    assert scene.axial_shortening is False and scene_arm(scene).axial_shortening is False
    assert build_model(scene_arm(scene), "amm:1").info["axial_shortening"] is False
    assert build_model(scene_arm(scene), "fem:1").info["axial_shortening"] is False
