"""The NMPC's reduced prediction model (Galerkin truncation) and the warm-started HPIPM."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from flexctrl import linear as L
from flexctrl.control import design
from flexctrl.control.nmpc.controller import interval_functions
from flexctrl.control.nmpc.prediction_model import prediction_model, truncated_model
from flexctrl.errors import SpecError
from flexctrl.scenes.model_files import load_model
from flexctrl.spec.controller_reader import controller_from_document
from flexctrl.spec.controller_settings import NMPCSettings


@pytest.fixture(scope="module")
def arms():
    return (
        load_model("models/subedi3link.toml", fidelity="amm:2"),
        load_model("models/subedi3link.toml", fidelity="amm:1"),
    )


def test_truncation_to_one_mode_per_link_is_the_one_mode_model(arms):
    # an independent build: the amm:1 arm from the file, against amm:2 with its second modes dropped
    two, one = arms
    reduced, keep = truncated_model(two, 1)
    assert (
        reduced.coordinate_names
        == one.coordinate_names
        == ("q1", "q2", "q3", "qf11", "qf21", "qf31")
    )
    assert keep.tolist() == [0, 1, 2, 3, 5, 7]
    rng = np.random.default_rng(3)
    for _ in range(4):
        q = np.r_[rng.uniform(-2, 2, 3), rng.normal(0, 1e-2, 3)]
        qd = np.r_[rng.normal(0, 2, 3), rng.normal(0, 0.1, 3)]
        u = rng.normal(0, 30, 3)
        x = np.r_[q, qd]
        expect = np.asarray(one.functions["f"](x, u)).ravel()
        got = np.asarray(reduced.functions["f"](x, u)).ravel()
        assert np.max(np.abs(got - expect)) < 1e-8 * np.max(np.abs(expect))
        np.testing.assert_allclose(
            reduced.mass_matrix(q), one.mass_matrix(q), rtol=1e-12, atol=1e-12
        )
        for name in ("energies", "tip", "deflection"):
            args = (q, qd) if name != "deflection" else (q,)
            for a, b in zip(reduced.functions[name](*args), one.functions[name](*args)):
                np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-10, atol=1e-14)


def test_prediction_model_keeps_the_design_model_when_nothing_is_dropped(arms):
    two, _ = arms
    for modes in (0, 2, 3):
        pred = prediction_model(two, modes)
        assert pred.model is two and not pred.reduced and pred.keep.tolist() == list(range(18))
    pred = prediction_model(two, 1)
    assert pred.reduced and pred.model.n_x == 12
    assert pred.keep.tolist() == [
        0,
        1,
        2,
        3,
        5,
        7,
        9,
        10,
        11,
        12,
        14,
        16,
    ]  # (q, qd) of the kept coordinates


def test_prediction_modes_needs_an_assumed_modes_model():
    fem = SimpleNamespace(info={"family": "fem"}, n_u=3, n_q=12, n_x=24, fidelity="fem:3")
    with pytest.raises(SpecError, match=r"prediction_modes.*assumed-modes.*fem:3"):
        prediction_model(fem, 1)


def test_prediction_settings_are_checked():
    with pytest.raises(SpecError, match="prediction_modes"):
        NMPCSettings(prediction_modes=-1)
    with pytest.raises(SpecError, match="nmpc_bad.toml.*qp_warm_start"):
        controller_from_document({"kind": "nmpc", "qp_warm_start": "yes"}, "nmpc_bad.toml")
    settings = controller_from_document(
        {"kind": "nmpc", "prediction_modes": 1, "qp_warm_start": True}, "nmpc.toml"
    )
    assert settings.prediction_modes == 1 and settings.qp_warm_start is True


@pytest.mark.slow
def test_reduced_warm_started_nmpc_regulates_the_full_arm_like_the_cold_one(arms):
    two, _ = arms
    op = L.equilibrium(two, np.radians([80.0, -10.0, -10.0]))
    common = dict(
        horizon=20,
        sample_time=0.01,
        compile=False,
        prediction_modes=1,
        prediction_basis="assumed",
        prediction_map="select",
    )
    cold = design(two, op, NMPCSettings(**common))
    warm = design(two, op, NMPCSettings(**common, qp_warm_start=True))
    assert (
        cold.substeps == warm.substeps == 2 and cold.problem.n == 12
    )  # the first modes need 2 RK4 steps
    # the prediction's own equilibrium: the same joints, nearly the design model's first-mode
    # deflections
    np.testing.assert_array_equal(cold.pred_op.x[:3], op.x[:3])
    assert np.max(np.abs(cold.pred_op.x - op.x[cold.keep])) < 1e-3
    F, _ = interval_functions(two, 0.01, 9, None)  # the plant: the whole 18-state arm
    x = op.x.copy()
    x[:3] += np.radians([3.0, -3.0, 3.0])
    cold.reset()
    warm.reset()
    for k in range(60):
        u_cold = cold.step(0.01 * k, x)
        u_warm = warm.step(0.01 * k, x)
        # the same QP to HPIPM's tolerances (torques scaled by their limits)
        assert np.max(np.abs(u_cold - u_warm) / warm.limits) < 1e-3
        x = np.asarray(F(x, u_warm)).ravel()
    for ctrl in (cold, warm):
        summary = ctrl.stats.summary()
        assert summary["steps"] == 60 and summary["fallbacks"] == 0
    assert sum(warm.stats.iterations[1:]) < sum(cold.stats.iterations[1:])
    assert np.max(np.abs(x[:3] - op.x[:3])) < np.radians(3.0) * 0.5
