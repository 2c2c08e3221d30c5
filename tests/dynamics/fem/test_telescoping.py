"""Telescoping prismatic joint, two flexible links (flexctrl.dynamics.fem.telescoping; Pan et al.
Fig 5)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid
from support import DATA

from flexctrl.dynamics.fem.rp_arm import RPMotion, simulate_rp_arm
from flexctrl.dynamics.fem.telescoping import (
    TelescopingModel,
    simulate_telescoping,
    static_tip_deflection,
)
from flexctrl.errors import SpecError
from flexctrl.scenes.run_fem_scene import run_fem_scene
from flexctrl.spec.fem_models import (
    Contact,
    LinkProps,
    TelescopingSpec,
    load_rp_arm,
    load_telescoping,
    telescoping_from_document,
)
from flexctrl.spec.overrides import apply_overrides
from flexctrl.spec.reader import read_toml

MODEL = DATA / "models" / "telescoping.toml"
SCENE = DATA / "studies" / "scenes" / "telescoping_extend.toml"
RP = load_rp_arm(DATA / "models" / "rp_arm.toml")
ROTATE = RPMotion(C1=0.3, C2=-0.4, T=1.0, theta0=0.0, dtheta=math.radians(60.0))


def _housing_like(outer_EI: float) -> TelescopingSpec:
    """An outer link with two bearings where rp_arm's housing has its supports (0.6, 0.8 m)."""
    return TelescopingSpec(
        "housing-like",
        outer=LinkProps(RP.support_outer, 1.5, outer_EI),
        inner=LinkProps(RP.length, RP.mass_per_length, RP.EI),
        contacts=(Contact("outer", RP.support_inner), Contact("outer", RP.support_outer)),
    )


def test_stiff_outer_link_is_the_rigid_housing():
    """(a) EI_outer x 1e6: the inner link responds as in rp_arm's rigid housing (Fig 4), same
    motion (extend 0.4 m while turning 60 deg).  The outer link then deflects ~1e-6 of its
    flexible value (~1e-9 m), so the bound is 1e-4 of the 1.35 mm peak; with the plain EI the
    tube's compliance changes the tip by more than the peak itself."""
    ref = simulate_rp_arm(RP, ROTATE, 8, dt=1e-3, duration=1.3)
    peak = np.abs(ref.tip_y).max()
    stiff = simulate_telescoping(_housing_like(2000.0 * 1e6), ROTATE, 8, 8, dt=1e-3, duration=1.3)
    assert np.abs(stiff.tip_y - ref.tip_y).max() < 1e-4 * peak
    np.testing.assert_allclose(
        stiff.lam, -ref.lam, rtol=0, atol=1e-4 * np.abs(ref.lam).max()
    )  # w1 - w2 rows
    soft = simulate_telescoping(_housing_like(2000.0), ROTATE, 8, 8, dt=1e-3, duration=1.3)
    assert np.abs(soft.tip_y - ref.tip_y).max() > 0.5 * peak


@pytest.fixture(scope="module")
def scene_spec():
    return load_telescoping(MODEL)


EXTEND = RPMotion(C1=0.1, C2=-0.5, T=1.0, theta0=0.0, dtheta=math.radians(60.0))


def test_constraint_violation_small_and_baumgarte_removes_drift(scene_spec):
    """(b) Mouth and root contacts sliding along both links: position/velocity violations stay
    below 1e-7 m and 1e-6 m/s against millimetre deflections.  Without Baumgarte (gamma = beta
    = 0) Newmark's acceleration-level constraint lets the violation drift; with it, the
    violation decays (Eq 49), so at the end it is >100x smaller."""
    on = simulate_telescoping(scene_spec, EXTEND, 8, 8, dt=1e-3, duration=2.0)
    off = simulate_telescoping(scene_spec, EXTEND, 8, 8, dt=1e-3, duration=2.0, gamma=0.0, beta=0.0)
    assert np.abs(on.tip_y).max() > 1e-3 and np.abs(on.outer_tip_y).max() > 1e-4
    assert on.phi_violation.max() < 1e-7 and on.phidot_violation.max() < 1e-6
    late = on.t > 1.5
    assert off.phi_violation[late].mean() > 100 * on.phi_violation[late].mean()
    assert off.phi_violation[-1] > off.phi_violation[on.t < 1.0].mean()  # still growing, not damped
    x1, x2 = scene_spec.contact_points(on.model.s(0.0)), scene_spec.contact_points(on.model.s(1.0))
    assert x1[0][1] != x2[0][1] and x1[1][0] != x2[1][0]  # contacts moved along both links


def test_energy_balance(scene_spec):
    """(c) d/dt (1/2 qd M qd + 1/2 q K q) = qd . (f - (K_g - theta'^2 M) q) + lam . Phi_t: the
    frame loads, the rigid-motion axial forces and the contact forces on the *sliding* contacts
    (their power uses Phi_t, not A qd, so the balance holds only if the constraints do).  The
    trapezoidal rule makes the residual O(dt^2): halving dt must cut it ~4x, and at 1 ms it must
    be below 1e-3 of the peak energy (measured ~1e-5)."""
    errors = {}
    for dt in (1e-3, 5e-4):
        res = simulate_telescoping(scene_spec, EXTEND, 8, 8, dt=dt, duration=1.5)
        m, prob = res.model, res.model.problem()
        E = np.array([m.vibration_energy(q, qd) for q, qd in zip(res.q, res.qd)])
        power = np.array(
            [
                qd @ (m.load(t) - (m.stiffness(t) - m.K) @ q) + lam @ prob.phi_t(q, t)
                for t, q, qd, lam in zip(res.t, res.q, res.qd, res.lam)
            ]
        )
        work = cumulative_trapezoid(power, res.t, initial=0.0)
        errors[dt] = np.abs(E - E[0] - work).max() / E.max()
        assert np.abs(work).max() > 0.5 * E.max()  # the motion does the work
    assert errors[1e-3] < 1e-3
    assert errors[1e-3] / errors[5e-4] > 3.0


@pytest.mark.parametrize(
    "contacts",
    [(Contact("outer", 0.8), Contact("inner", 0.0)), (Contact("outer", 0.8, True),)],
    ids=["mouth+root", "sleeve (Eqs 26-28 at one point)"],
)
def test_static_tip_load_matches_the_stepped_beam(contacts):
    """(d) Cantilevered pair, tip force: exact (rounding) when the contacts sit on nodes (Hermite
    elements are exact for point loads at nodes); converging otherwise.  The overlap is not a
    composite section: a bonded overlap (EI1 + EI2) would be stiffer."""
    spec = TelescopingSpec(
        "static",
        outer=LinkProps(0.8, 1.5, 2000.0),
        inner=LinkProps(0.8, 1.0, 212.8),
        contacts=contacts,
    )
    P = 1.0
    on_node = static_tip_deflection(spec, 0.1, P)
    m = TelescopingModel(spec, RPMotion(0.1, 0.0, 1.0), 8, 8)  # s = W = 0.1: contacts on nodes
    assert m.static(P)[0][m.tip] == pytest.approx(on_node, rel=1e-9)
    ref = static_tip_deflection(spec, 0.137, P)
    errs = []
    for n in (8, 32):
        m = TelescopingModel(spec, RPMotion(0.137, 0.0, 1.0), n, n)
        errs.append(abs(m.static(P)[0][m.tip] - ref) / ref)
    # 4x refinement: a point force inside an element (jump of w''') converges fast; the sleeve's
    # multiplier is a point *moment* (jump of w'', not representable in a cubic): first order
    assert errs[0] < 1e-2 and errs[1] < errs[0] / (3.0 if contacts[0].slope else 10.0)
    # a composite section (EI1 + EI2 over the overlap [s, L1]) would be a stepped cantilever:
    # delta = P sum_seg ((Lt - x_a)^3 - (Lt - x_b)^3) / (3 EI_seg), Lt = L1 + c
    s0, L1, c = 0.1, spec.outer.length, spec.inner.length - (spec.outer.length - 0.1)
    Lt = L1 + c
    segments = (
        (0.0, s0, spec.outer.EI),
        (s0, L1, spec.outer.EI + spec.inner.EI),
        (L1, Lt, spec.inner.EI),
    )
    composite = P * sum(((Lt - xa) ** 3 - (Lt - xb) ** 3) / (3 * EI) for xa, xb, EI in segments)
    assert (
        on_node > 1.05 * composite
    )  # measured 7.5 % (mouth+root) and 7.1 % (sleeve) more compliant


def test_model_file_and_errors(scene_spec):
    doc = read_toml(MODEL)
    assert scene_spec.outer.length == doc["outer"]["length"] and len(scene_spec.contacts) == 2
    with pytest.raises(SpecError, match="at least two"):
        telescoping_from_document(
            {**doc, "contacts": [{"on": "outer", "at": doc["outer"]["length"]}]}, "t.toml"
        )
    with pytest.raises(SpecError, match="did you mean 'mass_per_length'"):
        telescoping_from_document(apply_overrides(doc, ["inner.mass_per_lenght=1.0"]), "t.toml")
    with pytest.raises(SpecError, match="allowed: 'outer', 'inner'"):
        telescoping_from_document(
            {**doc, "contacts": [{"on": "tube", "at": 0.1}, {"on": "inner", "at": 0.0}]}, "t.toml"
        )
    with pytest.raises(SpecError, match="key 'C1'.*0 < x1"):
        TelescopingModel(
            scene_spec, RPMotion(C1=0.0, C2=-0.5, T=1.0), 4, 4
        )  # root contact at the clamp


def test_scene_runs(tmp_path):
    doc = apply_overrides(read_toml(SCENE), ["duration=0.3"])
    summary = run_fem_scene(doc, str(SCENE), tmp_path, None)
    header = (tmp_path / "trajectory.csv").read_text().splitlines()[0]
    assert header == "t,W,tip_y,phi_max,phidot_max,theta,tip_X,tip_Y,outer_tip_y"
    assert (
        summary["kind"] == "telescoping" and summary["max_phi_violation_m"] < doc["max_violation"]
    )
    assert (tmp_path / "tip.png").stat().st_size > 1000
    assert summary["model"]["contacts"][0]["on"] == "outer"
    with pytest.raises(SpecError, match="driven_end"):
        run_fem_scene({**doc, "driven_end": "H"}, str(SCENE), None, None)
