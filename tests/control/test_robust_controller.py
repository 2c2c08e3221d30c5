"""The robust controller: designed at [30, 0, 0] deg and 2 kg, stable at every payload and pose.

Its linear loop, checked over a grid of payloads and poses.
"""

from __future__ import annotations

import numpy as np
import pytest
from support import DATA

import flexctrl as fc
from flexctrl.loop.mismatch import plant_sensors
from flexctrl.loop.verdict import linear_closed_loop_radius

DESIGN_Q = np.radians([30.0, 0.0, 0.0])
DAMPED = {f"links[{i}].damping_ratio": 0.005 for i in (1, 2, 3)}


def _model(payload: float, q):
    return fc.load_model(
        DATA / "models" / "subedi3link.toml",
        payload=payload,
        fidelity="amm:2",
        gravity=[0.0, 0.0],
        overrides=DAMPED,
        reference_q=q,
    )


@pytest.fixture(scope="module")
def robust():
    design = _model(2.0, DESIGN_Q)
    return fc.design(
        design,
        fc.equilibrium(design, DESIGN_Q),
        fc.load_controller(DATA / "controllers" / "robust.toml"),
    )


@pytest.mark.parametrize("payload", [0.0, 2.0, 4.0])
@pytest.mark.parametrize("q23", [(0.0, 0.0), (90.0, -90.0), (135.0, 90.0), (45.0, 90.0)])
def test_linear_loop_is_stable_at_every_payload_and_pose(robust, payload, q23):
    target = np.radians([30.0, *q23])
    plant = _model(payload, target)
    radius = linear_closed_loop_radius(
        plant, robust, target, plant_sensors(plant, robust.sensors, tuple(DESIGN_Q))
    )
    assert radius < 1.0


def test_the_nonlinear_run_agrees_at_the_lightest_folded_cell(robust):
    plant = _model(0.0, np.radians([0.0, 135.0, 90.0]))
    move = fc.Move(
        start=np.radians([0.0, 135.0, 90.0]), target=np.radians([30.0, 135.0, 90.0]), time=1.5
    )
    res = fc.closed_loop(
        robust.design_model,
        robust,
        move,
        duration=6.0,
        plant=plant,
        on_divergence="record",
        metrics=fc.MetricSettings(settle_allowance=1.0),
    )
    assert res.metrics["stable"] == 1 and res.metrics["closed_loop_radius"] < 1.0
